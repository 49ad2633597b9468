"""The indexed scoring kernels against their brute-force definitions, on real Kitimat tracks and
random ones: `lane_distances` (a k-d tree, kept between calls) and `nearest_mean_dtw_m` (lower
bounds and abandoning) must give what comparing every point, or every pair, gives."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.dtw import batch_mean_dtw_m, nearest_mean_dtw_m
from aisdati.geo import courses_deg, haversine_m, lane_distances
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def real(kitimat) -> list[np.ndarray]:
    ids = read_track_table(kitimat)["track_id"].tolist()[:40]
    return [t.positions for t in load_tracks(kitimat, ids)]


def random_tracks(seed: int, count: int) -> list[np.ndarray]:
    """Random walks near Kitimat, some standing still for a while (points with no course)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        steps = rng.normal(0, 0.01, (int(rng.integers(5, 120)), 2))
        steps[rng.random(len(steps)) < 0.1] = 0.0
        out.append(np.array([-129.0, 53.9]) + rng.normal(0, 0.05, 2) + np.cumsum(steps, 0))
    return out


def brute_lane(track: np.ndarray, lane: list[np.ndarray], course_m: float) -> np.ndarray:
    """Every report against every lane point, as `lane_distances` defines the distance."""
    cloud = np.concatenate(lane)
    d = haversine_m(track[:, None, 0], track[:, None, 1], cloud[None, :, 0], cloud[None, :, 1])
    if course_m > 0:

        def course(p: np.ndarray) -> np.ndarray:
            theta = np.radians(courses_deg(p))
            prv, nxt = np.r_[0, np.arange(len(p) - 1)], np.r_[np.arange(1, len(p)), len(p) - 1]
            moves = np.any(p[nxt] != p[prv], axis=1)
            return np.column_stack([np.cos(theta), np.sin(theta)]) * moves[:, None]

        c = np.concatenate([course(p) for p in lane])
        turn = np.linalg.norm(course(track)[:, None] - c[None], axis=2)
        d = np.hypot(d, course_m / 2 * turn)
    return d.min(axis=1)


@pytest.mark.parametrize("course_m", [0.0, 2000.0])
def test_lane_distances_equal_the_brute_force_on_real_and_random_tracks(real, course_m):
    rand = random_tracks(1, 30)
    for k in range(6):
        lane = [t for j, t in enumerate(real) if j != k and j % 3 != k % 3]
        for track, pool in ((real[k], lane), (rand[k], rand[6:]), (real[k], rand[6:] + lane)):
            got = lane_distances(track, pool, course_m)
            np.testing.assert_allclose(got, brute_lane(track, pool, course_m), rtol=0, atol=1e-6)


def test_the_kept_index_serves_subsets_and_notices_changed_tracks(real):
    lane = [t.copy() for t in real[1:]]
    whole = lane_distances(real[0], lane, 2000.0)  # builds the index
    most = [*lane[:-3], real[0][::2].copy()]  # most of it, plus a polyline it does not hold
    assert np.max(lane_distances(real[0][::2], most, 2000.0)) == 0.0  # its own points
    np.testing.assert_allclose(
        lane_distances(real[0], most, 2000.0), brute_lane(real[0], most, 2000.0), atol=1e-6
    )
    assert np.all(lane_distances(real[0], lane, 2000.0) == whole)
    lane[5] += 0.05  # moved in place: the index's copy is stale and must not be used
    np.testing.assert_allclose(
        lane_distances(real[0], lane, 2000.0), brute_lane(real[0], lane, 2000.0), atol=1e-6
    )


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
