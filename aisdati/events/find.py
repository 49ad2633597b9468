"""Events from reports: every model-free finder run over each vessel's reports, and the
events placed (times, where, the track) as the rows of events.parquet."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from aisdati.events.behaviour import ashore, drift, gaps, loitering, sudden_speed_change
from aisdati.events.motion import course_inconsistent, position_jumps, speed_inconsistent
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found
from aisdati.tracks.ashore import AshoreCheck

EVENT_COLUMNS = (
    "mmsi", "name", "ship_type", "kind", "start", "end", "duration_s", "n_reports", "lon",
    "lat", "track_id", "strength", "evidence", "model", "lons", "lats",
)  # fmt: skip
"""An event's fields (events.parquet; `lons`/`lats`: the stretch's positions)."""


def find_events(
    v: VesselReports,
    settings: EventSettings = EventSettings(),
    length_m: float = np.nan,
    seen: np.ndarray | None = None,
) -> list[Found]:
    """Every model-free event of one vessel (`aisdati.events.kinds.MODEL_FREE`), in time order;
    `length_m`: the vessel's length if known; `seen`: where its area's training traffic reported
    ashore (`aisdati.tracks.ashore`)."""
    check = AshoreCheck()
    finders: list[Callable[[], list[Found]]] = [
        lambda: position_jumps(v, settings),
        lambda: speed_inconsistent(v, settings),
        lambda: course_inconsistent(v, settings),
        lambda: drift(v, settings, length_m),
        lambda: sudden_speed_change(v, settings),
        lambda: loitering(v, settings),
        lambda: gaps(v, settings, check),
        lambda: ashore(v, check, seen),
    ]
    found = [event for finder in finders for event in finder()]
    return sorted(found, key=lambda e: (e.start, e.kind))


def placed(v: VesselReports, found: Sequence[Found], identity: dict | None = None) -> pd.DataFrame:
    """The events of one vessel as rows of `EVENT_COLUMNS` (`placed_rows`), as a table."""
    return pd.DataFrame(placed_rows(v, found, identity), columns=list(EVENT_COLUMNS))


def placed_rows(
    v: VesselReports, found: Sequence[Found], identity: dict | None = None
) -> list[dict[str, Any]]:
    """The events of one vessel as records of `EVENT_COLUMNS`: times, the report where each is
    strongest (its place), the track of that report, the stretch's positions, and the vessel's
    name and type (`identity`: name, ship_type) when known. Records, not a table: the live
    watch places events thousands of times a second, and a table costs about as much as
    finding them."""
    identity = identity or {}
    rows = []
    for e in found:
        track = int(v.track_id[e.peak])
        rows.append(
            {
                "mmsi": v.mmsi,
                "name": identity.get("name"),
                "ship_type": identity.get("ship_type"),
                "kind": e.kind,
                "start": _utc(v.time_s[e.start]),
                "end": _utc(v.time_s[e.end]),
                "duration_s": float(v.time_s[e.end] - v.time_s[e.start]),
                "n_reports": int(e.end - e.start + 1),
                "lon": float(v.lon[e.peak]),
                "lat": float(v.lat[e.peak]),
                "track_id": track if track >= 0 else None,
                "strength": round(float(e.strength), 3),
                "evidence": e.evidence,
                "model": None,
                "lons": v.lon[e.start : e.end + 1].tolist(),
                "lats": v.lat[e.start : e.end + 1].tolist(),
            }
        )
    return rows


def _utc(seconds: float) -> pd.Timestamp:
    return pd.Timestamp(round(seconds * 1e6), unit="us", tz="UTC")
