"""The self-test baselines (BC, DDPG-TI) and DATI ablations: learning, wiring, CLI end to end."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch
from line_family import LINE

from aisdati.errors import UserError
from aisdati.model.bc import BCConfig, BCTrainer, bc_act
from aisdati.model.networks import DATINetworks
from aisdati.model.rollout import rollout_policy
from aisdati.selftest.paper import PAPER_TABLE1
from aisdati.selftest.protocol import evaluation_references
from aisdati.selftest.settings import ABLATION, SelftestSettings, parse_methods
from aisdati.selftest.sources import make_family_env


def _bc_scores(trainer: BCTrainer, refs: int = 5) -> np.ndarray:
    references = evaluation_references(LINE, refs, 1)
    act = bc_act(trainer.policy, refs, seed=1)
    grid = [[make_family_env(LINE) for _ in references] for _ in trainer.seeds]
    return rollout_policy(act, grid, [references] * len(trainer.seeds))[1]


def test_bc_learns_a_straight_line_family_in_a_few_hundred_updates():
    torch.set_num_threads(1)
    untrained = _bc_scores(BCTrainer([make_family_env(LINE)], [0], BCConfig(episodes=0)))
    trainer = BCTrainer([make_family_env(LINE)], [0], BCConfig(episodes=30))
    trainer.train()  # 30 episodes x 20 pairs, one update of 64 per pair: 600 updates
    scores = _bc_scores(trainer)
    assert untrained.min() > 0.3
    assert scores.max() < 0.03, scores  # stochastic rollouts on their own predictions
    assert trainer.losses[-1][0] < trainer.losses[0][0]


def test_bc_ensemble_trains_each_seed_as_if_alone():
    cfg = BCConfig(episodes=2, updates_per_episode=5)
    pair = BCTrainer([make_family_env(LINE) for _ in range(2)], [3, 4], cfg)
    alone = BCTrainer([make_family_env(LINE)], [4], cfg)
    pair.train(), alone.train()
    for a, b in zip(pair.losses, alone.losses, strict=True):
        assert a[1] == pytest.approx(b[0], rel=1e-5, abs=1e-6)


def test_bc_policy_has_the_papers_shape():
    policy = BCTrainer([make_family_env(LINE)], [0]).policy
    assert policy.feature_width == 156
    widths = [w.shape[1] for w in policy.hidden.first.weights]
    assert widths == [80, 1, 75]  # 80 state features + Time2Vec(76)
    hidden = [m for m in policy.hidden.rest if hasattr(m, "weight")]
    assert len(hidden) == 3 and all(m.weight.shape[1:] == (32, 32) for m in hidden)


def test_environment_passes_sb3_check_env():
    from stable_baselines3.common.env_checker import check_env

    check_env(make_family_env(LINE), warn=False)
    check_env(make_family_env("circles"), warn=False)


def _count(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def test_ablation_flags_remove_the_inputs():
    settings = SelftestSettings()
    full = DATINetworks(2, 2, settings.dati_config("dati").network, [0])
    no_time = DATINetworks(2, 2, settings.dati_config("dati-no-time-embedding").network, [0])
    no_reward = DATINetworks(2, 2, settings.dati_config("dati-no-reward-input").network, [0])

    def first_widths(net):
        return [w.shape[1] for w in net.hidden.first.weights]

    # full: actors see (input 16, noise 16, time 1 + 75); critics (input 16, time, reward 92)
    assert first_widths(full.forward_actor) == [16, 16, 1, 75]
    assert first_widths(full.forward_critic) == [16, 1, 75, 92]
    # no time embedding: no Time2Vec anywhere, the time blocks are gone from every network
    assert no_time.time2vec is None and no_time.time_features(torch.zeros(1, 1, 1)) == []
    assert first_widths(no_time.forward_actor) == [16, 16]
    assert first_widths(no_time.backward_critic) == [16, 16]
    # no reward input: critics lose the reward layer and block, actors are untouched
    assert no_reward.forward_critic.reward_features is None
    assert first_widths(no_reward.forward_critic) == [16, 1, 75]
    assert _count(no_reward.forward_actor) == _count(full.forward_actor)
    reward_params = 92 * 92 + 92 + 92 * 32  # tiled-reward layer and its first-layer block
    assert _count(full.forward_critic) - _count(no_reward.forward_critic) == reward_params
    assert _count(no_time) < _count(full)


def test_parse_methods():
    assert parse_methods("DATI, bc,ddpg-ti,bc") == ("dati", "bc", "ddpg-ti")
    with pytest.raises(UserError, match="unknown method 'bogus'"):
        parse_methods("dati,bogus")


@pytest.mark.parametrize(
    "args",
    [
        ("--methods", "bogus"),
        ("--methods", ","),
        ("--methods", "table2,bc"),
    ],
)
def test_bad_methods_are_one_line_errors(cli, tmp_path, args):
    result = cli("selftest", "--out", tmp_path / "o", *args)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:")


TINY = ("--seeds", "1", "--references", "2", "--workers", "1")


def test_table1_methods_end_to_end(cli, tmp_path):
    out = tmp_path / "t1"
    result = cli(
        "selftest", "--methods", "dati,bc,ddpg-ti", "--family", "circles",
        "--episodes", "2", "--steps", "20", "--out", out, *TINY,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "Table 1" in result.output and "DDPG-TI" in result.output
    rows = pd.read_csv(out / "results.csv")
    assert list(rows["method"]) == ["dati", "bc", "ddpg-ti"]
    assert list(rows["paper_best"]) == [PAPER_TABLE1[m]["circles"] for m in rows["method"]]
    assert (rows["best"] <= rows["second_best"]).all() and (rows["mean_episodes"] == 2).all()
    scores = pd.read_csv(out / "scores.csv")
    assert sorted(scores["method"].unique()) == ["bc", "dati", "ddpg-ti"]
    assert len(scores) == 3 * 2 and np.isfinite(scores["score"]).all()
    doc = json.loads((out / "results.json").read_text())
    assert doc["settings"]["methods"] == ["dati", "bc", "ddpg-ti"]
    assert doc["settings"]["bc"]["episodes"] == doc["settings"]["ddpg"]["episodes"] == 2
    assert (out / "rollouts.png").stat().st_size > 0


def test_ablation_end_to_end(cli, tmp_path):
    out = tmp_path / "t2"
    result = cli("selftest", "--methods", "table2", "--episodes", "1", "--steps", "10",
                 "--out", out, *TINY)
    assert result.exit_code == 0, result.output
    assert "ablation" in result.output and "top-2" in result.output
    rows = pd.read_csv(out / "results.csv")
    assert tuple(rows["method"]) == ABLATION and set(rows["family"]) == {"circles"}
    assert list(rows["paper_best"]) == [0.058, 1.829, 0.305]
    assert list(rows["paper_second_best"]) == [0.074, 1.976, 0.451]
