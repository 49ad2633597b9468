"""Constructed cases of an area's interference and of a gap's coverage, written into real
traffic (`aisdati.evaluation.constructed`).

- **gnss-interference**: a block of real vessels near one another at one time (every report
  within `BLOCK_M` of a vessel under way, from just after one of its reports, for ten minutes
  to four hours, log-uniform) displaced together, one of three ways drawn alike: *shifted* by
  one vector (2-15 km, any bearing), *onto one point* (20-50 km away, the reports' own GNSS
  noise of a few metres kept), or *onto a circle* (radius 2-10 km, its centre 20-40 km away,
  each vessel at its own angle going round it once in 20 minutes to 2 hours). Every report in
  the area then is displaced (vessels coming in later too); the case names the block: the
  vessels there at its start whose displacement shows (two displaced reports or more, the
  first within a jump's longest step, `EventSettings.jump_step_max_s`, of the start and of the
  report before it); it needs three.
- **gap-heard**: a vessel under way silenced (its reports removed) for 1.2-3 times its gap
  limit (`aisdati.events.behaviour.gap_limit`), both ends at sea, where another vessel
  reported near its path during it: found as a gap whose coverage is "heard".
- **gap-quiet**: the same silence, and every other report within `QUIET_M` of the vessel's
  path during it removed too (an area silenced), where others reported near its path before
  and after: found as a gap whose coverage is "quiet"."""

from __future__ import annotations

import numpy as np
import pandas as pd

from aisdati.evaluation.case import Case
from aisdati.events.behaviour import gap_limit, land_mask
from aisdati.events.coverage import HEARD, QUIET
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.geo import haversine_m, moved_m

BLOCK_M = 15_000.0
"""The block of displaced reports: within this of the first vessel's position."""
QUIET_M = 30_000.0
"""An area silenced: every report within this of the silenced vessel's path (over a gap's
neighbourhood, `EventSettings.gap_coverage_m`)."""
UNDER_WAY_KN = 2.0
SETTINGS = EventSettings()

Built = "tuple[pd.DataFrame, pd.DataFrame, Case] | None"


def seconds(times: pd.Series) -> np.ndarray:
    return (
        (pd.to_datetime(times, utc=True) - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy()
    )


WAYS = ("shifted", "point", "circle")
"""How a block is displaced: by one vector, onto one point, onto one circle."""


def construct_interference(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator
) -> Built:
    """A block of vessels displaced together, one of `WAYS` drawn alike."""
    return displaced_block(reports, identity, rng, WAYS[int(rng.integers(len(WAYS)))])


def displaced_block(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator, way: str
) -> Built:
    """A block of vessels displaced together `way` (`WAYS`)."""
    r = reports.sort_values(["mmsi", "time"], kind="stable").reset_index(drop=True)
    t = seconds(r["time"])
    under_way = np.flatnonzero(r["sog"].to_numpy() >= UNDER_WAY_KN)
    if not under_way.size:
        return None
    seed = int(rng.choice(under_way))
    start = t[seed] + 1.0
    end = start + float(np.exp(rng.uniform(np.log(600.0), np.log(4 * 3600.0))))
    lon, lat = r["lon"].to_numpy(), r["lat"].to_numpy()
    inside = (t >= start) & (t <= end)
    inside &= haversine_m(lon[seed], lat[seed], lon, lat) <= BLOCK_M
    mmsi = r["mmsi"].to_numpy()
    named = []
    for m in np.unique(mmsi[inside]):
        mine = np.flatnonzero((mmsi == m) & inside)
        before = mine[0] - 1
        at_once = t[mine[0]] - start <= SETTINGS.jump_step_max_s
        heard = before >= 0 and mmsi[before] == m
        shows = heard and t[mine[0]] - t[before] <= SETTINGS.jump_step_max_s
        if len(mine) >= 2 and at_once and shows:
            named.append(int(m))
    if len(named) < SETTINGS.interference_min_vessels:
        return None
    rows = np.flatnonzero(inside)
    new_lon, new_lat = _displaced(
        way, lon[rows], lat[rows], t[rows] - start, mmsi[rows], (lon[seed], lat[seed]), rng
    )
    out = r.copy()
    out.loc[rows, "lon"], out.loc[rows, "lat"] = new_lon, new_lat
    case = Case("gnss-interference", tuple(sorted(named)), _utc(start), _utc(end))
    return out, identity, case


def _displaced(way, lon, lat, since_s, mmsi, centre, rng) -> tuple[np.ndarray, np.ndarray]:
    """The block's positions displaced `way`."""
    if way == "shifted":
        east, north = _vector(rng.uniform(2_000.0, 15_000.0), rng.uniform(0.0, 360.0))
        return _moved(lon, lat, east, north)
    if way == "point":  # with the receivers' own noise
        px, py = moved_m(*centre, rng.uniform(0.0, 360.0), rng.uniform(20_000.0, 50_000.0))
        east, north = rng.normal(0.0, 5.0, (2, len(lon)))
        return _moved(np.full(len(lon), px), np.full(len(lon), py), east, north)
    cx, cy = moved_m(*centre, rng.uniform(0.0, 360.0), rng.uniform(20_000.0, 40_000.0))
    radius, period = rng.uniform(2_000.0, 10_000.0), rng.uniform(1200.0, 7200.0)
    phases = {m: rng.uniform(0.0, 2 * np.pi) for m in np.unique(mmsi)}
    angle = np.array([phases[m] for m in mmsi]) + 2 * np.pi * since_s / period
    east, north = radius * np.sin(angle), radius * np.cos(angle)
    return _moved(np.full(len(lon), cx), np.full(len(lon), cy), east, north)


def _vector(metres: float, bearing_deg: float) -> tuple[float, float]:
    b = np.radians(bearing_deg)
    return metres * np.sin(b), metres * np.cos(b)


def _moved(lon, lat, east, north) -> tuple[np.ndarray, np.ndarray]:
    """Positions moved east/north by metres (flat: a few tens of km)."""
    m_per_deg = 111_194.9
    new_lat = lat + np.asarray(north) / m_per_deg
    new_lon = lon + np.asarray(east) / (m_per_deg * np.cos(np.radians(lat)))
    return np.asarray(new_lon, float), np.asarray(new_lat, float)


def _utc(s: float) -> pd.Timestamp:
    return pd.Timestamp(round(s * 1e6), unit="us", tz="UTC")


def construct_gap_heard(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator
) -> Built:
    """A vessel silenced while its neighbours keep reporting."""
    return _silenced(reports, identity, rng, area=False)


def construct_gap_quiet(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator
) -> Built:
    """A vessel silenced with its area."""
    return _silenced(reports, identity, rng, area=True)


def _silenced(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator, area: bool
) -> Built:
    """One vessel under way silenced for 1.2-3 times its gap limit (and, `area`, every report
    within `QUIET_M` of its path then). The truth is the traffic's, not the detector's rule:
    "heard" where another vessel reported within a gap's neighbourhood
    (`EventSettings.gap_coverage_m`) of the vessel's path during the silence; "quiet" where,
    the area silenced, another reported near its path before the silence and another after."""
    r = reports.sort_values(["mmsi", "time"], kind="stable").reset_index(drop=True)
    mmsi, t = r["mmsi"].to_numpy(), seconds(r["time"])
    lon, lat = r["lon"].to_numpy(), r["lat"].to_numpy()
    m = int(rng.choice(np.unique(mmsi)))
    mine = np.flatnonzero(mmsi == m)
    v = VesselReports.of(r.iloc[mine])
    if len(v) < 10:
        return None
    length = gap_limit(v, SETTINGS) * rng.uniform(1.2, 3.0)
    k = int(rng.integers(1, len(v) - 1))
    after = int(np.searchsorted(v.time_s, v.time_s[k] + length))
    if length > SETTINGS.gap_max_s / 2 or after >= len(v):
        return None
    if min(v.sog[k], v.sog[after]) < UNDER_WAY_KN or v.dt_s[k:after].max() >= gap_limit(
        v, SETTINGS
    ):
        return None  # not under way at its ends, or already silent in it
    ashore = land_mask(v.positions(np.array([k, after])), None)
    if ashore is not None and ashore.any():
        return None  # a gap is at sea (`aisdati.events.behaviour.gaps`)
    span = (float(v.time_s[k]), float(v.time_s[after]))
    path = v.positions(np.arange(k, after + 1))
    path = path[:: max(1, len(path) // 20)]
    others = mmsi != m

    def near(rows: np.ndarray, radius: float) -> np.ndarray:
        close = np.zeros(len(rows), bool)
        for x, y in path:
            close |= haversine_m(x, y, lon[rows], lat[rows]) <= radius
        return rows[close]

    during = np.flatnonzero((t > span[0]) & (t < span[1]) & others)
    if not len(near(during, SETTINGS.gap_coverage_m)):
        return None  # nobody to hear near it: no truth to write
    gone = mine[k + 1 : after]
    if area:
        gone = np.r_[gone, near(during, QUIET_M)]
        before = np.flatnonzero((t >= span[0] - length) & (t <= span[0]) & others)
        later = np.flatnonzero((t >= span[1]) & (t <= span[1] + length) & others)
        if not len(near(before, SETTINGS.gap_coverage_m)) or not len(
            near(later, SETTINGS.gap_coverage_m)
        ):
            return None  # no neighbour before and after: the silence is no one's but its
    out = r.drop(index=gone).reset_index(drop=True)
    case = Case("gap", (m,), _utc(span[0]), _utc(span[1]), coverage=QUIET if area else HEARD)
    return out, identity, case
