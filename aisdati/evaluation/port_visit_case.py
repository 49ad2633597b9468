"""A constructed port visit: a real vessel that sailed past a port or anchorage stops there.

Vessel V's report nearest an anchorage the traffic shows (`aisdati.events.anchorages`), on a
pass within `PASS_M` of it under way and not in one of its real visits, is where V stops: a
real stop of another vessel B (its report times and its small movement about its middle, its
reported speed and course) is laid there for `HOURS`, and V's later reports are retimed by as
much, so V then sails on along its real route. The deceleration and acceleration are not
modelled (V stops at one report)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from aisdati.evaluation.case import Case
from aisdati.evaluation.encounter_case import LOOKED_AT, stop_rows
from aisdati.events.anchorages import learned_from
from aisdati.events.port_visits import stays
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings

HOURS = (3.5, 12.0)
"""How long a constructed visit lasts (drawn uniformly): from over the 3-hour minimum to a
half-day call."""
PASS_M = 1500.0
UNDER_WAY_KN = 3.0


def construct_port_visit(
    reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator
) -> tuple[pd.DataFrame, pd.DataFrame, Case] | None:
    """`reports` with one port visit written in (`aisdati.evaluation.constructed.Constructor`),
    or None where no vessel passes an anchorage under way or none has a stop to lend."""
    s = EventSettings()
    ports = learned_from(reports, s)
    if not len(ports):
        return None
    by_vessel = {int(m): g.sort_values("time") for m, g in reports.groupby("mmsi", sort=False)}
    order = [int(m) for m in rng.permutation(sorted(by_vessel))[:LOOKED_AT]]
    held_s = float(rng.uniform(*HOURS)) * 3600
    for a in order:
        v = VesselReports.of(by_vessel[a])
        metres, _ = ports.nearest(v.lon, v.lat)
        passing = np.flatnonzero((metres <= PASS_M) & (v.sog >= UNDER_WAY_KN))
        passing = passing[(passing > 0) & (passing < len(v) - 1)]
        for first, last, _ in stays(v, metres, s):  # not a pass during a real visit
            passing = passing[(passing < first) | (passing > last)]
        if not passing.size:
            continue
        k = int(passing[np.argmin(metres[passing])])
        for b in order:
            rows = stop_rows(VesselReports.of(by_vessel[b]), s, held_s, rng) if b != a else None
            if rows is None:
                continue
            stopped = _stopped_at(by_vessel[a], k, by_vessel[b].iloc[rows])
            mine = by_vessel[a]
            t = mine["time"].iloc[k + 1 :] + pd.Timedelta(seconds=held_s)
            after = mine.iloc[k + 1 :].assign(time=t)
            out = pd.concat(
                [reports[reports["mmsi"] != a], mine.iloc[: k + 1], stopped, after],
                ignore_index=True,
            ).sort_values(["mmsi", "time"], kind="stable")
            case = Case("port-visit", (a,), stopped["time"].iloc[0], stopped["time"].iloc[-1])
            return out.reset_index(drop=True), identity, case
        return None
    return None


def _stopped_at(v: pd.DataFrame, k: int, stop: pd.DataFrame) -> pd.DataFrame:
    """`stop` (another vessel's stop) laid at V's report `k`, beginning a minute after it."""
    stop_time = pd.to_datetime(stop["time"], utc=True)
    begin = pd.Timestamp(v["time"].iloc[k]) + pd.Timedelta(minutes=1)
    lat0 = float(v["lat"].iloc[k])
    east = (stop["lon"] - np.median(stop["lon"])) * np.cos(np.radians(stop["lat"]))
    return stop.assign(
        mmsi=int(v["mmsi"].iloc[k]),
        time=(begin + (stop_time - stop_time.iloc[0])).astype(v["time"].dtype),
        lon=float(v["lon"].iloc[k]) + east / np.cos(np.radians(lat0)),
        lat=lat0 + (stop["lat"] - np.median(stop["lat"])),
        track_id=-1,
    )
