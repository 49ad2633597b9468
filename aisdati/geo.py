"""Geodesy shared by preprocessing, the AIS environment and detection.

Great-circle distances use the haversine formula on a sphere of the mean Earth radius (the same
radius as the `haversine` package, so the two agree to float precision). The spherical update
rule is eq. (5) of the paper: a flat-Earth step whose longitude is rescaled by cos(latitude).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence

import numpy as np
from numba import njit

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius in metres (IUGG), as used by the `haversine` package."""

NM_PER_DEGREE = 60.0
"""Nautical miles per degree of latitude, the paper's conversion factor (appendix A.3)."""


def haversine_m(lon1, lat1, lon2, lat2):
    """Great-circle distance in metres between points given in degrees (numpy broadcasting)."""
    lon1, lat1, lon2, lat2 = (
        np.radians(np.asarray(v, dtype=np.float64)) for v in (lon1, lat1, lon2, lat2)
    )
    a = (
        np.sin((lat2 - lat1) / 2) ** 2
        + np.cos(lat1) * np.cos(lat2) * np.sin((lon2 - lon1) / 2) ** 2
    )
    return 2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0)))


def legs_m(polyline: np.ndarray) -> np.ndarray:
    """The great-circle length of each leg of a [n, 2] (lon, lat) polyline, metres ([n - 1])."""
    p = polyline
    return haversine_m(p[:-1, 0], p[:-1, 1], p[1:, 0], p[1:, 1])


@njit(cache=True)
def haversine_one_m(lon1: float, lat1: float, lon2: float, lat2: float) -> float:
    """`haversine_m` of one pair of points, compiled: for the sequential scans of ingest
    (`aisdati.preprocess.clean`, `aisdati.preprocess.stops`), which compare report by report."""
    to_rad = math.pi / 180.0
    phi1 = lat1 * to_rad
    phi2 = lat2 * to_rad
    h = (
        math.sin((phi2 - phi1) / 2) ** 2
        + math.cos(phi1) * math.cos(phi2) * math.sin((lon2 - lon1) * to_rad / 2) ** 2
    )
    return 2 * EARTH_RADIUS_M * math.asin(math.sqrt(min(max(h, 0.0), 1.0)))


def initial_bearing_deg(lon1, lat1, lon2, lat2):
    """Course from point 1 to point 2 in degrees clockwise from north, in [0, 360)."""
    lon1, lat1, lon2, lat2 = (
        np.radians(np.asarray(v, dtype=np.float64)) for v in (lon1, lat1, lon2, lat2)
    )
    dlon = lon2 - lon1
    x = np.sin(dlon) * np.cos(lat2)
    y = np.cos(lat1) * np.sin(lat2) - np.sin(lat1) * np.cos(lat2) * np.cos(dlon)
    return np.degrees(np.arctan2(x, y)) % 360.0


def spherical_step(lon, lat, sog_kn, cog_deg, dt_h):
    """Eq. (5) of the paper: the position after sailing SOG knots on course COG for dt hours."""
    cog = np.radians(cog_deg)
    dist_deg = np.asarray(sog_kn) * np.asarray(dt_h) / NM_PER_DEGREE
    new_lat = lat + np.cos(cog) * dist_deg
    new_lon = lon + np.sin(cog) * dist_deg / np.cos(np.radians(lat))
    return new_lon, new_lat


def moved_m(lon, lat, bearing_deg, metres):
    """Points moved `metres` along `bearing_deg` by a local flat-Earth step (fine at a few km;
    arrays broadcast): where an injected anomaly puts a report, where the ashore check probes."""
    b = np.radians(bearing_deg)
    dlat = np.degrees(metres * np.cos(b) / EARTH_RADIUS_M)
    coslat = np.maximum(np.cos(np.radians(lat)), 1e-6)
    return lon + np.degrees(metres * np.sin(b) / EARTH_RADIUS_M) / coslat, lat + dlat


def spherical_decision(lon, lat, next_lon, next_lat, dt_h):
    """Inverse of `spherical_step`: the SOG (knots) and COG (degrees) that map a point exactly
    onto the next one in `dt_h` hours. These are the paper's perfect decisions for AIS."""
    dlat = np.asarray(next_lat) - lat
    dlon_scaled = (np.asarray(next_lon) - lon) * np.cos(np.radians(lat))
    dist_deg = np.hypot(dlat, dlon_scaled)
    cog = np.degrees(np.arctan2(dlon_scaled, dlat)) % 360.0
    with np.errstate(divide="ignore", invalid="ignore"):
        sog = np.where(np.asarray(dt_h) > 0, dist_deg * NM_PER_DEGREE / np.asarray(dt_h), 0.0)
    return sog, cog


def unit_vectors(lonlat: np.ndarray) -> np.ndarray:
    """(lon, lat) degrees [..., 2] -> unit vectors [..., 3]: the batched kernels (here and in
    `aisdati.dtw`) measure great-circle distance as 2R asin(chord / 2), which equals the
    haversine formula."""
    lon, lat = np.radians(lonlat[..., 0]), np.radians(lonlat[..., 1])
    return np.ascontiguousarray(
        np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    )


def arc_m(chord: np.ndarray) -> np.ndarray:
    """Great-circle distance (m) of chords between `unit_vectors`: 2R asin(chord / 2)."""
    return 2 * EARTH_RADIUS_M * np.arcsin(np.minimum(chord / 2, 1.0))


def draw_spread(draws: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per row of K drawn positions ([n, K, 2] lon/lat degrees): their centroid (unit vectors
    [n, 3]) and their spread, the root mean square great-circle distance from it (m [n]): how
    sure a model is where the next report lies (`stepspread`)."""
    u = unit_vectors(draws)
    centre = u.mean(axis=1)
    centre /= np.linalg.norm(centre, axis=1, keepdims=True)
    spread = np.sqrt((arc_m(np.linalg.norm(u - centre[:, None], axis=2)) ** 2).mean(axis=1))
    return centre, spread


def _neighbours(sizes: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Indices of each point's previous and next point in polylines of `sizes` points laid end
    to end (each polyline's ends stand in for the missing)."""
    sizes = np.asarray(sizes, dtype=np.int64)
    first = np.repeat(np.cumsum(sizes) - sizes, sizes)
    last = np.repeat(np.cumsum(sizes) - 1, sizes)
    at = np.arange(int(sizes.sum()))
    return np.maximum(at - 1, first), np.minimum(at + 1, last)


def courses_deg(polyline: np.ndarray) -> np.ndarray:
    """Course at each point of a polyline (lon, lat) [n, 2], from its neighbours (the
    previous point to the next; the ends use the one neighbour they have)."""
    p = np.asarray(polyline, np.float64)
    return _courses(p, [len(p)])[0]


def _courses(points: np.ndarray, sizes: Sequence[int]) -> tuple[np.ndarray, ...]:
    """`courses_deg` of polylines of `sizes` points laid end to end in `points`, with each
    point's previous and next point (the ends stand in for the missing)."""
    prv, nxt = _neighbours(sizes)
    before, after = points[prv], points[nxt]
    return initial_bearing_deg(before[:, 0], before[:, 1], after[:, 0], after[:, 1]), before, after


def _course_vectors(points: np.ndarray, sizes: Sequence[int]) -> np.ndarray:
    """[sum n_i, 2] unit (cos, sin) of each point's course, polylines of `sizes` points laid end
    to end in `points`; zero where the point does not move (a stuck rollout has no course, so it
    is equally near every heading). One pass over all points: a lane is tens of rollouts, and
    a pass per rollout was a tenth of lane scoring's time."""
    course, before, after = _courses(points, sizes)
    theta = np.radians(course)
    moves = np.any(after != before, axis=1)
    return np.column_stack([np.cos(theta), np.sin(theta)]) * moves[:, None]


def lane_distances(
    track: np.ndarray, lane: Sequence[np.ndarray], course_m: float = 0.0
) -> np.ndarray:
    """For each point of `track` (lon, lat), its distance (m) to the nearest point of `lane`,
    polylines [n_i, 2] (several rollouts or training tracks) pooled into one cloud: how far the
    track is from anywhere that traffic goes, whatever the timing.

    With `course_m` > 0 the distance also weighs the course: sqrt(d^2 + (course_m / 2 |c - c'|)^2)
    for great-circle distance d and the points' course vectors c, c' (`_course_vectors`: that is
    course_m sin(dθ/2) for course difference dθ, and course_m / 2 against a point that does not
    move), so sailing against the traffic, or across it, costs up to `course_m` (a loiter's
    circles do both where the lane's points are near).

    The result is the brute-force minimum over every point of the lane (to well under a
    micrometre): a k-d tree on unit vectors (scaled to metres) joined by the course vectors
    scaled by course_m / 2 ranks the points by a chord metric that never exceeds the exact one,
    so once the exact distance of the best of the k nearest is within the k-th one's, no point
    further out can be nearer (`_nearest_exact`). The tree is kept for the next call
    (`_LaneIndex`): scoring many tracks against the same training tracks builds it once."""
    track = np.asarray(track, np.float64)
    query = _lane_keys([track], course_m)
    index = _INDEX[0]
    fresh, allowed = _split(index, lane, course_m)
    if index is None or not index.worth_reusing(fresh, allowed):
        index = _INDEX[0] = _LaneIndex(_unique(lane), course_m)
        fresh, allowed = [], None
    d = index.nearest(track, query, allowed)
    if fresh:
        d = np.minimum(d, _LaneIndex(fresh, course_m).nearest(track, query, None))
    return d


def _lane_keys(polylines: Sequence[np.ndarray], course_m: float) -> np.ndarray:
    """The k-d tree's coordinates of the polylines' points: unit vectors in metres, then (when
    the course is weighed) the course vectors times course_m / 2."""
    cloud = np.concatenate([np.asarray(p, np.float64) for p in polylines])
    keys = EARTH_RADIUS_M * unit_vectors(cloud)
    if course_m > 0:
        course = _course_vectors(cloud, [len(p) for p in polylines])
        keys = np.hstack([keys, course_m / 2 * course])
    return keys


def _unique(lane: Sequence[np.ndarray]) -> list[np.ndarray]:
    """The lane's polylines, each object once (a repeated one adds no nearer point)."""
    return list({id(p): p for p in lane}.values())


def _split(
    index: _LaneIndex | None, lane: Sequence[np.ndarray], course_m: float
) -> tuple[list[np.ndarray], np.ndarray | None]:
    """The lane's polylines that `index` does not hold, and a mask of those it does (None when
    it holds none, or one of them has changed since)."""
    if index is None or index.course_m != course_m:
        return _unique(lane), None
    held: dict[int, np.ndarray] = {}
    fresh = []
    for p in _unique(lane):
        k = index.holds(p)
        if k is None:
            fresh.append(p)
        else:
            held[k] = p
    if not held:
        return fresh, None
    allowed = np.zeros(len(index.refs), dtype=bool)
    allowed[list(held)] = True
    order = sorted(held)
    now = np.concatenate([held[k] for k in order])
    was = np.concatenate([index.lonlat[index.offsets[k] : index.offsets[k + 1]] for k in order])
    return fresh, allowed if np.array_equal(now, was) else None


class _LaneIndex:
    """A k-d tree over some polylines' points (`_lane_keys`), and which polyline each point is
    from, so that a later call with the same polylines, or most of them, queries it instead of
    building another. It holds weak references to the polylines and a copy of their points: a
    polyline is reused only while it is the same living object with the same points."""

    def __init__(self, polylines: list[np.ndarray], course_m: float) -> None:
        from scipy.spatial import cKDTree

        self.course_m = course_m
        self.refs = [weakref.ref(p) if isinstance(p, np.ndarray) else None for p in polylines]
        self.ids = {id(p): k for k, p in enumerate(polylines)}
        self.lonlat = np.concatenate([np.asarray(p, np.float64) for p in polylines])
        sizes = [len(p) for p in polylines]
        self.offsets = np.r_[0, np.cumsum(sizes)]
        self.owner = np.repeat(np.arange(len(polylines)), sizes)
        self.keys = _lane_keys(polylines, course_m)
        self.tree = cKDTree(self.keys)

    def holds(self, p: np.ndarray) -> int | None:
        """The number of polyline `p` in this index, or None where it is not here (`_split`
        then checks that the points held are still the polylines' points)."""
        k = self.ids.get(id(p))
        if k is None or self.refs[k] is None or self.refs[k]() is not p:
            return None
        return k if p.shape == (self.offsets[k + 1] - self.offsets[k], 2) else None

    def worth_reusing(self, fresh: list[np.ndarray], allowed: np.ndarray | None) -> bool:
        """Whether the lane's held polylines are at least half of this index and of the lane:
        a lane that is mostly new, or a small part of the index, is cheaper as its own tree."""
        if allowed is None:
            return False
        held = int(np.diff(self.offsets)[allowed].sum())
        new = sum(len(p) for p in fresh)
        return held >= new and 2 * held >= len(self.lonlat)

    def nearest(
        self, track: np.ndarray, query: np.ndarray, allowed: np.ndarray | None
    ) -> np.ndarray:
        """Each track point's exact distance to the nearest point of the allowed polylines: the
        k nearest by the tree's metric, k growing (x4) for the points not yet settled. A point
        is settled when the exact distance (haversine, as the brute force) of its best allowed
        neighbour is within `_unseen_m` of the k-th neighbour, which bounds every point not yet
        seen from below (less `_TREE_SLACK_M` for rounding)."""
        size = len(self.lonlat)
        out = np.full(len(track), np.inf)
        todo = np.arange(len(track))
        k = min(4, size)
        while todo.size:
            chord, idx = self.tree.query(query[todo], k)
            chord, idx = chord.reshape(len(todo), k), idx.reshape(len(todo), k)
            lon, lat = track[todo, 0, None], track[todo, 1, None]
            d = haversine_m(lon, lat, self.lonlat[idx, 0], self.lonlat[idx, 1])
            if self.course_m > 0:
                turn = query[todo, None, 3:] - self.keys[idx, 3:]
                d = np.hypot(d, np.linalg.norm(turn, axis=2))
            if allowed is not None:
                d[~allowed[self.owner[idx]]] = np.inf
            best = d.min(axis=1)
            done = (best <= _unseen_m(chord[:, -1], self.course_m) - _TREE_SLACK_M) | (k == size)
            out[todo[done]] = best[done]
            todo = todo[~done]
            k = min(4 * k, size)
        return out


def _unseen_m(tree_m: np.ndarray, course_m: float) -> np.ndarray:
    """The least exact distance of a point at `tree_m` by the tree's metric, sqrt(chord^2 +
    penalty^2): the penalty is at most course_m, so the chord is at least
    x = sqrt(tree_m^2 - course_m^2), and the arc of a chord x is 2R asin(x / 2R) >= x."""
    x = np.sqrt(np.maximum(tree_m**2 - course_m**2, 0.0))
    return np.sqrt(arc_m(x / EARTH_RADIUS_M) ** 2 + tree_m**2 - x**2)


_TREE_SLACK_M = 1e-6
"""Metres of rounding allowed in the tree's distances (keys of about 6.4e6 m, so about 1e-9 m)."""

_INDEX: list[_LaneIndex | None] = [None]
"""The last lane's index (`lane_distances`), replaced by the next lane that does not fit it."""
