"""Training any detector on an ingest folder (`aisdati.detectors.train`) on real Kitimat
tracks: the presets through the model card, the baselines under the lanes preset, every route
as one ensemble."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from aisdati.ais.card import CalibratedWith
from aisdati.ais.space import PRESETS, LaneConfig
from aisdati.ais.training import TrainSettings
from aisdati.detectors import ScoreSettings, load_detector
from aisdati.errors import UserError
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_preset_round_trips_through_the_model_card_and_old_cards_load(kitimat, tmp_path):
    from aisdati.detectors.train import train_detector

    table = read_track_table(kitimat)
    ids = tuple(int(i) for i in table["track_id"][:5])
    # one member: the cards below stand for cards from before lane configurations (one seed)
    lane = replace(PRESETS["lanes"], validation_tracks=2, validation_rollouts=1, members=1)
    settings = TrainSettings(
        data_dir=kitimat,
        cluster="other",
        out_dir=tmp_path,
        episodes=1,
        track_ids=ids,
        preset="lanes",
        lane=lane,
    )
    trained = train_detector("dati", settings, ScoreSettings(rollouts=2))
    card = json.loads(trained.model.with_suffix(".json").read_text())
    assert card["preset"] == "lanes" and LaneConfig.from_dict(card["lane_config"]) == lane
    assert card["training"]["selected_by"] == "validation rollouts"
    assert card["training"]["validation_dtw_m"][0] > 0
    assert (tmp_path / "other.corridor.npz").is_file()
    det = load_detector(tmp_path / "other")
    assert det.policy().space.config == lane and det.corridor is not None
    # the lane of K rollouts is never farther from a report than the best rollout's match
    # (by position: the course weight is a metric of its own)
    assert len(card["calibration"]["lane"]) == len(ids)
    # beside the scores, the alert budget's record of the training period: its vessel-days and
    # the strengths of the events it raised at the floors, strongest first
    # (`aisdati.events.calibrate`)
    assert card["calibration"]["event-days"][0] >= 1
    raised = [v for k, v in card["calibration"].items() if k.startswith("event:")]
    assert all(v == sorted(v, reverse=True) and min(v) >= 1 for v in raised)
    few = load_tracks(kitimat, list(ids[:2]))
    where = ScoreSettings(score="lane", rollouts=3, lane_course_km=0.0)
    lane_s = det.score(few, where, also=("rollout",))
    best_s = det.score(few, ScoreSettings(score="rollout", rollouts=3))
    for a, b in zip(lane_s.profiles, best_s.profiles, strict=True):
        assert np.all(a <= b + 1e-6)
    # the lane's longer rollouts begin with the rollout score's own: that score is unchanged,
    # and a lane that reaches further is nowhere farther from a report
    np.testing.assert_array_equal(lane_s.parts["rollout"], best_s.score)
    # the lane holds L rollouts, the K scored ones first, drawn as without a lane
    policy, starts = det.policy(), [t.positions for t in few]
    _, _, k3 = policy.rollout_scores(starts, 3, 0, 2.0)
    _, _, l7 = policy.rollout_scores(starts, 3, 0, 2.0, lane_rollouts=7)
    assert all(len(b) == 7 and np.array_equal(b[:3], a) for a, b in zip(k3, l7, strict=True))
    short = det.score(few, replace(where, lane_reach=1.0))
    for a, b in zip(lane_s.profiles, short.profiles, strict=True):
        assert np.all(a <= b + 1e-6)
    # the traffic rollouts: one from every training start, added to each track's own lane
    traffic = det.traffic(policy, where)
    assert len(traffic) == len(ids)
    np.testing.assert_allclose([t[0] for t in traffic], det.card.data.starts)
    alone = det.score(few, replace(where, lane_traffic=False))
    for a, b in zip(lane_s.profiles, alone.profiles, strict=True):
        assert np.all(a <= b + 1e-6) and np.any(a < b - 1.0)
    # thresholds need the traffic setting the model was calibrated with
    lane_how = ScoreSettings(score="lane")
    assert card["calibrated_with"]["lane_traffic"] is True and det.threshold(lane_how, 0.05) > 0
    with pytest.raises(UserError, match="calibrated with lane_traffic=True, not False"):
        det.threshold(replace(lane_how, lane_traffic=False), 0.05)
    course = det.card.calibrated_with.lane_course_km
    det.card.calibrated_with = CalibratedWith(lane_course_km=course)  # from before the traffic
    with pytest.raises(UserError, match="with lane_traffic=False, not True: score with its"):
        det.threshold(lane_how, 0.05)
    assert det.threshold(replace(lane_how, lane_traffic=False), 0.05) > 0
    # a card from before lane configurations and calibration: the paper's set-up (the paper's
    # state, so a model of the position alone), step score; with a wider state it is refused
    before = ("lane_config", "preset", "calibration", "files")  # what older cards lacked
    wide = {k: v for k, v in card.items() if k not in before}
    (tmp_path / "wide.json").write_text(json.dumps(wide))
    (tmp_path / "wide.pt").write_bytes((tmp_path / "other.pt").read_bytes())
    with pytest.raises(UserError, match="state_dim must be one of 2, got 26"):
        load_detector(tmp_path / "wide")
    plain = replace(settings, lane=replace(lane, fourier=0), stem="plain")
    train_detector("dati", plain, ScoreSettings(rollouts=2))
    card = json.loads((tmp_path / "plain.json").read_text())
    old = {k: v for k, v in card.items() if k not in before}
    (tmp_path / "old.json").write_text(json.dumps(old))
    (tmp_path / "old.pt").write_bytes((tmp_path / "plain.pt").read_bytes())
    det = load_detector(tmp_path / "old")
    assert det.policy().space.config == LaneConfig()
    tracks = load_tracks(kitimat, list(ids[:2]))
    assert np.isfinite(det.score(tracks, ScoreSettings(rollouts=2)).score).all()


def test_the_baselines_train_one_model_under_the_lanes_seed_ensemble(cli, kitimat, tmp_path):
    """The `lanes` preset trains DATI as three seeds; BC and `nearest` stay one model, their
    cards say so, and they load and score (a BC card once claimed three members, one seed)."""
    models = tmp_path / "models"
    for method in ("bc", "nearest"):
        r = cli("train", "--cluster", "route-2", "--data", kitimat, "--out", models,
                "--method", method, "--episodes", "1", "--max-tracks", "4")  # fmt: skip
        assert r.exit_code == 0, r.output
        det = load_detector(models / f"route-2-{method}")
        assert det.card.preset == "lanes" and det.card.lane_config.members == 1
        held = load_tracks(kitimat, read_track_table(kitimat).query("route == 'route-2'")
                           ["track_id"].tolist()[-2:])  # fmt: skip
        assert np.isfinite(det.score(held, ScoreSettings(rollouts=2)).score).all()
    assert len(load_detector(models / "route-2-bc").card.networks.seeds) == 1


def test_train_every_route_as_one_ensemble(kitimat, tmp_path):
    from aisdati.commands.train import route_settings
    from aisdati.detectors.train import train_routes

    data, models = kitimat, tmp_path / "models"
    models.mkdir()
    lane = ["validation_tracks=2", "validation_rollouts=1"]
    train_routes("dati", route_settings(data, models, None, lane, 1, 0, 10, 4), routes_per_task=0)
    routes = read_track_table(data)["route"].dropna().value_counts()
    trained = sorted(p.stem for p in models.glob("route-*.pt"))
    assert trained == sorted(n for n, c in routes.items() if c >= 5)
    seeds = set()
    for name in trained:
        card = json.loads((models / f"{name}.json").read_text())
        assert card["cluster"] == name and card["training"]["routes_in_ensemble"] == len(trained)
        assert card["data"]["tracks_used"] == 4 and card["calibration"]["rollout"]
        seeds.add(card["seed"])
    assert len(seeds) == len(trained)  # each route its own member
    det = load_detector(models / trained[0])
    assert det.policy().space.corridor is not None
