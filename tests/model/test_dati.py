"""The DATI trainer (ensemble = independent runs, early stopping, warm-up, the actor chosen by
validation), checkpoints and the evaluation statistics."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from aisdati.errors import UserError
from aisdati.model.dati import WARMUP_SPREAD, DATIConfig, DATITrainer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks, NetworkConfig
from aisdati.model.persistence import load_networks, network_bytes, network_meta
from aisdati.model.rollout import dati_policy, rollout_policy
from aisdati.selftest.families import get_family
from aisdati.selftest.protocol import evaluation_references
from aisdati.selftest.sources import FamilySource
from aisdati.selftest.summary import interquartile_mean, summarize

SMALL = DATIConfig(episodes=2, batch_size=16, patience=0)


def tiny_family(steps: int = 12):
    return replace(get_family("circles"), steps=steps)


def make_trainer(seeds, config: DATIConfig, steps: int = 12) -> DATITrainer:
    fam = tiny_family(steps)
    envs = [TrajectoryImitationEnv(FamilySource(fam)) for _ in seeds]
    return DATITrainer(envs, list(seeds), config)


def member_logs(trainer: DATITrainer, seed: int):
    return [log for log in trainer.history if log.seed == seed]


def assert_same_member(ensemble: DATITrainer, k: int, single: DATITrainer, atol=1e-5):
    """Member k of an ensemble behaved like the single-member run of the same seed."""
    seed = ensemble.seeds[k]
    assert single.seeds == [seed]
    mine, theirs = member_logs(ensemble, seed), member_logs(single, seed)
    assert [(x.episode, x.steps, x.stopped) for x in mine] == [
        (x.episode, x.steps, x.stopped) for x in theirs
    ]
    for x, y in zip(mine, theirs, strict=True):
        assert x.mean_loss == pytest.approx(y.mean_loss, rel=1e-5, abs=atol)
        assert x.final_dtw == pytest.approx(y.final_dtw, rel=1e-5, abs=atol)
        assert x.mean_reward == pytest.approx(y.mean_reward, abs=1e-9)
    assert ensemble.episode[k] == single.episode[0]
    assert ensemble.best_episode[k] == single.best_episode[0]
    single_final = dict(single.final.forward_actor.named_parameters())
    for name, p in ensemble.final.forward_actor.named_parameters():
        torch.testing.assert_close(p[k], single_final[name][0], rtol=0, atol=atol, msg=name)
    single_t2v = dict(single.final.time2vec.named_parameters())
    for name, p in ensemble.final.time2vec.named_parameters():
        torch.testing.assert_close(p[k], single_t2v[name][0], rtol=0, atol=atol, msg=name)


# ---------------------------------------------------------------------------- ensemble
def test_ensemble_equals_independent_runs():
    ensemble = make_trainer([3, 7], SMALL)
    ensemble.train()
    singles = [make_trainer([s], SMALL) for s in (3, 7)]
    for single in singles:
        single.train()
    assert len(ensemble.history) == 4
    for k, single in enumerate(singles):
        assert_same_member(ensemble, k, single)
    # both members are still in the live networks (nobody stopped early): compare those too
    for k, single in enumerate(singles):
        live = dict(single.nets.forward_actor.named_parameters())
        for name, p in ensemble.nets.forward_actor.named_parameters():
            torch.testing.assert_close(p[k], live[name][0], rtol=0, atol=1e-5, msg=name)
    # and the two members really are different runs
    a, b = member_logs(ensemble, 3), member_logs(ensemble, 7)
    assert a[-1].mean_loss != b[-1].mean_loss


def test_trainer_rejects_mismatched_seeds():
    env = TrajectoryImitationEnv(FamilySource(tiny_family()))
    with pytest.raises(ValueError):
        DATITrainer([env], [1, 2], SMALL)
    with pytest.raises(ValueError):
        DATITrainer([], [], SMALL)


# ---------------------------------------------------------------------------- early stopping
# With these settings seed 11's second episode has a higher mean loss than its first, so it
# stops at episode 2 with patience 1; seed 3's loss keeps falling over 4 episodes.
EARLY = DATIConfig(episodes=4, batch_size=16, patience=1)


def _train_with_snapshots(trainer: DATITrainer):
    """Train, keeping member 0's forward actor (and Time2Vec) at the end of every episode."""
    snapshots: dict[int, dict[str, torch.Tensor]] = {}

    def on_step(trainer, logs):
        for log in logs:
            if log.member == 0:
                snapshots[log.episode] = {
                    name: p[0].detach().clone()
                    for name, p in trainer.nets.named_parameters()
                    if name.startswith(("forward_actor.", "time2vec."))
                }

    trainer.train(on_step)
    return snapshots


def test_early_stopping_keeps_the_best_episode():
    trainer = make_trainer([11], EARLY)
    snapshots = _train_with_snapshots(trainer)
    logs = trainer.history
    assert trainer.done
    assert len(logs) < EARLY.episodes, "this seed is expected to stop early"
    assert logs[-1].stopped and not any(x.stopped for x in logs[:-1])
    losses = [x.mean_loss for x in logs]
    best = int(np.argmin(losses)) + 1
    assert trainer.best_episode[0] == best
    assert trainer.best_loss[0] == pytest.approx(min(losses))
    assert trainer.episode[0] == len(logs)
    assert best < len(logs)  # it stopped because it no longer improved
    assert trainer.wait[0] == len(logs) - best == EARLY.patience
    final = dict(trainer.final.named_parameters())
    for name, snap in snapshots[best].items():
        torch.testing.assert_close(final[name][0], snap, rtol=0, atol=0, msg=name)
    # training went on after the best episode, so the live actor moved away from the kept one
    live = dict(trainer.nets.forward_actor.named_parameters())
    assert any(not torch.equal(final[f"forward_actor.{n}"][0], p[0]) for n, p in live.items())
    # only the forward actor and Time2Vec are kept: the critics are untouched initial weights
    initial = DATINetworks(2, 2, EARLY.network, [11])
    torch.testing.assert_close(
        trainer.final.forward_critic.out.weight, initial.forward_critic.out.weight
    )


@pytest.fixture(scope="module")
def early_singles():
    """Seed 11 alone (stops at episode 2) and seed 3 alone (runs all 4 episodes)."""
    torch.set_num_threads(1)
    singles = {s: make_trainer([s], EARLY) for s in (11, 3)}
    for single in singles.values():
        single.train()
    assert singles[11].episode == [2] and singles[3].episode == [4]
    return singles


def test_member_that_stops_first_leaves_the_ensemble_unchanged(early_singles):
    """Seed 11 (last in the ensemble) stops at episode 2 and is dropped from the batched
    ensemble; seed 3 carries on alone exactly as in its own run (weights, optimiser state and
    buffers sliced right)."""
    ensemble = make_trainer([3, 11], EARLY)
    ensemble.train()
    assert ensemble.done and ensemble.active == []
    for k, seed in enumerate((3, 11)):
        assert_same_member(ensemble, k, early_singles[seed])


def test_member_stopping_after_an_earlier_drop_leaves_the_ensemble(early_singles):
    """As above with the order swapped: seed 11 (member 0) is dropped at episode 2, then
    seed 3 (member 1, now at position 0) stops at episode 4 and must leave too."""
    ensemble = make_trainer([11, 3], EARLY)
    ensemble.train()
    assert ensemble.done and ensemble.active == []
    for k, seed in enumerate((11, 3)):
        assert_same_member(ensemble, k, early_singles[seed])


def test_patience_zero_runs_every_episode():
    cfg = replace(EARLY, patience=0, episodes=3)
    trainer = make_trainer([11], cfg)
    trainer.train()
    assert [x.episode for x in trainer.history] == [1, 2, 3]
    assert [x.stopped for x in trainer.history] == [False, False, True]
    assert all(x.steps == 12 for x in trainer.history)
    # episode 2 was worse than episode 1 (see EARLY), yet training went on
    assert trainer.history[1].mean_loss > trainer.history[0].mean_loss


# ---------------------------------------------------------------------------- warm-up
def test_warmup_fills_the_buffer_with_near_perfect_decisions():
    cfg = DATIConfig(episodes=1, batch_size=64, buffer_capacity=500)
    trainer = make_trainer([5, 6], cfg, steps=200)
    buf = trainer.buffer
    assert buf.size == cfg.batch_size and buf.ptr == cfg.batch_size
    for k, env in enumerate(trainer.envs):
        data = {key: v[k, : cfg.batch_size] for key, v in buf.data.items()}
        steps = data["time"][:, 0].long().numpy()
        assert steps[0] == 0 and len(set(steps.tolist())) == cfg.batch_size
        ref = env.reference
        expected_states = env.source.features(ref.positions[steps], None, None)
        np.testing.assert_allclose(data["state"].numpy(), expected_states, atol=1e-6)
        np.testing.assert_allclose(data["perfect"].numpy(), env.perfect_actions[steps], atol=1e-6)
        spread = (data["action"] - data["perfect"]).abs()
        assert spread[0].max() == 0 and data["reward"][0] == 1.0
        assert spread.max() < 6 * WARMUP_SPREAD
        assert set(data["reward"][:, 0].tolist()) <= {-1.0, 1.0}
        assert torch.all(buf.data["state"][k, cfg.batch_size :] == 0)  # nothing past the warm-up

        noise = data["noise"]  # [64 transitions, 64 latent dimensions]
        assert noise.shape == (64, cfg.network.latent_dim)
        assert torch.unique(noise).numel() == noise.numel()  # independent, not broadcast
        per_dim = noise.std(dim=0)
        assert per_dim.mean() == pytest.approx(cfg.noise_sigma, abs=0.03)
        assert per_dim.min() > 0.15 and per_dim.max() < 0.45
        assert noise.std() == pytest.approx(cfg.noise_sigma, abs=0.02)
        assert noise.mean().abs() < 0.03
    # the members' warm-up noise comes from their own streams
    assert not torch.equal(buf.data["noise"][0, :64], buf.data["noise"][1, :64])


def test_latent_noise_processes():
    gens = [torch.Generator().manual_seed(s) for s in (1, 2)]
    gauss = DATIConfig().latent_noise(gens)
    draws = torch.cat([gauss.sample() for _ in range(200)], dim=1)  # [2, 200, 64]
    assert draws.std() == pytest.approx(0.3, abs=0.02)
    ou = DATIConfig(noise="ou").latent_noise([torch.Generator().manual_seed(1)])
    a, b = ou.sample(), ou.sample()
    # Ornstein-Uhlenbeck: small increments of σ sqrt(dt) from a state that persists
    assert (a.std() / 0.03) == pytest.approx(1.0, abs=0.3)
    assert (b - a).std() < 0.05
    ou.reset(0)
    assert torch.count_nonzero(ou.state) == 0


# ---------------------------------------------------------------------------- config
def test_config_round_trip():
    cfg = DATIConfig(
        episodes=7,
        batch_size=32,
        betas=(0.4, 0.8),
        noise="ou",
        patience=3,
        network=NetworkConfig(time_embedding=False, reward_input=False, hidden_units=24),
    )
    assert DATIConfig.from_dict(cfg.to_dict()) == cfg
    through_json = json.loads(json.dumps(cfg.to_dict()))
    assert DATIConfig.from_dict(through_json) == cfg
    assert DATIConfig.from_dict(DATIConfig().to_dict()) == DATIConfig()
    assert cfg.with_network(hidden_units=8).network.hidden_units == 8
    assert cfg.with_network(hidden_units=8).episodes == 7


# ---------------------------------------------------------------------------- checkpoints
@pytest.fixture
def saved(tmp_path):
    """Perturbed (so not re-creatable from the seeds) two-member networks, saved to disk."""
    cfg = SMALL
    nets = DATINetworks(2, 2, cfg.network, [3, 7])
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in nets.parameters():
            p.add_(torch.randn(p.shape, generator=g) * 0.05)
    stem = tmp_path / "model"
    stem.with_suffix(".pt").write_bytes(network_bytes(nets))
    card = {**network_meta(nets, cfg), "family": "circles", "note": "test"}
    stem.with_suffix(".json").write_text(json.dumps(card))
    return stem, nets, cfg


def _rollout(nets, cfg, seed):
    fam = tiny_family(12)
    refs = evaluation_references(fam, 2, 99)
    grid = [[TrajectoryImitationEnv(FamilySource(fam)) for _ in refs] for _ in range(2)]
    return rollout_policy(dati_policy(nets, cfg, len(refs), seed), grid, [refs, refs])


def test_save_load_gives_an_identical_rollout(saved):
    stem, nets, cfg = saved
    assert stem.with_suffix(".pt").is_file() and stem.with_suffix(".json").is_file()
    assert not list(stem.parent.glob("*.tmp"))
    loaded, cfg2, meta = load_networks(stem)
    assert cfg2 == cfg
    assert meta["seeds"] == [3, 7] and meta["family"] == "circles" and meta["note"] == "test"
    assert meta["state_dim"] == 2 and meta["decision_dim"] == 2
    ours, theirs = nets.state_dict(), loaded.state_dict()
    assert ours.keys() == theirs.keys()
    for key in ours:
        assert torch.equal(ours[key], theirs[key]), key
    a_paths, a_scores = _rollout(nets, cfg, seed=5)
    b_paths, b_scores = _rollout(loaded, cfg2, seed=5)
    assert a_scores.shape == (2, 2) and np.all(np.isfinite(a_scores))
    np.testing.assert_array_equal(a_scores, b_scores)
    for row_a, row_b in zip(a_paths, b_paths, strict=True):
        for pa, pb in zip(row_a, row_b, strict=True):
            assert pa.shape == (13, 2)
            np.testing.assert_array_equal(pa, pb)
    # another evaluation seed draws other noise
    c_scores = _rollout(loaded, cfg2, seed=6)[1]
    assert not np.array_equal(a_scores, c_scores)


def test_load_of_a_corrupt_weights_file_is_a_user_error(saved):
    stem, _, _ = saved
    stem.with_suffix(".pt").write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(UserError) as err:
        load_networks(stem)
    assert "\n" not in str(err.value)


def test_load_of_mismatched_weights_is_a_user_error(saved):
    stem, _, _ = saved
    torch.save({"foo": torch.zeros(3)}, stem.with_suffix(".pt"))
    with pytest.raises(UserError) as err:
        load_networks(stem)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    "card",
    [
        '{"hello": "world"}',
        "[1, 2, 3]",
        "not json at all",
        '{"format": "aisdati-dati/1"}',
    ],
    ids=["foreign", "list", "garbage", "incomplete"],
)
def test_load_of_a_foreign_card_is_a_user_error(saved, card):
    stem, _, _ = saved
    stem.with_suffix(".json").write_text(card)
    with pytest.raises(UserError) as err:
        load_networks(stem)
    assert "\n" not in str(err.value)


def test_load_of_missing_files_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="not found"):
        load_networks(tmp_path / "nothing")


# ---------------------------------------------------------------------------- statistics
def test_summarize_known_values():
    scores = np.array([[9.0, 1.0, 4.0, 100.0], [2.0, 50.0, 5.0, 3.0]])
    s = summarize(scores)
    assert s.n == 8
    assert s.best == 1.0
    assert s.median == pytest.approx(4.5)
    # middle 50 % of 1 2 3 4 5 9 50 100 is 3 4 5 9
    assert s.iqm == pytest.approx((3 + 4 + 5 + 9) / 4)
    assert interquartile_mean(scores.ravel()) == pytest.approx(5.25)
    assert s.iqm_low <= s.iqm <= s.iqm_high
    assert summarize(scores, resamples=200) == summarize(scores, resamples=200)  # seeded
    # non-finite scores are left out
    with_nan = summarize(np.append(scores.ravel(), [np.nan, np.inf]), resamples=200)
    assert with_nan.n == 8 and with_nan.iqm == pytest.approx(s.iqm)


def test_summarize_interval_on_a_larger_sample():
    x = np.random.default_rng(1).lognormal(size=100)
    s = summarize(x, resamples=1000)
    srt = np.sort(x)
    assert s.iqm == pytest.approx(srt[25:75].mean())
    assert s.median == pytest.approx(np.median(x))
    assert s.iqm_low < s.iqm < s.iqm_high
    assert s.iqm_high - s.iqm_low < 0.5 * s.iqm


def test_validation_selects_the_actor_with_the_best_validation_score():
    from aisdati.model.dati import DATIConfig, DATITrainer
    from aisdati.selftest.families import get_family
    from aisdati.selftest.sources import make_family_env

    scores = iter([5.0, 3.0, 4.0, 6.0, 7.0])
    snapshots = []

    def validate(trainer, k):
        snapshots.append(trainer.nets.forward_actor.out.weight.detach().clone())
        return next(scores)

    env = make_family_env(replace(get_family("circles"), steps=12))
    cfg = DATIConfig(episodes=5, batch_size=16, patience=0)
    trainer = DATITrainer([env], [0], cfg, validate)
    trainer.train()
    assert trainer.best_episode[0] == 2
    kept = trainer.final.forward_actor.out.weight
    assert torch.equal(kept, snapshots[1])
    assert [h.validation for h in trainer.history] == [5.0, 3.0, 4.0, 6.0, 7.0]
