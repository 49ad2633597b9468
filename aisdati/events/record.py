"""One event's record, defined once: its fields (events.parquet's columns, events.geojson's
properties, report.json's entries, the live watch's rows) and the one function that builds it,
for every kind, model-free, learned or live."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import pandas as pd
import pyarrow as pa

from aisdati.events.kinds import KINDS
from aisdati.tracks.schema import UTC_US

EVENTS_SCHEMA = pa.schema(
    [
        ("event_id", pa.int64()),
        ("mmsi", pa.int64()),
        ("name", pa.string()),
        ("ship_type", pa.string()),
        ("kind", pa.string()),
        ("class", pa.string()),
        ("start", UTC_US),
        ("end", UTC_US),
        ("duration_s", pa.float64()),
        ("n_reports", pa.int64()),
        ("lon", pa.float64()),
        ("lat", pa.float64()),
        ("track_id", pa.int64()),
        ("strength", pa.float64()),
        ("rarity_days", pa.float64()),
        ("evidence", pa.string()),
        ("model", pa.string()),
        ("others", pa.string()),
        ("coverage", pa.string()),
        ("geometry", pa.binary()),
    ]
)
"""events.parquet (GeoParquet, WKB in WGS84 lon/lat): `start`/`end` the event's first and
last report; `lon`/`lat` the report where it is strongest; `track_id` that report's track
(null: a report in no track, e.g. a slow one); `class` alert or activity; `strength` how far
over its threshold (1 = at it); `rarity_days` an alert as strong came once in so many
vessel-days of the training period (null: not calibrated, or an activity); `model` the model of
a learned event; `others` the other vessels a fleet event names (`aisdati.events.fleet`), as
JSON: a list of {mmsi, name, ship_type} (null: the event is one vessel's); `coverage` whether a
gap's area kept being heard ("heard": others near its ends kept reporting; "quiet": the area
went silent too; null: not judged); `geometry` the stretch (an area event: its outline)."""
EVENT_COLUMNS = (
    *[n for n in EVENTS_SCHEMA.names if n not in ("event_id", "geometry")],
    "lons",
    "lats",
)
"""An event's fields before it is numbered and drawn (`lons`/`lats`: its stretch's positions;
a fleet event's, each vessel's stretch in turn, separated by NaN: a MultiLineString)."""


def event_row(
    mmsi: int,
    kind: str,
    times_s: tuple[float, float],
    n_reports: int,
    place: tuple[float, float],
    stretch: tuple[Sequence[float], Sequence[float]],
    strength: float,
    evidence: str,
    *,
    identity: dict | None = None,
    track_id: int | None = None,
    rarity_days: float | None = None,
    model: str | None = None,
    others: Sequence[dict] | None = None,
    coverage: str | None = None,
) -> dict[str, Any]:
    """An event as a record of `EVENT_COLUMNS`: its vessel (`identity`: name, ship_type), kind
        and class, first and last report times (seconds since the epoch, kept to the microsecond as
        reports are), where it is strongest (`place`: lon, lat), its stretch's positions, the track
        of its strongest report, its strength over its threshold, its rarity and evidence; a fleet
    event's other vessels (`others`: mmsi, name, ship_type each) and a gap's `coverage`."""
    identity = identity or {}
    start, end = times_s
    return {
        "mmsi": int(mmsi), "name": identity.get("name"), "ship_type": identity.get("ship_type"),
        "kind": kind, "class": KINDS[kind].cls, "start": utc(start), "end": utc(end),
        "duration_s": float(end - start), "n_reports": int(n_reports),
        "lon": float(place[0]), "lat": float(place[1]), "track_id": track_id,
        "strength": round(float(strength), 3), "rarity_days": rarity_days, "evidence": evidence,
        "model": model, "others": _others(others), "coverage": coverage,
        "lons": list(stretch[0]), "lats": list(stretch[1]),
    }  # fmt: skip


def _others(others: Sequence[dict] | None) -> str | None:
    if not others:
        return None
    keys = ("mmsi", "name", "ship_type")
    return json.dumps([{k: o.get(k) for k in keys} for o in others])


def utc(seconds: float) -> pd.Timestamp:
    """Seconds since the epoch as a UTC time, to the microsecond."""
    return pd.Timestamp(round(seconds * 1e6), unit="us", tz="UTC")
