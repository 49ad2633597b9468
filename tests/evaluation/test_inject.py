"""Anomalies written into a real Kitimat track (`aisdati.evaluation.inject`), one kind at a
time, and a 3 km detour that `nearest` and DATI score above its source."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.evaluation.inject import DEFAULTS, inject, parse_params
from aisdati.geo import haversine_m
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def track(kitimat):
    table = read_track_table(kitimat)
    tid = int(table.sort_values("n_points").iloc[len(table) // 2]["track_id"])
    (t,) = load_tracks(kitimat, [tid])
    return t


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
    got = inject("detour", held.positions, _times(held), np.random.default_rng(0),
                 parse_params(["detour.km=3"]))
    detoured = Track(-1, held.mmsi, held.start, got.positions, np.diff(got.times_s) / 3600,
                     held.cluster)
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
