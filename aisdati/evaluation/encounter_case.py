"""A constructed encounter: two real vessels' real reports brought together at sea for hours.

Vessel A is left as it is: a real stretch of it slow at sea (under `encounter_kn`, at least
`encounter_port_m` plus `MARGIN_M` from every anchorage the traffic shows) lasting `HOURS`. Vessel
B's real stop (a stretch under `stopped_kn` within `STOP_SPREAD_M` of its middle) is retimed to
that stretch and laid beside A, as two vessels rafted or lying close drift together: at each of
B's reports, A's position then (interpolated between its reports), a fixed offset of
`OFFSET_M`, and B's own small movement about its stop. B reports A's motion (its speed and
course); its other reports are dropped (B is heard only while it meets A). Both keep their
identity, so the event must name each."""

from __future__ import annotations

import numpy as np
import pandas as pd

from aisdati.evaluation.case import Case
from aisdati.events.anchorages import Anchorages, learned_from
from aisdati.events.encounters import slow_samples
from aisdati.events.reports import M_PER_DEG, VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import runs
from aisdati.geo import moved_m

HOURS = (2.5, 6.0)
"""How long a constructed meeting lasts (drawn uniformly): from over the 2-hour minimum to
what a transfer between two vessels takes."""
OFFSET_M = (50.0, 250.0)
"""How far B lies from A (drawn uniformly, at a random bearing)."""
MARGIN_M = 1000.0
STOP_SPREAD_M = 200.0
LOOKED_AT = 400
"""How many vessels are looked at for each part before giving up (the traffic offers none)."""


def construct_encounter(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator
) -> tuple[pd.DataFrame, pd.DataFrame, Case] | None:
    """`reports` with one encounter written in (`aisdati.evaluation.constructed.Constructor`),
    or None where no vessel is slow at sea long enough or none has a stop to lend."""
    s = EventSettings()
    ports = learned_from(reports, s)
    by_vessel = {int(m): g.sort_values("time") for m, g in reports.groupby("mmsi", sort=False)}
    order = rng.permutation(sorted(by_vessel))[:LOOKED_AT]
    hours = float(rng.uniform(*HOURS))
    for a in order:
        a = int(a)
        window = _slow_at_sea(VesselReports.of(by_vessel[a]), s, ports, hours * 3600, rng)
        if window is None:
            continue
        for b in order:
            b = int(b)
            if b == a:
                continue
            stop = stop_rows(VesselReports.of(by_vessel[b]), s, hours * 3600, rng)
            if stop is not None:
                moved = _beside(by_vessel[a], by_vessel[b].iloc[stop], window[0], rng)
                out = pd.concat(
                    [reports[reports["mmsi"] != b], moved], ignore_index=True
                ).sort_values(["mmsi", "time"], kind="stable")
                case = Case("encounter", (a, b), moved["time"].iloc[0], moved["time"].iloc[-1])
                return out.reset_index(drop=True), identity, case
        return None  # a vessel to meet, but no stop anywhere to lend it
    return None


def _slow_at_sea(
    v: VesselReports, s: EventSettings, ports: Anchorages, held_s: float, rng: np.random.Generator
) -> tuple[float, float] | None:
    """A random window of `held_s` (seconds since the epoch) in which the vessel's samples are
    slow and at sea with `MARGIN_M` to spare, step after step; None where there is none."""
    samples = slow_samples(v, s, ports)
    samples = samples[samples["port_m"] >= s.encounter_port_m + MARGIN_M]
    if not len(samples):
        return None
    steps = samples["step"].to_numpy()
    need = int(np.ceil(held_s / s.encounter_step_s))
    breaks = np.flatnonzero(np.diff(steps) != 1)
    firsts, lasts = np.r_[0, breaks + 1], np.r_[breaks, len(steps) - 1]
    long = [(steps[f], steps[x]) for f, x in zip(firsts, lasts, strict=True)]
    long = [(f, x) for f, x in long if x - f >= need]
    if not long:
        return None
    first, last = long[int(rng.integers(len(long)))]
    begin = int(rng.integers(first, last - need + 1))
    return begin * s.encounter_step_s, (begin + need) * s.encounter_step_s


def stop_rows(
    v: VesselReports, s: EventSettings, held_s: float, rng: np.random.Generator
) -> np.ndarray | None:
    """The rows (positions in the vessel's time order) of a random `held_s` of one of its
    stops, reports at most `encounter_max_gap_s / 2` apart; None where it has none."""
    t = v.time_s
    for a, b in runs(v.sog < s.stopped_kn):
        silent = np.max(np.diff(t[a : b + 1]), initial=0.0)
        if t[b] - t[a] < held_s or silent > s.encounter_max_gap_s / 2:
            continue
        begin = int(rng.integers(a, int(np.searchsorted(t, t[b] - held_s, "right"))))
        end = int(np.searchsorted(t, t[begin] + held_s, "right"))
        lon, lat = v.lon[begin:end], v.lat[begin:end]
        east = (lon - np.median(lon)) * np.cos(np.radians(lat[0])) * M_PER_DEG
        north = (lat - np.median(lat)) * M_PER_DEG
        if np.max(np.hypot(east, north)) <= STOP_SPREAD_M:
            return np.arange(begin, end)
    return None


def _beside(
    a: pd.DataFrame, b: pd.DataFrame, start_s: float, rng: np.random.Generator
) -> pd.DataFrame:
    """B's stop `b` retimed to begin at `start_s` and laid beside A (`a`: its reports)."""
    a = a.sort_values("time")
    at = VesselReports.of(a).time_s
    b_time = pd.to_datetime(b["time"], utc=True)
    b_s = (b_time - b_time.iloc[0]).dt.total_seconds().to_numpy() + start_s
    lon, lat = np.interp(b_s, at, a["lon"]), np.interp(b_s, at, a["lat"])
    lon, lat = moved_m(lon, lat, float(rng.uniform(0, 360)), float(rng.uniform(*OFFSET_M)))
    own_lat = np.radians(b["lat"].to_numpy())
    east = (b["lon"].to_numpy() - np.median(b["lon"])) * np.cos(own_lat)
    lon = lon + east / np.cos(np.radians(lat))
    lat = lat + (b["lat"].to_numpy() - np.median(b["lat"]))
    nearest = np.clip(np.searchsorted(at, b_s), 0, len(at) - 1)
    return b.assign(
        time=pd.to_datetime(np.round(b_s * 1e6).astype("int64"), unit="us", utc=True).astype(
            a["time"].dtype
        ),
        lon=lon, lat=lat,
        sog=a["sog"].to_numpy()[nearest], cog=a["cog"].to_numpy()[nearest],
        track_id=-1,
    )  # fmt: skip
