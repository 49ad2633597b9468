"""Geodesy shared by preprocessing, the AIS environment and detection.

Great-circle distances use the haversine formula on a sphere of the mean Earth radius (the same
radius as the `haversine` package, so the two agree to float precision). The spherical update
rule is eq. (5) of the paper: a flat-Earth step whose longitude is rescaled by cos(latitude).
"""

from __future__ import annotations

import numpy as np

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius in metres (IUGG), as used by the `haversine` package."""

NM_PER_DEGREE = 60.0
"""Nautical miles per degree of latitude, the paper's conversion factor (appendix A.3)."""


def _radians(*degrees) -> list[np.ndarray]:
    return [np.radians(np.asarray(v, dtype=np.float64)) for v in degrees]


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


def lane_distances(track: np.ndarray, lane: np.ndarray) -> np.ndarray:
    """For each point of `track` (lon, lat), the great-circle distance (m) to the nearest point
    of `lane` [m, 2], a cloud of points in no order (several rollouts or training tracks
    stacked): how far the track is from anywhere that traffic goes, whatever the timing. A
    k-d tree on unit vectors finds the nearest chord, which orders points as the arc does."""
    from scipy.spatial import cKDTree

    chord, _ = cKDTree(unit_vectors(np.asarray(lane, np.float64))).query(
        unit_vectors(np.asarray(track, np.float64))
    )
    return 2 * EARTH_RADIUS_M * np.arcsin(np.minimum(chord / 2, 1.0))
