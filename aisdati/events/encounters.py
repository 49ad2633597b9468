"""Encounters (`aisdati.events.kinds`: encounter): two vessels within `encounter_m` of each
other for `encounter_min_s` or more, both under `encounter_kn` by their positions, at least
`encounter_port_m` from every port and anchorage (`aisdati.events.anchorages`), as Global
Fishing Watch defines them. A close pass of vessels under way is none: they are not slow.

How, over thousands of vessels: each vessel's positions are interpolated every
`encounter_step_s` (GFW resamples to 10 minutes) between reports at most `encounter_max_gap_s`
apart; only the samples slow and at sea are kept, put in a grid of cells `encounter_m` wide,
and compared with those of the same time step in the same or a neighbouring cell. The work
grows with the slow vessels at sea, not with the square of the fleet."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from aisdati.events.anchorages import Anchorages
from aisdati.events.record import event_row
from aisdati.events.reports import M_PER_DEG, VesselReports
from aisdati.events.settings import EventSettings
from aisdati.geo import haversine_m
from aisdati.tracks.schema import KNOT_MPS

if TYPE_CHECKING:  # the fleet module registers this finder
    from aisdati.events.fleet import Fleet
    from aisdati.events.rules import EventRules

NOT_A_VESSEL = ("0", "111", "8", "9")
"""MMSI prefixes of what is not a vessel (ITU-R M.585): coast stations and groups (0), search
and rescue aircraft (111), handheld radios (8), SARTs, man-overboard and EPIRB devices, craft
of a parent ship, aids to navigation and the fishing-gear buoys that borrow 9xx numbers (9)."""
ALLOWED_MISSING_STEPS = 1
"""Time steps a pair may miss inside one encounter (a sample a few metres too far, or lost)."""


def slow_samples(v: VesselReports, s: EventSettings, ports: Anchorages) -> pd.DataFrame:
    """The vessel's positions every `encounter_step_s` (step = time // step_s) where it is under
    `encounter_kn` (the mean of the two sampled steps around, by position) and at least
    `encounter_port_m` from every anchorage: columns mmsi, step, lon, lat, port_m."""
    steps, lon, lat = slow_steps(v, s)
    return at_sea(np.full(len(steps), v.mmsi, np.int64), steps, lon, lat, s, ports)


def slow_steps(v: VesselReports, s: EventSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`slow_samples` before the anchorages are asked: the steps, lons and lats (none where
    the vessel's positions never imply a step under `encounter_kn`)."""
    none = np.empty(0, np.int64), np.empty(0), np.empty(0)
    if len(v) < 2 or not (v.implied_kn < s.encounter_kn).any():
        return none
    t, step_s = v.time_s, s.encounter_step_s
    steps = np.arange(np.ceil(t[0] / step_s), np.floor(t[-1] / step_s) + 1).astype(np.int64)
    at = steps * step_s
    before = np.clip(np.searchsorted(t, at, side="right") - 1, 0, len(t) - 2)
    bridged = (t[before + 1] - t[before] <= s.encounter_max_gap_s) | (t[before] == at)
    steps, at = steps[bridged], at[bridged]
    if len(steps) < 2:
        return none
    lon, lat = np.interp(at, t, v.lon), np.interp(at, t, v.lat)
    joined = np.diff(steps) == 1
    step_kn = haversine_m(lon[:-1], lat[:-1], lon[1:], lat[1:]) / step_s / KNOT_MPS
    step_kn = np.where(joined, step_kn, np.nan)
    around = np.vstack([np.r_[np.nan, step_kn], np.r_[step_kn, np.nan]])
    counted = np.isfinite(around).sum(axis=0)
    kn = np.where(counted > 0, np.nansum(around, axis=0) / np.maximum(counted, 1), np.inf)
    slow = kn < s.encounter_kn  # no sampled step around: not judged
    return steps[slow], lon[slow], lat[slow]


def at_sea(
    mmsi: np.ndarray, steps: np.ndarray, lon: np.ndarray, lat: np.ndarray, s: EventSettings,
    ports: Anchorages,
) -> pd.DataFrame:  # fmt: skip
    """The samples (`slow_steps`' of one vessel or of many, `mmsi` each) at least
    `encounter_port_m` from every anchorage, as `slow_samples` gives them."""
    port_m, _ = ports.nearest(lon, lat)
    sea = port_m >= s.encounter_port_m
    return pd.DataFrame(
        {"mmsi": mmsi[sea], "step": steps[sea], "lon": lon[sea], "lat": lat[sea],
         "port_m": port_m[sea]}
    )  # fmt: skip


def close_pairs(samples: pd.DataFrame, s: EventSettings) -> pd.DataFrame:
    """Each pair of samples of two vessels at one time step within `encounter_m`: columns
    a, b (MMSIs, a < b), step, metres, lon, lat (their midpoint), port_m (the nearer's)."""
    lat_step = s.encounter_m / M_PER_DEG
    widest = max(np.cos(np.radians(np.abs(samples["lat"]).max())), 0.05)
    grid = samples.assign(
        iy=np.floor(samples["lat"] / lat_step).astype(np.int64),
        ix=np.floor(samples["lon"] / (lat_step / widest)).astype(np.int64),
    )
    parts = []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            shifted = grid.assign(ix=grid["ix"] + dx, iy=grid["iy"] + dy)
            pairs = grid.merge(shifted, on=["step", "ix", "iy"], suffixes=("_a", "_b"))
            parts.append(pairs[pairs["mmsi_a"] < pairs["mmsi_b"]])
    pairs = pd.concat(parts, ignore_index=True)
    metres = haversine_m(pairs["lon_a"], pairs["lat_a"], pairs["lon_b"], pairs["lat_b"])
    pairs = pairs[np.asarray(metres) <= s.encounter_m]
    return pd.DataFrame(
        {
            "a": pairs["mmsi_a"].to_numpy(np.int64),
            "b": pairs["mmsi_b"].to_numpy(np.int64),
            "step": pairs["step"].to_numpy(np.int64),
            "metres": np.asarray(metres)[np.asarray(metres) <= s.encounter_m],
            "lon": ((pairs["lon_a"] + pairs["lon_b"]) / 2).to_numpy(),
            "lat": ((pairs["lat_a"] + pairs["lat_b"]) / 2).to_numpy(),
            "port_m": np.minimum(pairs["port_m_a"], pairs["port_m_b"]).to_numpy(),
        }
    )


def meetings(pairs: pd.DataFrame, s: EventSettings) -> list[pd.DataFrame]:
    """The runs of one pair's close steps (missing at most `ALLOWED_MISSING_STEPS` in a row)
    that last `encounter_min_s` or more, each a frame of `close_pairs`' rows."""
    pairs = pairs.sort_values(["a", "b", "step"]).reset_index(drop=True)
    same = (pairs["a"].diff() == 0) & (pairs["b"].diff() == 0)
    near = pairs["step"].diff() <= 1 + ALLOWED_MISSING_STEPS
    run = np.cumsum(~(same & near).to_numpy())
    out = []
    for _, g in pairs.groupby(run, sort=False):
        held = (g["step"].iloc[-1] - g["step"].iloc[0]) * s.encounter_step_s
        if held >= s.encounter_min_s:
            out.append(g)
    return out


def encounter_row(fleet: Fleet, g: pd.DataFrame, s: EventSettings) -> dict[str, Any]:
    """One meeting as an event of its first vessel naming the second (`others`): from its
    first to its last close step, placed where the two came closest, its stretch each vessel's
    reports in it (a MultiLineString of two), its strength its length over `encounter_min_s`."""
    a, b = int(g["a"].iloc[0]), int(g["b"].iloc[0])
    start, end = g["step"].iloc[0] * s.encounter_step_s, g["step"].iloc[-1] * s.encounter_step_s
    va, vb = fleet.vessels[a], fleet.vessels[b]
    mine = (va.time_s >= start) & (va.time_s <= end)
    theirs = (vb.time_s >= start) & (vb.time_s <= end)
    closest = g.loc[g["metres"].idxmin()]
    tracks = va.track_id[mine][va.track_id[mine] >= 0]
    other, port_m = fleet.who(b), float(g["port_m"].min())
    away = (
        f"{port_m / 1000:.0f} km or more from any port or anchorage"
        if np.isfinite(port_m)
        else "no port or anchorage known"
    )
    said = (
        f"within {g['metres'].median():.0f} m (closest {closest['metres']:.0f} m) of "
        f"{other['name'] or b} for {(end - start) / 3600:.1f} h, both under "
        f"{s.encounter_kn:g} kn, {away}"
    )
    return event_row(
        a, "encounter", (float(start), float(end)), int(mine.sum() + theirs.sum()),
        (float(closest["lon"]), float(closest["lat"])),
        ([*va.lon[mine], np.nan, *vb.lon[theirs]], [*va.lat[mine], np.nan, *vb.lat[theirs]]),
        (end - start) / s.encounter_min_s,
        said, identity=fleet.who(a), track_id=int(tracks[0]) if len(tracks) else None,
        others=[other],
    )  # fmt: skip


def away_from_others_ports(pairs: pd.DataFrame, doubtful: Anchorages, s: EventSettings):
    """[n] whether each of `close_pairs`' rows is `encounter_port_m` or more from every learned
    anchorage that vessels other than its two make: two vessels meeting at sea do not make the
    place an anchorage (with one more vessel once stopped there, they would reach
    `anchorage_min_vessels`). `doubtful`: the points with fewer than two vessels to spare."""
    keep = np.ones(len(pairs), bool)
    if not len(doubtful) or not len(pairs):
        return keep
    metres, _ = doubtful.nearest(pairs["lon"].to_numpy(), pairs["lat"].to_numpy())
    for i in np.flatnonzero(metres < s.encounter_port_m):
        row = pairs.iloc[i]
        two = {int(row["a"]), int(row["b"])}
        near = doubtful.within(float(row["lon"]), float(row["lat"]), s.encounter_port_m)
        keep[i] = all(len(doubtful.stoppers[k] - two) < s.anchorage_min_vessels for k in near)
    return keep


def is_vessel(mmsi: int) -> bool:
    """Whether an MMSI may be a vessel's (not of `NOT_A_VESSEL`; 9 digits, as the anonymised
    ids of some public data sets are too)."""
    return not f"{int(mmsi):09d}".startswith(NOT_A_VESSEL)


def encounters(fleet: Fleet, rules: EventRules) -> list[dict[str, Any]]:
    """Every encounter between the fleet's vessels (`is_vessel`: a buoy or a SART beside its
    ship is none), one event per pair and meeting. Samples are
    judged at sea by the anchorages that stay so whatever two vessels are left out; those that
    two vessels could make are judged for each pair (`away_from_others_ports`)."""
    s, ports = rules.settings, fleet.anchorages(rules)
    doubtful = ports.fragile(2, s.anchorage_min_vessels)
    firm = ports.subset(~doubtful)
    every = fleet.joined  # (a vessel whose positions never imply a slow step has no sample)
    slow = every.any_step(every.reports.implied_kn < s.encounter_kn)
    sampled = [(v.mmsi, *slow_steps(v, s)) for k, (m, v) in enumerate(fleet.vessels.items())
               if slow[k] and is_vessel(m)]  # fmt: skip
    mmsi = [np.full(len(x[1]), x[0], np.int64) for x in sampled]
    steps, lon, lat = ([x[i] for x in sampled] for i in (1, 2, 3))
    if not sampled:
        return []
    samples = at_sea(*(np.concatenate(a) for a in (mmsi, steps, lon, lat)), s, firm)
    if samples["mmsi"].nunique() < 2:
        return []
    pairs = close_pairs(samples, s)
    pairs = pairs[away_from_others_ports(pairs, ports.subset(doubtful), s)]
    return [encounter_row(fleet, g, s) for g in meetings(pairs, s)]
