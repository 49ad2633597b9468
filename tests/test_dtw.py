"""Exact DTW: whole-pair forms against a naive reference, the incremental form against the
whole-pair form, and the haversine metric against the `haversine` package; the batched mean
DTW, a planted detour on a real New York Harbor track, and the pruned nearest-track search
against every pair, on real Kitimat tracks and random ones."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from haversine import Unit, haversine
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from aisdati.dtw import (
    IncrementalDTW,
    batch_mean_dtw_m,
    dtw,
    dtw_path,
    dtw_path_length,
    matched_distances,
    nearest_mean_dtw_m,
    pairs_mean_dtw_m,
    prepare_lonlat,
)
from aisdati.geo import arc_m, haversine_m
from aisdati.tracks.store import load_tracks, read_track_table
from tests.helpers.tracks import random_tracks

COORD = st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)
# Few distinct values make exact ties between warping paths common.
TIED = st.sampled_from([0.0, 1.0, 2.0])


def series(max_len: int = 12) -> st.SearchStrategy[np.ndarray]:
    return st.integers(1, max_len).flatmap(
        lambda n: arrays(np.float64, (n, 2), elements=st.one_of(COORD, TIED))
    )


def point_dist(p: np.ndarray, q: np.ndarray, metric: str) -> float:
    if metric == "euclidean":
        return math.dist(p, q)
    return float(haversine_m(p[0], p[1], q[0], q[1]))


def naive_dtw(a: np.ndarray, b: np.ndarray, metric: str = "euclidean") -> float:
    n, m = len(a), len(b)
    cost = [[math.inf] * (m + 1) for _ in range(n + 1)]
    cost[0][0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            best = min(cost[i - 1][j - 1], cost[i - 1][j], cost[i][j - 1])
            cost[i][j] = point_dist(a[i - 1], b[j - 1], metric) + best
    return cost[n][m]


def random_track(rng: np.random.Generator, n: int) -> np.ndarray:
    """A (lon, lat) random walk of small steps around the Baltic."""
    start = np.array([18.0, 57.0])
    return start + np.cumsum(rng.normal(0.0, 0.01, size=(n, 2)), axis=0)


@settings(max_examples=200, deadline=None)
@given(series(), series())
def test_dtw_matches_naive_reference(a, b):
    assert dtw(a, b) == pytest.approx(naive_dtw(a, b), rel=1e-9, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(series(), series())
def test_dtw_path_is_a_valid_optimal_path(a, b):
    cost, path = dtw_path(a, b)
    n, m = len(a), len(b)
    assert cost == pytest.approx(dtw(a, b), rel=1e-12, abs=1e-12)
    assert path.dtype.kind == "i" and path.shape[1] == 2
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (n - 1, m - 1)
    steps = np.diff(path, axis=0)
    assert np.all((steps >= 0) & (steps <= 1)) and np.all(steps.sum(axis=1) >= 1)
    along = sum(math.dist(a[i], b[j]) for i, j in path)
    assert along == pytest.approx(cost, rel=1e-9, abs=1e-9)
    length_cost, length = dtw_path_length(a, b)
    assert length == len(path)
    assert length_cost == cost


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 12), st.data())
def test_incremental_matches_whole_pair_on_random_series(n, data):
    elements = data.draw(st.sampled_from([COORD, TIED]))
    a = data.draw(arrays(np.float64, (n, 2), elements=elements))
    b = data.draw(arrays(np.float64, (n, 2), elements=elements))
    inc = IncrementalDTW(capacity=2)
    for t in range(len(a)):
        value = inc.push(a[t], b[t])
        cost, length = dtw_path_length(a[: t + 1], b[: t + 1])
        assert value == inc.distance == cost
        assert inc.path_length == length
        assert inc.n == t + 1


@pytest.mark.parametrize("metric", ["euclidean", "haversine"])
def test_incremental_matches_whole_pair_beyond_capacity(metric):
    rng = np.random.default_rng(7)
    n = 150
    a, b = random_track(rng, n), random_track(rng, n)
    # Repeated points create exact ties, which exercise the tie-breaking rule.
    b[40:60] = b[40]
    a[90:100] = b[90:100]
    inc = IncrementalDTW(metric=metric, capacity=8)
    assert inc.n == 0 and inc.distance == 0.0 and inc.path_length == 0
    for t in range(n):
        inc.push(a[t], b[t])
        cost, length = dtw_path_length(a[: t + 1], b[: t + 1], metric=metric)
        assert inc.distance == pytest.approx(cost, rel=1e-12)
        assert inc.path_length == length
    assert dtw(a, b, metric=metric) == pytest.approx(naive_dtw(a, b, metric), rel=1e-9)
    inc.reset()
    assert inc.n == 0 and inc.distance == 0.0
    assert inc.push(a[0], b[0]) == pytest.approx(point_dist(a[0], b[0], metric), rel=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-180.0, 180.0),
    st.floats(-90.0, 90.0),
    st.floats(-180.0, 180.0),
    st.floats(-90.0, 90.0),
)
def test_haversine_metric_matches_haversine_package(lon1, lat1, lon2, lat2):
    expected = haversine((lat1, lon1), (lat2, lon2), unit=Unit.METERS)
    got = dtw([[lon1, lat1]], [[lon2, lat2]], metric="haversine")
    assert got == pytest.approx(expected, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("metric", ["euclidean", "haversine"])
def test_identical_series_give_zero(metric):
    a = random_track(np.random.default_rng(3), 40)
    assert dtw(a, a, metric=metric) == 0.0
    cost, path = dtw_path(a, a, metric=metric)
    assert cost == 0.0
    np.testing.assert_array_equal(path, np.stack([np.arange(40)] * 2, axis=1))
    assert dtw_path_length(a, a, metric=metric) == (0.0, 40)
    inc = IncrementalDTW(metric=metric)
    for p in a:
        assert inc.push(p, p) == 0.0
    assert inc.path_length == 40


def test_euclidean_works_in_any_dimension():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(7, 5)), rng.normal(size=(9, 5))
    assert dtw(a, b) == pytest.approx(naive_dtw(a, b), rel=1e-12)


def test_unknown_metric_raises():
    with pytest.raises(ValueError, match="euclidean"):
        dtw([[0.0, 0.0]], [[1.0, 1.0]], metric="manhattan")
    with pytest.raises(ValueError, match="haversine"):
        IncrementalDTW(metric="cosine")


def test_incremental_dtw_continues_exactly_from_its_state():
    rng = np.random.default_rng(3)
    a = rng.uniform(-1, 1, (12, 2)) + np.array([-129.0, 53.0])
    b = rng.uniform(-1, 1, (12, 2)) + np.array([-129.0, 53.0])
    whole = IncrementalDTW(metric="haversine", capacity=4)  # grows past its capacity
    half = IncrementalDTW(metric="haversine", capacity=4)
    for i in range(6):
        whole.push(a[i], b[i])
        half.push(a[i], b[i])
    restored = IncrementalDTW(metric="haversine", capacity=4)
    restored.load_state_dict(half.state_dict())
    for i in range(6, 12):
        assert restored.push(a[i], b[i]) == whole.push(a[i], b[i])
        assert restored.path_length == whole.path_length
    empty = IncrementalDTW()
    empty.load_state_dict(IncrementalDTW().state_dict())
    assert empty.n == 0 and empty.push([0.0, 0.0], [3.0, 4.0]) == 5.0


# ------------------------------------------------------------- input the kernels cannot take
NAN_TRACK = np.array([[-74.0, 40.6], [np.nan, 40.7], [-74.1, 40.8]])
TRACK = np.array([[-74.0, 40.6], [-74.05, 40.7], [-74.1, 40.8]])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_every_public_dtw_refuses_non_finite_points(bad):
    """NaN costs compare false with everything, so no predecessor wins and the back-track of
    `dtw_path` left its matrix (a segfault in `detect`); every entry refuses them first."""
    worse = np.where(np.isnan(NAN_TRACK), bad, NAN_TRACK)
    for call in (
        lambda: dtw(worse, TRACK),
        lambda: dtw_path(TRACK, worse, "haversine"),
        lambda: dtw_path_length(worse, TRACK, "haversine"),
        lambda: matched_distances(TRACK, worse),
        lambda: IncrementalDTW("haversine").push(worse[1], TRACK[1]),
        lambda: batch_mean_dtw_m(worse[None], np.array([3]), [TRACK], np.array([0])),
        lambda: batch_mean_dtw_m(TRACK[None], np.array([3]), [worse], np.array([0])),
        lambda: nearest_mean_dtw_m([worse], [TRACK], [np.array([0])]),
        lambda: nearest_mean_dtw_m([TRACK], [TRACK, worse], [np.array([0, 1])]),
        lambda: prepare_lonlat(worse[None]),
    ):
        with pytest.raises(ValueError, match="non-finite"):
            call()


def test_indices_into_the_kernels_arrays_are_checked():
    """numba does not check indices: out of range they read and write other memory."""
    ready = prepare_lonlat(TRACK[None])
    for call, needle in (
        (lambda: pairs_mean_dtw_m(ready, ready, np.array([[0, 1]])), r"pairs\[:, 1\] must lie"),
        (lambda: pairs_mean_dtw_m(ready, ready, np.array([[-1, 0]])), r"pairs\[:, 0\] must lie"),
        (lambda: batch_mean_dtw_m(TRACK[None], np.array([4]), [TRACK], np.array([0])),
         "lengths - 1 must lie in"),
        (lambda: batch_mean_dtw_m(TRACK[None], np.array([0]), [TRACK], np.array([0])),
         "lengths - 1 must lie in"),
        (lambda: batch_mean_dtw_m(TRACK[None], np.array([3]), [TRACK], np.array([1])),
         "owner must lie in"),
        (lambda: nearest_mean_dtw_m([TRACK], [TRACK], [np.array([1])]),
         r"candidates\[0\] must lie in"),
        (lambda: nearest_mean_dtw_m([TRACK], [TRACK], []), "1 queries, 0 candidate lists"),
        (lambda: nearest_mean_dtw_m([TRACK], [np.empty((0, 2))], [np.array([0])]),
         r"references\[0\] must be a non-empty array"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=needle):
            call()
    assert pairs_mean_dtw_m(ready, ready, np.array([[0, 0]])) == pytest.approx([0.0])


def test_point_distances_are_the_arc_of_the_chord_to_the_last_roundings():
    """The kernels sum asin's series for arcs up to 255 km (`ASIN_SERIES_MAX`) and call asin
    beyond: one-point series from 1 mm to 20,000 km apart measure 2R asin(chord / 2) as numpy
    computes it, within a few roundings."""
    east = np.geomspace(1e-8, 179.0, 400)  # degrees of longitude along the equator
    a = prepare_lonlat(np.zeros((1, 1, 2)))
    b = prepare_lonlat(np.stack([east, np.zeros_like(east)], axis=1)[:, None, :])
    got = pairs_mean_dtw_m(a, b, np.stack([np.zeros(len(east), int), np.arange(len(east))], 1))
    want = arc_m(np.linalg.norm(b[:, 0] - a[0, 0], axis=1))
    assert np.all(np.abs(got - want) <= 4 * np.spacing(want))
    assert got[east < 2.0].size and got[east > 3.0].size  # both sides of the 255 km switch


BACK_TRACK = """
import numpy as np
from aisdati.dtw import dtw_path
big = 1e308  # finite points whose distances overflow to inf: every cost is inf
cost, path = dtw_path(np.array([[big], [-big], [big]]), np.full((5, 1), -big))
print(cost, path.tolist())
"""


def test_the_back_track_stays_in_its_matrix_whatever_the_costs():
    """With costs that compare false (inf < inf) every back-pointer says diagonal; the
    back-track walked off the first row into memory past its path. In a process of its own,
    so that a crash fails this test instead of the session."""
    proc = subprocess.run(
        [sys.executable, "-c", BACK_TRACK], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    cost, path = proc.stdout.split(" ", 1)
    assert cost == "inf"
    assert json.loads(path) == [[0, 0], [0, 1], [0, 2], [1, 3], [2, 4]]


def test_a_damaged_incremental_state_is_refused():
    """A training checkpoint's DTW state goes to a compiled push that trusts its arrays."""
    dtw_state = IncrementalDTW("haversine")
    for a, b in zip(TRACK, TRACK[::-1], strict=True):
        dtw_state.push(a, b)
    good = dtw_state.state_dict()
    for change, needle in (
        ({"n": 10**6}, r"_a must have shape \(1000000, 3\)"),
        ({"n": -1}, "n must be >= 0"),
        ({"dim": 3}, "3 values per point do not fit haversine DTW"),
        ({"_row_d": np.array([0.0, np.nan, 1.0])}, "_row_d holds values no DTW of 3 points has"),
        ({"_col_l": np.array([1, 2, 99])}, "_col_l holds values no DTW of 3 points has"),
        ({"_row_l": np.array([1.0, 2.0, 3.0])}, "_row_l holds values"),
    ):
        with pytest.raises(ValueError, match=needle):
            IncrementalDTW("haversine").load_state_dict({**good, **change})
    restored = IncrementalDTW("haversine")
    restored.load_state_dict(good)
    assert restored.distance == dtw_state.distance


def mean_dtw_m(a: np.ndarray, b: np.ndarray) -> float:
    cost, length = dtw_path_length(a, b, "haversine")
    return cost / length


def _detour(track: np.ndarray, km: float) -> np.ndarray:
    """The track with a smooth bump of `km` peak in its middle third, perpendicular to the line
    from its first to its last point."""
    n = len(track)
    coslat = np.cos(np.radians(track[0, 1]))
    d = (track[-1] - track[0]) * [coslat, 1.0]
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)
    i = np.arange(n)
    bump = np.clip(1 - np.abs(i - n / 2) / (n / 6), 0, 1)
    offset_deg = bump[:, None] * km / 111.2 * normal / [coslat, 1.0]
    return track + offset_deg


def test_planted_detour_scores_above_its_untouched_twin(processed):
    (track,) = load_tracks(processed, [3])
    rng = np.random.default_rng(0)
    # a model that has learnt the route well: rollouts within ~50 m of the track
    rollouts = [track.positions + rng.normal(0, 0.0005, track.positions.shape) for _ in range(3)]
    twin = track.positions.copy()
    detoured = _detour(track.positions, 5.0)
    score_twin = min(mean_dtw_m(r, twin) for r in rollouts)
    score_detour = min(mean_dtw_m(r, detoured) for r in rollouts)
    assert score_detour > 5 * score_twin
    assert score_twin < 0.75 * score_detour  # the paper's rule flags the detour alone
    profile = matched_distances(detoured, rollouts[0])
    dev, idx = profile.max(), int(profile.argmax())
    assert dev > 4000
    assert abs(idx - len(detoured) / 2) <= len(detoured) / 10


def test_batched_parallel_dtw_equals_reference_dtw():
    rng = np.random.default_rng(0)
    origin = np.array([-80.0, 25.0])
    tracks = [np.cumsum(rng.normal(0, 0.001, (n, 2)), 0) + origin for n in (50, 80, 33)]
    rolls = np.cumsum(rng.normal(0, 0.001, (6, 90, 2)), 1) + origin
    lengths = np.array([90, 60, 81, 40, 33, 70])
    owner = np.array([0, 0, 1, 1, 2, 2])
    got = batch_mean_dtw_m(rolls, lengths, tracks, owner)
    want = [mean_dtw_m(rolls[i, : lengths[i]], tracks[owner[i]]) for i in range(6)]
    np.testing.assert_allclose(got, want, rtol=1e-9)


def plain_nearest(query: np.ndarray, refs: list[np.ndarray]) -> tuple[float, int]:
    """Every reference's full DTW (no bounds, no abandoning), the first of equal minima."""
    means = batch_mean_dtw_m(
        np.repeat(query[None], len(refs), 0), np.full(len(refs), len(query)), refs,
        np.arange(len(refs)),
    )  # fmt: skip
    return float(means.min()), int(means.argmin())


def test_the_pruned_nearest_search_equals_every_pair_on_real_and_random_tracks(real):
    for queries, refs in ((real[:8], real[8:]), (random_tracks(2, 6), random_tracks(3, 40))):
        refs = [*refs, refs[3]]  # a duplicate: equal means go to the smaller index
        dist, arg = nearest_mean_dtw_m(queries, refs, [np.arange(len(refs))] * len(queries))
        for q, d, a in zip(queries, dist, arg, strict=True):
            assert (d, a) == plain_nearest(q, refs)


def test_the_search_keeps_to_each_querys_candidates(real):
    queries, refs = real[:5], real[5:]
    cands = [np.arange(k, len(refs), 3) for k in range(5)]
    dist, arg = nearest_mean_dtw_m(queries, refs, cands)
    for q, c, d, a in zip(queries, cands, dist, arg, strict=True):
        best, at = plain_nearest(q, [refs[j] for j in c])
        assert d == best and a == c[at]
    dist, arg = nearest_mean_dtw_m(queries[:1], refs, [np.array([], np.int64)])
    assert dist[0] == np.inf and arg[0] == -1


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
