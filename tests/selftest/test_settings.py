"""The self-test's presets (`ours`, `paper`), the `bc-paper` baseline and `--repeats`, on tiny
budgets: each point of the paper preset that can be checked cheaply is checked here; the
methods of `--methods`."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import torch

from aisdati.commands.options import SelftestOptions
from aisdati.errors import UserError
from aisdati.model.bc import BC_PAPER, BCConfig, BCPolicy, BCTrainer
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.noise import NoiseProcess
from aisdati.selftest.families import get_family
from aisdati.selftest.protocol import evaluation_grid, run_selftest
from aisdati.selftest.settings import (
    SELFTEST_PRESETS,
    SelftestSettings,
    family_for,
    parse_methods,
    preset_settings,
)
from aisdati.selftest.sources import FamilySource


def tiny_env(name: str = "circles", steps: int = 12, exact: bool = False):
    return TrajectoryImitationEnv(FamilySource(family_for(name, steps, exact)))


# ------------------------------------------------------------------------------- bc-paper
def test_bc_paper_policy_ignores_time_and_has_one_log_std():
    policy = BCPolicy(2, 2, BC_PAPER, [0, 1])
    assert policy.time2vec is None and policy.feature_width == BC_PAPER.state_features
    assert isinstance(policy.log_std, torch.nn.Parameter) and policy.log_std.shape == (2, 1, 2)
    state = torch.rand(2, 5, 2)
    m0, s0 = policy(state, torch.zeros(2, 5, 1))
    m1, _ = policy(state, torch.full((2, 5, 1), 150.0))
    torch.testing.assert_close(m0, m1, rtol=0, atol=0)
    _, s2 = policy(torch.rand(2, 5, 2), torch.zeros(2, 5, 1))
    torch.testing.assert_close(s0, s2, rtol=0, atol=0)  # the same σ wherever the agent is
    assert BC_PAPER.batch_size == 32 and BC_PAPER.epochs == 1


def test_bc_paper_collects_every_episode_then_trains_its_epochs():
    cfg = replace(BC_PAPER, episodes=3, epochs=2)
    trainer = BCTrainer([tiny_env(), tiny_env()], [0, 1], cfg)
    before = [p.detach().clone() for p in trainer.policy.parameters()]
    trainer.step()
    assert np.isnan(trainer.losses[-1]).all()  # demonstrations only, no update yet
    assert all(torch.equal(a, b) for a, b in zip(before, trainer.policy.parameters(), strict=True))
    steps = []
    step = trainer.opt.step
    trainer.opt.step = lambda *a, **k: steps.append(1) or step(*a, **k)
    trainer.train()
    assert trainer.data.size == [36, 36]
    assert len(steps) == 2 * math.ceil(36 / 32)  # epochs x batches of 32
    assert np.isfinite(trainer.losses[-1]).all()


# ------------------------------------------------------------------------ paper preset
def test_presets_record_the_authors_choices():
    paper = preset_settings("paper", episodes=7)
    c = paper.config
    assert (c.episodes, c.patience, c.keep, c.adversarial_time2vec) == (7, 0, "final", False)
    assert paper.exact_region and paper.distinct_references and paper.preset == "paper"
    ours = preset_settings("ours")
    assert (ours.config.patience, ours.config.keep, ours.config.adversarial_time2vec) == (
        10,
        "best",
        True,
    )
    assert not ours.exact_region and not ours.distinct_references
    assert next(iter(SELFTEST_PRESETS)) == "paper"
    assert SelftestOptions().preset == "paper"
    assert SelftestSettings() == preset_settings()  # the dataclass defaults are the default preset
    with pytest.raises(UserError, match="unknown self-test preset"):
        preset_settings("nosuch")


def test_paper_noise_is_ou_at_the_familys_dt_and_gaussian_for_ribbons():
    settings = preset_settings("paper")
    for name in ("fixedstart", "ushaped", "circles"):
        fam = get_family(name)
        assert settings.noise_process(fam) == NoiseProcess("ou", fam.dt)
    assert settings.noise_process(get_family("ribbons")).kind == "gaussian"
    assert get_family("fixedstart").dt == pytest.approx(0.0349, abs=1e-4)
    assert get_family("circles").dt == pytest.approx(0.0785, abs=1e-4)
    ours = preset_settings("ours")
    assert ours.noise_process(get_family("circles")) == NoiseProcess("gaussian", 1e-2)


def test_latent_noise_follows_each_members_process():
    cfg = DATIConfig()
    gens = [torch.Generator().manual_seed(3) for _ in range(3)]
    procs = [NoiseProcess("ou", 0.01), NoiseProcess("ou", 0.09), NoiseProcess("gaussian")]
    eta = cfg.latent_noise(gens, procs).sample()[:, 0]
    draw = torch.randn(1, cfg.network.latent_dim, generator=torch.Generator().manual_seed(3))[0]
    draw = draw * cfg.noise_sigma
    torch.testing.assert_close(eta[0], draw * 0.1)  # OU from 0: one step of sqrt(dt) x draw
    torch.testing.assert_close(eta[1], draw * 0.3)
    torch.testing.assert_close(eta[2], draw)


def test_exact_region_is_the_familys_box_and_speed_range():
    loose, exact = family_for("circles", None), family_for("circles", None, exact=True)
    lo, hi = exact.bounds
    np.testing.assert_allclose(lo, [-1.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(hi, [1.0, 1.0], atol=1e-9)
    assert np.all(loose.bounds[0] < lo) and np.all(loose.bounds[1] > hi)
    # radius α in [0.5, 1] at angular speed ω = 0.4: speeds in [0.2, 0.4]
    assert exact.speed_range == pytest.approx((0.2, 0.4), rel=1e-3)
    assert loose.speed_range == pytest.approx((0.0, 0.5), rel=1e-3)
    scaler = tiny_env(exact=True).rule.decision_scaler  # τ = 12: chords, a little slower
    np.testing.assert_allclose(
        [scaler.low[0], scaler.high[0]], family_for("circles", 12, exact=True).speed_range
    )


def _t2v_after_one_batch(adversarial: bool) -> tuple[dict, dict]:
    cfg = DATIConfig(batch_size=8, lr_critic=0.0, lr_l1=0.0, adversarial_time2vec=adversarial)
    trainer = DATITrainer([tiny_env()], [0], cfg)
    before = {n: p.detach().clone() for n, p in trainer.nets.time2vec.named_parameters()}
    trainer.train_batch()  # the critics' and L1 steps have lr 0: only the adversarial one moves
    return before, dict(trainer.nets.time2vec.named_parameters())


def test_time2vec_frozen_under_the_adversarial_loss_only_in_the_paper_preset():
    before, after = _t2v_after_one_batch(adversarial=False)
    for name, p in after.items():
        torch.testing.assert_close(p, before[name], rtol=0, atol=0, msg=name)
    before, after = _t2v_after_one_batch(adversarial=True)
    assert any(not torch.equal(p, before[n]) for n, p in after.items())


def test_the_time2vec_still_learns_from_the_l1_terms_when_frozen_for_the_adversary():
    cfg = DATIConfig(batch_size=8, lr_critic=0.0, lr_actor=0.0, adversarial_time2vec=False)
    trainer = DATITrainer([tiny_env()], [0], cfg)
    before = {n: p.detach().clone() for n, p in trainer.nets.time2vec.named_parameters()}
    trainer.train_batch()
    assert any(not torch.equal(p, before[n]) for n, p in trainer.nets.time2vec.named_parameters())


def test_keep_final_ends_with_the_last_episodes_actor():
    cfg = DATIConfig(episodes=3, batch_size=8, patience=0, keep="final")
    trainer = DATITrainer([tiny_env(steps=6)], [0], cfg)
    final = trainer.train()
    live = dict(trainer.nets.named_parameters())
    for name, p in final.named_parameters():
        if name.startswith(("forward_actor.", "time2vec.")):
            torch.testing.assert_close(p, live[name], rtol=0, atol=0, msg=name)
    assert trainer.episode == [3]
    with pytest.raises(ValueError, match="keep"):
        DATIConfig(keep="last")


def test_each_seed_has_its_own_references_in_the_paper_preset():
    group = [(0, "circles", 0), (1, "circles", 1), (2, "circles", 0)]
    for preset, distinct in (("paper", True), ("ours", False)):
        settings = preset_settings(preset, references=4, steps=12)
        fams = {"circles": family_for("circles", 12, settings.exact_region)}
        refs, _ = evaluation_grid(group, settings, fams)
        alphas = [[r.label["alpha"] for r in row] for row in refs]
        assert alphas[0] == alphas[2]  # the same seed (another method) meets the same ones
        assert (alphas[0] != alphas[1]) is distinct
        if distinct:
            assert not set(alphas[0]) & set(alphas[1])


# -------------------------------------------------------------------- end to end
def test_paper_preset_runs_dati_and_bc_paper_with_repeats(tmp_path):
    settings = preset_settings(
        "paper",
        episodes=2,
        families=("circles", "ribbons"),
        seeds=2,
        references=2,
        steps=10,
        methods=("dati", "bc-paper"),
        repeats=2,
    )
    result = run_selftest(settings)
    assert [(f.method, f.family) for f in result.families] == [
        ("dati", "circles"),
        ("dati", "ribbons"),
        ("bc-paper", "circles"),
        ("bc-paper", "ribbons"),
    ]
    for f in result.families:
        assert sorted(m.seed for m in f.members) == [0, 1, 2, 3]
        assert [m.repeat for m in sorted(f.members, key=lambda m: m.seed)] == [0, 0, 1, 1]
        assert len(f.repeat_best) == 2 and all(math.isfinite(b) for b in f.repeat_best)
        for rep, best in enumerate(f.repeat_best):
            mine = [m.scores for m in f.members if m.repeat == rep]
            assert best == pytest.approx(np.nanmin(mine))
        assert f.summary.n == 8  # robust statistics pool every repeat
    dati = result.families[0]
    assert all(m.episodes == 2 for m in dati.members)  # no early stopping: the final actor


def test_cli_preset_repeats_and_bc_paper(cli, tmp_path):
    out = tmp_path / "run"
    result = cli(
        "selftest", "--out", out, "--family", "circles", "--seeds", "1",
        "--episodes", "1", "--steps", "10", "--references", "2", "--workers", "1",
        "--preset", "paper", "--repeats", "2", "--methods", "bc,bc-paper",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    doc = json.loads((out / "results.json").read_text())
    assert doc["settings"]["preset"] == "paper" and doc["settings"]["repeats"] == 2
    assert doc["settings"]["noise"] == "family"
    assert doc["settings"]["bc_paper"]["time_input"] is False
    rows = doc["results"]
    assert [r["method"] for r in rows] == ["bc", "bc-paper"]
    for r in rows:
        assert len(r["best_per_repeat"]) == 2 and r["repeats"] == 2
        assert r["best"] == pytest.approx(np.mean(r["best_per_repeat"]))
        assert r["best_sd"] == pytest.approx(np.std(r["best_per_repeat"], ddof=1))
    scores = pd.read_csv(out / "scores.csv")
    assert sorted(set(scores["repeat"])) == [0, 1] and sorted(set(scores["seed"])) == [0, 1]
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 2 and csv["best_per_repeat"].str.split().str.len().eq(2).all()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--preset", "nosuch"), "unknown self-test preset"),
        (("--repeats", "0"), "--repeats"),
    ],
    ids=["preset", "repeats"],
)
def test_bad_preset_options_are_one_line_errors(cli, tmp_path, args, message):
    out = tmp_path / "run"
    result = cli("selftest", "--out", out, "--family", "circles", *args)
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and message in lines[0]
    assert not out.exists()


def test_bc_config_round_trips_through_json_and_reads_older_cards():

    assert BCConfig.from_dict(json.loads(json.dumps(BC_PAPER.to_dict()))) == BC_PAPER
    old = {k: v for k, v in BCConfig().to_dict().items() if k not in ("time_input", "epochs")}
    assert BCConfig.from_dict(old) == BCConfig()


def test_parse_methods():
    assert parse_methods("DATI, bc,ddpg-ti,bc") == ("dati", "bc", "ddpg-ti")
    with pytest.raises(UserError, match="unknown method 'bogus'"):
        parse_methods("dati,bogus")
