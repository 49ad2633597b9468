"""Lane-learning levers on real Kitimat tracks: a seed ensemble trained and saved as one lane
model whose draws spread over its members, and the actors' pretraining on the
demonstrations."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from aisdati.ais.policy import dati_act, draw_rows
from aisdati.ais.space import PRESETS, lane_config
from aisdati.ais.training import TrainSettings, member_curves
from aisdati.detectors import ScoreSettings, load_detector
from aisdati.detectors.train import train_detector
from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.selftest.families import get_family
from aisdati.selftest.sources import make_family_env
from aisdati.tracks.store import load_tracks, read_track_table

SMALL = replace(PRESETS["lanes"], validation_tracks=2, validation_rollouts=1)


def _train(kitimat, tmp_path, lane, episodes=1):
    ids = tuple(int(i) for i in read_track_table(kitimat)["track_id"][:5])
    settings = TrainSettings(
        data_dir=kitimat,
        cluster="other",
        out_dir=tmp_path,
        episodes=episodes,
        track_ids=ids,
        lane=lane,
    )
    trained = train_detector("dati", settings, ScoreSettings(rollouts=4))
    return ids, json.loads(trained.model.with_suffix(".json").read_text())


def test_a_seed_ensemble_is_one_model_whose_draws_spread_over_its_members(kitimat, tmp_path):
    ids, card = _train(kitimat, tmp_path, replace(SMALL, members=3))
    assert card["seeds"] == [0, 1000, 2000] and card["lane_config"]["members"] == 3
    assert len(card["training"]["members"]) == 3
    assert all(m["episodes_run"] == 1 for m in card["training"]["members"])
    det = load_detector(tmp_path / "other")
    assert det.nets.members == 3
    # a track's draws take the members in turn: the spread policy's rows equal each member's
    width = det.nets.forward_actor.input_features.weight.shape[1]  # the state, then t
    obs = np.tile(np.r_[np.linspace(-0.2, 0.1, width), 3.0].astype(np.float32), (7, 1))
    rows = draw_rows(np.array([12345], np.uint64), range(7))  # 7 draws: 3 + 2 + 2
    member = rows.members(3)
    assert sorted(np.bincount(member)) == [2, 2, 3]
    spread = dati_act(det.nets, det.config)(rows, False)(obs)
    for m in range(3):
        own = dati_act(det.nets, det.config, member=m)(rows, False)(obs)
        # the same member on the same rows, in batches of other sizes: float rounding only
        np.testing.assert_allclose(spread[member == m], own[member == m], rtol=1e-5, atol=1e-6)
    assert not np.allclose(spread[member == 0][0], spread[member == 1][0])  # members differ
    tracks = load_tracks(kitimat, list(ids[:2]))
    assert np.isfinite(det.score(tracks, ScoreSettings(rollouts=3)).score).all()


def test_a_card_whose_seeds_do_not_match_its_members_is_refused(kitimat, tmp_path):
    _train(kitimat, tmp_path, replace(SMALL, members=2))
    card = json.loads((tmp_path / "other.json").read_text())
    card["seeds"] = card["seeds"][:1]
    (tmp_path / "other.json").write_text(json.dumps(card))
    with pytest.raises(UserError, match="seeds must be a list of 2"):
        load_detector(tmp_path / "other")


def test_members_option_is_checked():
    assert lane_config("lanes", ["members=4"]).members == 4
    for bad in ("members=0", "members=99", "members=two", "critic=state"):
        with pytest.raises(UserError):
            lane_config("lanes", [bad])


def test_routes_train_their_seed_ensembles_together(cli, kitimat, tmp_path):
    models = tmp_path / "models"
    r = cli(
        "train",
        "--cluster",
        "routes",
        "--data",
        kitimat,
        "--out",
        models,
        "--episodes",
        "1",
        "--max-tracks",
        "4",
        "--lane",
        "validation_tracks=2",
        "--lane",
        "validation_rollouts=1",
        "--lane",
        "members=2",
    )
    assert r.exit_code == 0, r.output
    seeds = []
    for path in sorted(models.glob("route-*.json")):
        if path.name.endswith(".log.json"):
            continue
        card = json.loads(path.read_text())
        assert len(card["seeds"]) == 2 and len(card["training"]["members"]) == 2
        assert load_detector(path.with_suffix("")).nets.members == 2
        seeds += card["seeds"]
    assert len(seeds) >= 4 and len(set(seeds)) == len(seeds)  # every member its own seed


def _forward_error(trainer: DATITrainer, demo) -> float:
    """Mean L1 of member 0's forward actor against the perfect decisions of a demonstration."""
    states, times, actions = (torch.as_tensor(x, dtype=torch.float32)[None] for x in demo)
    nets = trainer.nets
    with torch.no_grad():
        eta = torch.zeros(1, states.shape[1], nets.cfg.latent_dim)
        out = nets.forward_actor(states, eta, nets.time_features(times[..., None]))
    return float((out - actions).abs().mean())


def test_pretraining_makes_the_actor_follow_its_demonstrations():
    env = make_family_env(replace(get_family("circles"), steps=12))
    env.reset(seed=0)
    demo = env.demonstration(env.reference)
    assert demo[0].shape == (12, 2) and demo[1].shape == (12,) and demo[2].shape == (12, 2)
    np.testing.assert_allclose(demo[2], env.perfect_actions)
    cold = DATITrainer([env], [0], DATIConfig(batch_size=16))
    warm = DATITrainer([env], [0], DATIConfig(batch_size=16, pretrain_epochs=300))
    before = _forward_error(warm, demo)
    assert before == pytest.approx(_forward_error(cold, demo))  # same seed, same start
    warm.pretrain([demo])
    cold.pretrain([demo])  # 0 epochs, the paper's way: nothing changes
    assert _forward_error(cold, demo) == before
    assert _forward_error(warm, demo) < 0.5 * before
    assert not warm.history  # pretraining is no episode
    with pytest.raises(ValueError):
        warm.pretrain([demo, demo])


def test_pretrain_option_reaches_the_card(kitimat, tmp_path):
    with pytest.raises(UserError, match="pretrain"):
        lane_config("lanes", ["pretrain=-1"])
    _, card = _train(kitimat, tmp_path, replace(SMALL, pretrain=2))
    assert card["lane_config"]["pretrain"] == 2
    assert card["config"]["pretrain_epochs"] == 2


def test_the_pretrained_actor_is_kept_unless_an_episode_beats_it_on_validation():
    env = make_family_env(replace(get_family("circles"), steps=12))
    env.reset(seed=0)
    demo = env.demonstration(env.reference)

    calls: list[int] = []

    def validate(trainer: DATITrainer, k: int) -> float:
        calls.append(k)
        return 1.0 if len(calls) == 1 else 2.0  # no episode beats the warm start

    cfg = DATIConfig(episodes=2, batch_size=16, patience=0, pretrain_epochs=5)
    trainer = DATITrainer([env], [0], cfg, validate)
    trainer.pretrain([demo])
    assert trainer.pretrained_metric == [1.0]
    warm = {k: v.clone() for k, v in trainer.nets.forward_actor.state_dict().items()}
    final = trainer.train()
    assert [h.validation for h in trainer.history] == [2.0, 2.0]
    live = trainer.nets.forward_actor.state_dict()
    assert any(not torch.equal(warm[k], live[k]) for k in warm)  # training moved on
    kept = final.forward_actor.state_dict()
    assert all(torch.equal(warm[k], kept[k]) for k in warm)
    warm_start = trainer.pretrained_metric[0]
    assert member_curves(trainer.history, True, 2, warm_start)["best_episode"] == 0
    assert member_curves(trainer.history, True, 2, 3.0)["best_episode"] == 1


def test_a_member_can_leave_while_an_old_graph_is_still_alive():
    """A graph built before a member leaves (kept alive here as a reference cycle would keep
    it until the garbage collector runs) must not break the next training step."""
    envs = [make_family_env(replace(get_family("circles"), steps=12)) for _ in range(3)]
    trainer = DATITrainer(envs, [0, 1, 2], DATIConfig(batch_size=16))
    trainer.step()
    held = trainer.nets.time_features(torch.zeros(3, 1, 1))
    trainer.remove_members([0])
    trainer.step()
    assert trainer.nets.time2vec.phase.shape[0] == 2
    assert held[1].shape[0] == 3

