"""The detectors and what DATI needs to follow lanes, on real Kitimat tracks: exact nearest-track
search, teacher-forced step scores, the corridor, validation selection, the enlarged state, the
presets through the model card."""

from __future__ import annotations

import json
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch

from aisdati.ais.card import CalibratedWith
from aisdati.ais.corridor import TURNS_DEG, Corridor
from aisdati.ais.policy import AISPolicy
from aisdati.ais.source import build_source, make_env, track_reference
from aisdati.ais.space import PRESETS, LaneConfig, lane_config
from aisdati.ais.training import TrainSettings
from aisdati.detectors import ScoreSettings, load_detector
from aisdati.detectors.nearest import NearestDetector
from aisdati.dtw import dtw_path_length, nearest_mean_dtw_m
from aisdati.errors import UserError
from aisdati.evaluation.inject import inject
from aisdati.tracks.store import load_tracks, read_track_table


def nearest(tracks, how=None):
    """A fitted `nearest` (the paper's lane set-up: its card needs no corridor)."""
    return NearestDetector(TrainSettings(lane=LaneConfig()), how).fit(tracks)


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_nearest_search_is_exact_despite_pruning(tracks):
    queries = [t.positions for t in tracks[:6]]
    refs = [t.positions for t in tracks[6:]]
    cands = [np.arange(len(refs))] * len(queries)
    dist, arg = nearest_mean_dtw_m(queries, refs, cands)
    for q, d, a in zip(queries, dist, arg, strict=True):
        brute = [c / n for c, n in (dtw_path_length(q, r, "haversine") for r in refs)]
        assert d == pytest.approx(min(brute), rel=1e-9)
        assert brute[a] == pytest.approx(d, rel=1e-9)


def test_nearest_calibration_leaves_each_vessel_out(tracks):
    det = nearest(tracks)
    cal = np.asarray(det.card.calibration["nearest"])
    assert np.all(cal > 0)  # no track is compared with itself or its own vessel
    scored = det.score(tracks[:3], ScoreSettings())
    np.testing.assert_allclose(scored.score, 0.0, atol=1e-6)  # its own training tracks


def _perfect_policy(space, tracks, draws):
    """A policy that takes every track's own perfect decisions: it reproduces them exactly."""
    scaled = np.concatenate(
        [space.rule.decision_scaler.scale(space.rule.perfect_decisions(t.positions, t.dts))
         for t in tracks]
    ).repeat(draws, axis=0)

    def make(rows, temporal):
        return lambda obs: scaled[: len(obs)]

    return AISPolicy(space, make)


def test_step_errors_of_a_model_that_reproduces_the_tracks_are_zero(tracks):
    space = build_source(tracks, LaneConfig()).space
    policy = _perfect_policy(space, tracks[:5], draws=3)
    errors, predicted = policy.step_errors(
        [t.positions for t in tracks[:5]], [t.dts for t in tracks[:5]], 3
    )
    for e, p, t in zip(errors, predicted, tracks[:5], strict=True):
        assert len(e) == len(t.positions) - 1
        assert e.max() < 1e-3  # metres
        np.testing.assert_allclose(p, t.positions[1:], atol=1e-9)


def _dead_reckoning(space):
    """Continue at the current course and speed (read from the motion state)."""

    def make(rows, temporal):
        def act(obs):
            sog = obs[:, 4] * space.rule.max_sog
            cog = np.degrees(np.arctan2(obs[:, 2], obs[:, 3]))
            decision = np.stack([sog, cog, np.full(len(obs), 0.05)], axis=1)
            return space.rule.decision_scaler.scale(decision)

        return act

    return make


def test_a_position_jump_gives_the_largest_step_error(tracks):
    t = tracks[3]
    times = np.r_[0.0, np.cumsum(t.dts)] * 3600.0
    got = inject("jump", t.positions, times, np.random.default_rng(0))
    i, j = got.stretch
    space = build_source(tracks, LaneConfig(state="motion")).space
    policy = AISPolicy(space, _dead_reckoning(space))
    (errors,), _ = policy.step_errors([got.positions], [np.diff(got.times_s) / 3600.0], 1)
    peak = int(np.argmax(errors)) + 1  # error k is at report k + 1
    # at the jump itself, or the report after it (dead reckoning carries the jump one step on)
    assert min(abs(peak - i), abs(peak - j)) <= 1, (peak, i, j)
    assert errors.max() > 2500


def test_corridor_refuses_steps_out_of_it_and_onto_land(tracks):
    positions = [t.positions for t in tracks]
    corridor = Corridor.from_tracks(positions, buffer_km=1.0)
    assert corridor.allowed(np.concatenate(positions)).all()
    far = positions[0][:1] + np.array([0.3, 0.3])
    assert not corridor.allowed(far).any()
    # a step straight out of the corridor is refused or turned into it, never taken
    here = positions[0][10:11]
    out = corridor.slide(here, here + np.array([0.2, 0.0]))
    assert corridor.allowed(out).all()
    # with a coastline saying "land" east of a meridian, no cell there is allowed
    cut = float(np.median(np.concatenate(positions)[:, 0]))
    dry = Corridor.from_tracks(positions, 1.0, on_land=lambda lon, lat: lon > cut + 0.05)
    pts = np.concatenate(positions)
    east = pts[pts[:, 0] > cut + 0.06]
    assert dry.allowed(east).all()  # where ships sailed stays water
    probe = east + np.array([0.008, 0.0])
    onland = probe[~corridor.allowed(probe) | (probe[:, 0] > cut + 0.05)]
    assert not (dry.allowed(onland) & ~corridor.allowed(onland)).any()


def _slide_by_numpy(corridor, position, proposed):
    """The slide rule as numpy states it: a move no farther from the corridor is taken, else
    the smallest turn (15, -15, 30, ... 180 degrees) of the same step that is, else none."""
    limit = corridor.gap_m(position)
    finite = np.isfinite(proposed).all(axis=1)
    out = np.where((finite & (corridor.gap_m(proposed) <= limit))[:, None], proposed, position)
    coslat = np.cos(np.radians(position[:, 1]))
    d = (proposed - position) * np.column_stack([coslat, np.ones_like(coslat)])
    for k in np.flatnonzero(finite & (corridor.gap_m(proposed) > limit)):
        for turn in TURNS_DEG:
            a = np.radians(turn)
            rx = d[k, 0] * np.cos(a) + d[k, 1] * np.sin(a)
            ry = -d[k, 0] * np.sin(a) + d[k, 1] * np.cos(a)
            cand = position[k] + np.array([rx / coslat[k], ry])
            if corridor.gap_m(cand[None])[0] <= limit[k]:
                out[k] = cand
                break
    return out


def test_the_compiled_slide_is_the_rule_to_the_last_bit(tracks):
    positions = [t.positions for t in tracks]
    corridor = Corridor.from_tracks(positions, buffer_km=1.0)
    rng = np.random.default_rng(3)
    pts = np.concatenate(positions)
    start = pts[rng.integers(0, len(pts), 3000)] + rng.normal(0, 0.02, (3000, 2))
    course, step_deg = rng.uniform(0, 2 * np.pi, 3000), rng.uniform(0.0005, 0.03, 3000)
    moved = start + step_deg[:, None] * np.column_stack([np.sin(course), np.cos(course)])
    moved[:30, 0] = np.nan  # a broken decision stays where it is
    got = corridor.slide(start, moved)
    np.testing.assert_array_equal(got, _slide_by_numpy(corridor, start, moved))
    assert 0 < (got != moved).any(axis=1).mean() < 1  # some moves taken, some turned or refused


def test_an_agent_at_the_closed_end_of_a_channel_turns_round():
    # a channel 20 km long running east from 129 W at 53 N, 1 km either side
    channel = np.column_stack([np.linspace(-129.0, -128.7, 60), np.full(60, 53.0)])
    corridor = Corridor.from_tracks([channel], buffer_km=1.0)
    tip = channel[:1]
    west = tip + np.array([[-0.045, 0.0]])  # 3 km further west: out of the channel
    got = corridor.slide(tip, west)
    # a quarter turn leaves the channel too (3 km north or south); turned (nearly) round it
    # sails east along the channel
    assert not corridor.allowed(tip + np.array([[0.0, 0.027], [0.0, -0.027]])).any()
    assert corridor.allowed(got).all() and got[0, 0] > tip[0, 0] + 0.04


def test_env_with_a_corridor_never_leaves_it(tracks):
    source = build_source(tracks[:8], LaneConfig(region="corridor", corridor_km=1.0))
    env = make_env(source)
    env.reset(seed=0, options={"reference": track_reference(tracks[0])})
    rng = np.random.default_rng(0)
    for _ in range(60):
        env.step(rng.uniform(-1, 1, 3).astype(np.float32))
        assert source.space.contains(env.position)


def test_an_agent_outside_the_corridor_moves_in_and_then_stays(tracks):
    space = build_source(tracks[:8], LaneConfig(region="corridor", corridor_km=1.0)).space
    corridor = space.corridor
    lo, hi = space.bounds
    grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 60), np.linspace(lo[1], hi[1], 60)), -1)
    grid = grid.reshape(-1, 2)
    gaps = corridor.gap_m(grid)
    start = grid[np.argmin(np.abs(gaps - 3000))]  # a start ~3 km off the lanes
    assert not space.contains(start) and space.in_box(start)
    g0 = corridor.gap_m(start[None])[0]
    moves = 0.01 * np.array([[np.cos(a), np.sin(a)] for a in np.radians(np.arange(0, 360, 45))])
    # a move that takes it no farther from the corridor is taken as it is (held to moves that
    # enter at once, a policy may never leave its start)
    for move in moves:
        got = space.resolve(start, start + move)
        if corridor.gap_m((start + move)[None])[0] <= g0:
            np.testing.assert_array_equal(got, start + move)  # no farther: taken
        else:  # farther: turned until it is not, or refused
            assert corridor.gap_m(got[None])[0] <= g0
            assert np.array_equal(got, start) or not np.allclose(got, start + move)
    # an agent that steps towards the corridor gets in, and then never leaves it
    pos = start
    for _ in range(40):
        step = min(moves, key=lambda m: corridor.gap_m((pos + m)[None])[0])
        pos = space.resolve(pos, pos + step)
        if space.contains(pos):
            break
    assert space.contains(pos) and corridor.gap_m(pos[None])[0] == 0
    for move in moves * 20:
        assert space.contains(space.resolve(pos, pos + move))
    # a step out of the box is refused wherever the agent is
    np.testing.assert_array_equal(space.resolve(start, start + np.array([0.0, 5.0])), start)


def test_enlarged_state_shape_scaling_and_env_checker(tracks):
    from gymnasium.utils.env_checker import check_env

    source = build_source(tracks[:8], LaneConfig(state="motion"))
    env = make_env(source)
    assert env.observation_space.shape == (6,)
    check_env(env, skip_render_check=True)
    ref = track_reference(tracks[0])
    obs, _ = env.reset(seed=0, options={"reference": ref})
    assert np.all(obs[2:5] == 0) and obs[5] == 0  # no motion yet, step 0
    for k, action in enumerate(env.perfect_actions[:20]):
        obs, *_ = env.step(action)
        sog, cog, _ = source.rule.perfect_decisions(ref.positions, ref.dts)[k]
        assert obs[2] == pytest.approx(np.sin(np.radians(cog)), abs=1e-4)
        assert obs[3] == pytest.approx(np.cos(np.radians(cog)), abs=1e-4)
        assert obs[4] == pytest.approx(sog / source.rule.max_sog, abs=1e-4)
        assert obs[5] == k + 1  # the step index, the paper's time input
        assert env.observation_space.contains(obs)


def test_fourier_state_encodes_the_position_at_each_octave(tracks):
    from gymnasium.utils.env_checker import check_env

    plain = build_source(tracks[:8], LaneConfig(state="motion")).space
    source = build_source(tracks[:8], LaneConfig(state="motion", fourier=3))
    space = source.space
    assert space.state_dim == 5 + 12
    env = make_env(source)
    assert env.observation_space.shape == (18,)
    check_env(env, skip_render_check=True)
    pos, prev, dts = tracks[0].positions[1:], tracks[0].positions[:-1], tracks[0].dts
    got, base = space.features(pos, prev, dts), plain.features(pos, prev, dts)
    np.testing.assert_array_equal(got[:, :5], base)  # the paper's view comes first, unchanged
    for coord in range(2):  # lon's 3 sines and 3 cosines, then lat's
        for octave in range(3):
            angle = np.pi * 2**octave * base[:, coord]
            np.testing.assert_allclose(got[:, 5 + 6 * coord + octave], np.sin(angle))
            np.testing.assert_allclose(got[:, 8 + 6 * coord + octave], np.cos(angle))
    lo, hi = space.state_bounds
    assert np.all(got >= lo - 1e-12) and np.all(got <= hi + 1e-12)
    with pytest.raises(UserError, match="fourier"):
        LaneConfig(fourier=-1)


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


def test_lane_presets_and_overrides():
    from aisdati.errors import UserError

    assert lane_config("paper") == LaneConfig()
    cfg = lane_config("paper", ["validation=true", "region=corridor", "corridor_km=3"])
    assert cfg.validation and cfg.region == "corridor" and cfg.corridor_km == 3.0
    assert lane_config("lanes") == PRESETS["lanes"]
    for bad in (["validation=maybe"], ["nope=1"], ["corridor_km=-1"], ["time=hours"]):
        with pytest.raises(UserError):
            lane_config("paper", bad)
    with pytest.raises(UserError):
        lane_config("fancy")


def test_preset_round_trips_through_the_model_card_and_old_cards_load(kitimat, tmp_path):
    from aisdati.detectors.train import train_detector

    table = read_track_table(kitimat)
    ids = tuple(int(i) for i in table["track_id"][:5])
    # one member: the cards below stand for cards from before lane configurations (one seed)
    lane = replace(PRESETS["lanes"], validation_tracks=2, validation_rollouts=1, members=1)
    settings = TrainSettings(
        data_dir=kitimat, cluster="other", out_dir=tmp_path, episodes=1, track_ids=ids,
        preset="lanes", lane=lane,
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


def test_gym_space_of_the_paper_state_is_unchanged(tracks):
    env = make_env(build_source(tracks[:4], LaneConfig()))
    assert env.observation_space.shape == (3,)
    assert isinstance(env.action_space, gym.spaces.Box)


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


def test_lane_distances_equal_the_brute_force_nearest_great_circle_distance(tracks):
    from aisdati.geo import haversine_m, lane_distances

    track, lane = tracks[0].positions, np.concatenate([t.positions for t in tracks[1:4]])
    brute = haversine_m(
        track[:, None, 0], track[:, None, 1], lane[None, :, 0], lane[None, :, 1]
    ).min(axis=1)
    np.testing.assert_allclose(lane_distances(track, [lane]), brute, rtol=1e-6, atol=1e-3)


def test_the_course_weighted_lane_distance_is_the_brute_force_minimum(tracks):
    from aisdati.geo import courses_deg, haversine_m, lane_distances

    track, lane = tracks[0].positions, [t.positions for t in tracks[1:4]]
    cloud = np.concatenate(lane)
    courses = np.concatenate([courses_deg(p) for p in lane])
    dtheta = np.radians(courses_deg(track)[:, None] - courses[None, :])
    gc = haversine_m(track[:, None, 0], track[:, None, 1], cloud[None, :, 0], cloud[None, :, 1])
    brute = np.hypot(gc, 3000.0 * np.sin(dtheta / 2)).min(axis=1)
    np.testing.assert_allclose(lane_distances(track, lane, 3000.0), brute, rtol=1e-6, atol=1e-3)


def test_sailing_a_lane_backwards_costs_the_course_weight(tracks):
    from aisdati.geo import lane_distances

    track = tracks[0].positions
    np.testing.assert_allclose(lane_distances(track, [track], 3000.0), 0.0, atol=1e-6)
    backwards = lane_distances(track[::-1], [track], 3000.0)
    assert np.all(backwards <= 3000.0 + 1e-6)
    assert np.median(backwards) > 2500.0  # the same places, the opposite way
    np.testing.assert_allclose(lane_distances(track[::-1], [track]), 0.0, atol=1e-6)


def test_a_threshold_needs_the_course_weight_the_model_was_calibrated_with(tracks):
    det = nearest(tracks, ScoreSettings(lane_course_km=2.0))
    assert det.card.calibrated_with.lane_course_km == 2.0
    how = ScoreSettings(score="lane", lane_course_km=2.0)
    assert det.threshold(how, 0.05) > 0
    with pytest.raises(UserError, match=r"calibrated with lane_course_km=2\.0, not 0\.0"):
        det.threshold(replace(how, lane_course_km=0.0), 0.05)
    det.card.calibrated_with = None  # a card from before the course weight
    assert det.threshold(replace(how, lane_course_km=0.0), 0.05) > 0


def test_nearest_calibrates_a_route_sailed_by_one_vessel_on_its_other_tracks(tracks):
    ferry = [replace(t, mmsi=100000001) for t in tracks[:6]]  # one boat runs the whole line
    det = nearest(ferry)
    for key in ("nearest", "lane"):
        cal = np.asarray(det.card.calibration[key])
        assert len(cal) == 6 and np.all(np.isfinite(cal)) and np.all(cal > 0)
    assert det.threshold(ScoreSettings(score="lane"), 0.05) > 0


def test_nearest_lane_score_sees_a_jump_and_is_calibrated_per_vessel(kitimat):
    table = read_track_table(kitimat)
    held, *lane = load_tracks(kitimat, table.loc[table["route"] == "route-1", "track_id"][:20])
    det = nearest([t for t in lane if t.mmsi != held.mmsi])
    assert np.all(np.asarray(det.card.calibration["lane"]) >= 0)
    times = np.r_[0.0, np.cumsum(held.dts)] * 3600.0
    params = {"jump": {"span": (0.1, 0.2), "km": (5.0, 5.0)}}
    got = inject("jump", held.positions, times, np.random.default_rng(1), params)
    jumped = replace(held, positions=got.positions, dts=np.diff(got.times_s) / 3600.0)
    how = ScoreSettings(score="lane")
    scored = det.score([held, jumped], how, also=("nearest",))
    assert set(scored.parts) == {"nearest", "lane"}
    assert scored.score[1] > scored.score[0] + 2000  # the jumped stretch is 5 km off
    assert len(scored.profiles[1]) == len(jumped.positions)
    assert det.calibration_key(how) == "lane" and det.threshold(how, 0.05) > 0


def test_the_tail_fraction_runs_from_the_largest_deviation_to_the_mean(tracks):
    det = nearest(tracks[3:])
    times = np.r_[0.0, np.cumsum(tracks[0].dts)] * 3600.0
    jumped = inject("jump", tracks[0].positions, times, np.random.default_rng(1))
    how = ScoreSettings(score="lane")
    profile = det.training_tracks.lane_scores([jumped.positions], how)[1][0]
    by_tail = {
        f: det.training_tracks.lane_scores([jumped.positions], replace(how, tail=f))[0][0]
        for f in (1e-9, 0.1, 0.5, 1.0)
    }
    assert by_tail[1e-9] == pytest.approx(profile.max())  # at least one report: the worst
    assert by_tail[1.0] == pytest.approx(profile.mean())
    k = int(np.ceil(0.1 * len(profile)))
    assert by_tail[0.1] == pytest.approx(np.sort(profile)[-k:].mean())
    assert by_tail[1e-9] > by_tail[0.1] > by_tail[0.5] > by_tail[1.0]
