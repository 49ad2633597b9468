"""Geodesy shared by preprocessing, the AIS environment and detection.

Great-circle distances use the haversine formula on a sphere of the mean Earth radius (the same
radius as the `haversine` package, so the two agree to float precision). The spherical update
rule is eq. (5) of the paper: a flat-Earth step whose longitude is rescaled by cos(latitude).
"""

from __future__ import annotations

import math
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


def _neighbours(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of each point's previous and next point (the ends stand in for the missing)."""
    return np.r_[0, np.arange(n - 1)], np.r_[np.arange(1, n), n - 1]


def courses_deg(polyline: np.ndarray) -> np.ndarray:
    """Course at each point of a polyline (lon, lat) [n, 2], from its neighbours (the
    previous point to the next; the ends use the one neighbour they have)."""
    p = np.asarray(polyline, np.float64)
    prv, nxt = _neighbours(len(p))
    return initial_bearing_deg(p[prv, 0], p[prv, 1], p[nxt, 0], p[nxt, 1])


def _course_vectors(polyline: np.ndarray) -> np.ndarray:
    """[n, 2] unit (cos, sin) of each point's course; zero where the point does not move
    (a stuck rollout has no course, so it is equally near every heading)."""
    p = np.asarray(polyline, np.float64)
    theta = np.radians(courses_deg(p))
    prv, nxt = _neighbours(len(p))
    moves = np.any(p[nxt] != p[prv], axis=1)
    return np.column_stack([np.cos(theta), np.sin(theta)]) * moves[:, None]


def lane_distances(
    track: np.ndarray, lane: Sequence[np.ndarray], course_m: float = 0.0
) -> np.ndarray:
    """For each point of `track` (lon, lat), its distance (m) to the nearest point of `lane`,
    polylines [n_i, 2] (several rollouts or training tracks) pooled into one cloud: how far the
    track is from anywhere that traffic goes, whatever the timing.

    With `course_m` > 0 the distance also weighs the course: sqrt(d^2 + (course_m sin(dθ/2))^2)
    for great-circle distance d and course difference dθ, so sailing against the traffic, or
    across it, costs up to `course_m` (a loiter's circles do both where the lane's points are
    near). A k-d tree on unit vectors (scaled to metres), joined by the course vectors scaled by
    course_m / 2, finds the nearest point in that metric (chord for arc: equal to well under a
    millimetre at lane scales); the distance is then recomputed exactly."""
    from scipy.spatial import cKDTree

    track = np.asarray(track, np.float64)
    cloud = np.concatenate([np.asarray(p, np.float64) for p in lane])
    keys = [EARTH_RADIUS_M * unit_vectors(cloud)]
    query = [EARTH_RADIUS_M * unit_vectors(track)]
    if course_m > 0:
        keys.append(course_m / 2 * np.concatenate([_course_vectors(p) for p in lane]))
        query.append(course_m / 2 * _course_vectors(track))
    _, idx = cKDTree(np.hstack(keys)).query(np.hstack(query))
    d = haversine_m(track[:, 0], track[:, 1], cloud[idx, 0], cloud[idx, 1])
    if course_m > 0:
        d = np.hypot(d, np.linalg.norm(query[1] - keys[1][idx], axis=1))
    return d
