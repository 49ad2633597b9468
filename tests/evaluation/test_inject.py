"""Anomalies written into a real Kitimat track (`aisdati.evaluation.inject`), one kind at a
time: each changes what it says it changes (positions, times, reported motion) and nothing
else; and a 3 km detour that `nearest` and DATI score above its source."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.evaluation.inject import DEFAULTS, DRIFT_MIN_S, SPEED_REPORTS, inject, parse_params
from aisdati.events.behaviour import angle_apart
from aisdati.geo import haversine_m
from aisdati.tracks.schema import KNOT_MPS
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def track(kitimat):
    table = read_track_table(kitimat)
    tid = int(table.sort_values("n_points").iloc[len(table) // 2]["track_id"])
    (t,) = load_tracks(kitimat, [tid])
    return t


@pytest.fixture(scope="module")
def motion(kitimat, track):
    """The track's reported SOG and COG (points.parquet), and a heading of COG + 5 degrees."""
    import pyarrow.parquet as pq

    pts = pq.read_table(kitimat / "points.parquet", filters=[("track_id", "=", track.track_id)])
    pts = pts.sort_by("time")
    sog, cog = pts["sog"].to_numpy().astype(float), pts["cog"].to_numpy().astype(float)
    return np.column_stack([sog, cog, (cog + 5.0) % 360.0])


def _times(t):
    return np.r_[0.0, np.cumsum(t.dts)] * 3600.0


def _dist(a, b):
    return haversine_m(a[:, 0], a[:, 1], b[:, 0], b[:, 1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_detour_moves_only_its_stretch_by_at_most_its_amplitude(track, seed):
    got = inject("detour", track.positions, _times(track), np.random.default_rng(seed))
    i, j = got.stretch
    d = _dist(got.positions, track.positions)
    assert np.all(d[:i] == 0) and np.all(d[j:] == 0)
    lo, hi = DEFAULTS["detour"]["span"]
    assert lo * len(d) - 1 <= j - i <= hi * len(d) + 1
    assert 0.9 * 2000 * np.sin(np.pi * 0.45) ** 2 < d[i:j].max() <= 5000 * 1.01
    np.testing.assert_array_equal(got.times_s, _times(track))


def test_jump_displaces_a_stretch_by_one_vector(track):
    got = inject("jump", track.positions, _times(track), np.random.default_rng(3))
    i, j = got.stretch
    d = _dist(got.positions, track.positions)
    assert np.all(d[:i] == 0) and np.all(d[j:] == 0)
    assert np.all((d[i:j] > 2990) & (d[i:j] < 6010))
    assert d[i:j].max() - d[i:j].min() < 50  # one displacement for the whole stretch


def test_loiter_inserts_circles_and_shifts_later_times(track):
    t = _times(track)
    got = inject("loiter", track.positions, t, np.random.default_rng(4))
    i, j = got.stretch
    m = j - i
    np.testing.assert_array_equal(got.positions[:i], track.positions[:i])
    np.testing.assert_array_equal(got.positions[j:], track.positions[i:])
    assert np.all(np.diff(got.times_s) > 0)
    shift = got.times_s[j:] - t[i:]
    assert np.allclose(shift, shift[0]) and shift[0] > 0
    ring = got.positions[i:j]
    centre = ring.mean(axis=0)
    radius = _dist(ring, np.repeat(centre[None], m, 0))
    assert 400 < np.median(radius) < 1600 and m >= 8


def test_speed_keeps_positions_and_scales_the_stretch_times(track):
    t = _times(track)
    got = inject("speed", track.positions, t, np.random.default_rng(5))
    i, j = got.stretch
    np.testing.assert_array_equal(got.positions, track.positions)
    ratio = np.diff(got.times_s)[i - 1 : j - 1] / np.diff(t)[i - 1 : j - 1]
    assert np.allclose(ratio, ratio[0])
    assert ratio[0] == pytest.approx(1 / 0.3) or 1 / 3 <= ratio[0] <= 1 / 2
    np.testing.assert_allclose(np.diff(got.times_s)[: i - 1], np.diff(t)[: i - 1])


def test_gap_removes_a_stretch(track):
    got = inject("gap", track.positions, _times(track), np.random.default_rng(6))
    removed = len(track.positions) - len(got.positions)
    lo, hi = DEFAULTS["gap"]["span"]
    assert lo * len(track.positions) - 1 <= removed <= hi * len(track.positions) + 1
    i = got.stretch[0] + 1
    np.testing.assert_array_equal(got.positions[:i], track.positions[:i])
    np.testing.assert_array_equal(got.positions[i:], track.positions[i + removed :])


def test_noise_moves_a_share_of_points(track):
    got = inject("noise", track.positions, _times(track), np.random.default_rng(7))
    d = _dist(got.positions, track.positions)
    moved = d > 0
    assert moved.sum() == round(0.2 * (len(d) - 2))
    assert np.all((d[moved] > 490) & (d[moved] < 1010))
    assert not moved[0] and not moved[-1]


def _run(kind, track, motion, seed):
    return inject(kind, track.positions, _times(track), np.random.default_rng(seed), None, motion)


@pytest.mark.parametrize("seed", [0, 1])
def test_shift_moves_a_short_stretch_1_to_2_km_and_keeps_what_it_reports(track, motion, seed):
    got = _run("shift", track, motion, seed)
    i, j = got.stretch
    d = _dist(got.positions, track.positions)
    assert np.all(d[:i] == 0) and np.all(d[j:] == 0)
    assert np.all((d[i:j] > 990) & (d[i:j] < 2010)) and d[i:j].max() - d[i:j].min() < 20
    assert 0.05 * len(d) - 1 <= j - i <= 0.2 * len(d) + 1
    np.testing.assert_array_equal(got.motion, motion)
    np.testing.assert_array_equal(got.times_s, _times(track))


@pytest.mark.parametrize("kind, column", [("course-noise", 1), ("speed-noise", 0)])
def test_motion_noise_changes_one_reported_value_over_a_stretch_only(track, motion, kind, column):
    got = _run(kind, track, motion, 3)
    i, j = got.stretch
    np.testing.assert_array_equal(got.positions, track.positions)
    np.testing.assert_array_equal(got.times_s, _times(track))
    other = [c for c in range(3) if c != column]
    np.testing.assert_array_equal(got.motion[:, other], motion[:, other])
    changed = got.motion[:, column] != motion[:, column]
    assert not changed[:i].any() and not changed[j:].any() and changed[i:j].mean() > 0.8
    if kind == "course-noise":
        sd = np.std(angle_apart(got.motion[i:j, 1], motion[i:j, 1]) * 1.25)  # |N| -> sigma
        assert 5 < sd < 30
    else:
        assert (
            np.all(got.motion[:, 0] >= 0) and np.abs(got.motion[i:j, 0] - motion[i:j, 0]).max() > 1
        )


def test_drift_retimes_a_stretch_to_a_slow_sideways_course(track, motion):
    got = _run("drift", track, motion, 4)
    i, j = got.stretch
    t = _times(track)
    np.testing.assert_array_equal(got.positions, track.positions)
    assert got.times_s[j - 1] - got.times_s[i] >= DRIFT_MIN_S - 1e-6
    np.testing.assert_allclose(np.diff(got.times_s)[:i], np.diff(t)[:i])
    np.testing.assert_allclose(np.diff(got.times_s)[j - 1 :], np.diff(t)[j - 1 :])
    sailed = _dist(got.positions[i : j - 1], got.positions[i + 1 : j]).sum()
    knots = sailed / (got.times_s[j - 1] - got.times_s[i]) / KNOT_MPS
    np.testing.assert_allclose(got.motion[i:j, 0], knots, rtol=1e-3)
    assert knots <= 5.0 + 1e-6
    apart = angle_apart(got.motion[i:j, 2], got.motion[i:j, 1])
    assert np.all((apart >= 60 - 1e-6) & (apart <= 120 + 1e-6))
    np.testing.assert_array_equal(got.motion[:i], motion[:i])
    np.testing.assert_array_equal(got.motion[j:], motion[j:])


def test_gap_keeps_the_remaining_reports_motion(track, motion):
    got = _run("gap", track, motion, 6)
    np.testing.assert_array_equal(got.motion, motion[got.rows])
    np.testing.assert_array_equal(got.positions, track.positions[got.rows])


@pytest.mark.parametrize("kind", ["jump", "noise"])
def test_spoofed_positions_keep_their_reported_motion(track, motion, kind):
    np.testing.assert_array_equal(_run(kind, track, motion, 2).motion, motion)


def test_speed_scales_the_reported_sog_by_its_factor(track, motion):
    got = _run("speed", track, motion, 5)
    i, j = got.stretch
    factor = np.diff(_times(track))[i - 1] / np.diff(got.times_s)[i - 1]
    np.testing.assert_allclose(got.motion[i:j, 0], motion[i:j, 0] * factor)
    np.testing.assert_array_equal(np.delete(got.motion, np.s_[i:j], 0)[:, 0],
                                  np.delete(motion, np.s_[i:j], 0)[:, 0])  # fmt: skip
    np.testing.assert_array_equal(got.motion[:, 1:], motion[:, 1:])


def _course(p):
    from aisdati.geo import courses_deg

    return courses_deg(p)


@pytest.mark.parametrize("kind", ["detour", "loiter"])
def test_a_sailed_anomaly_reports_the_motion_of_its_new_path(track, motion, kind):
    """The reported COG and heading turn with the new path's bearing and SOG follows its
    speed, from the original values: the report-to-report noise stays what it was (a detour's
    reported speed no more rough than the track's own)."""
    got = _run(kind, track, motion, 1)
    i, j = got.stretch
    turn = angle_apart(got.motion[:, 1], motion[got.rows, 1])
    path_turn = angle_apart(_course(got.positions), _course(track.positions)[got.rows])
    np.testing.assert_allclose(turn, path_turn, atol=1e-6)
    np.testing.assert_allclose(angle_apart(got.motion[:, 2], got.motion[:, 1]), 5.0, atol=1e-6)
    w = SPEED_REPORTS  # the new path's speed is measured over this many reports either side
    away = np.r_[np.arange(max(i - w, 0)), np.arange(j + w, len(got.rows))]
    np.testing.assert_allclose(got.motion[away], motion[got.rows[away]], atol=1e-6)
    if kind == "loiter":  # one source report sailed round at one speed: one SOG
        ring = got.motion[i + w : j - w, 0]
        np.testing.assert_allclose(ring, ring[0], rtol=0.02)
    rough = lambda sog: np.abs(sog[1:-1] - (sog[:-2] + sog[2:]) / 2)  # noqa: E731
    assert np.median(rough(got.motion[i:j, 0])) <= 2 * np.median(rough(motion[:, 0])) + 0.1


def test_params_parse_and_check_their_range():
    from aisdati.errors import UserError

    p = parse_params(["detour.km=1-3", "jump.km=4"])
    assert p["detour"]["km"] == (1.0, 3.0) and p["jump"]["km"] == (4.0, 4.0)
    for bad in ("detour.km=5-1", "detour.span=0.95", "nope.km=1", "detour.km=x", "jump.km=nan"):
        with pytest.raises(UserError):
            parse_params([bad])


def test_a_3_km_detour_scores_above_its_source_for_nearest_and_dati(kitimat, tmp_path):
    from aisdati.ais.training import TrainSettings
    from aisdati.detectors import ScoreSettings
    from aisdati.detectors.nearest import NearestDetector
    from aisdati.detectors.train import train_detector
    from aisdati.tracks.store import Track

    table = read_track_table(kitimat)
    lane = table[table["route"] == "route-2"].sort_values("track_id")
    train_ids = [int(i) for i in lane["track_id"][:8]]
    (held,) = load_tracks(kitimat, [int(lane["track_id"].iloc[-1])])
    got = inject(
        "detour",
        held.positions,
        _times(held),
        np.random.default_rng(0),
        parse_params(["detour.km=3"]),
    )
    detoured = Track(
        -1, held.mmsi, held.start, got.positions, np.diff(got.times_s) / 3600, held.cluster
    )
    how = ScoreSettings(score="rollout", rollouts=4)
    near = NearestDetector().fit(load_tracks(kitimat, train_ids))
    s = near.score([held, detoured], how).score
    assert s[1] > 1.3 * s[0]
    trained = train_detector(
        "dati",
        TrainSettings(kitimat, "route-2", tmp_path, episodes=2, track_ids=tuple(train_ids)),
        how,
    )
    det = load_detector_from(trained.model)
    s = det.score([held, detoured], how).score
    assert s[1] > s[0]


def load_detector_from(path):
    from aisdati.detectors import load_detector

    return load_detector(path.with_suffix(""))
