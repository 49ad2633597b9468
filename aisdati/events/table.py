"""events.parquet and events.geojson: one row (feature) per event, its stretch as the
geometry (a point where the event is one report), and the events' part of report.json."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import shapely

from aisdati.events.kinds import ALERT, KINDS
from aisdati.events.record import EVENTS_SCHEMA
from aisdati.outdir import atomic_write_bytes, parquet_bytes
from aisdati.tracks.schema import geo_metadata

GEO_METADATA = geo_metadata("LineString", "Point", "Polygon", "MultiLineString")


def shape(kind: str, lons: list[float], lats: list[float]) -> shapely.Geometry:
    """An event's geometry: an area kind's outline as a polygon (`EventKind.area`); where NaN
    separates parts (a fleet event's vessels: `aisdati.events.record.EVENT_COLUMNS`) a
    MultiLineString; else its stretch as a line, or a point where it is one report."""
    xy = np.round(np.column_stack([lons, lats]), 6)
    if KINDS[kind].area:
        return shapely.Polygon(xy)
    gaps = np.flatnonzero(np.isnan(xy[:, 0]))
    if gaps.size:
        parts = [part[~np.isnan(part[:, 0])] for part in np.split(xy, gaps)]
        parts = [p for p in parts if len(p)]
        return shapely.MultiLineString([p if len(p) > 1 else np.repeat(p, 2, 0) for p in parts])
    return shapely.Point(xy[0]) if len(xy) == 1 else shapely.LineString(xy)


def events_arrow(events: pd.DataFrame) -> pa.Table:
    """The events as events.parquet's table."""
    stretches = zip(events["kind"], events["lons"], events["lats"], strict=True)
    geometry = [shapely.to_wkb(shape(k, a, b)) for k, a, b in stretches]
    frame = events.drop(columns=["lons", "lats"]).assign(geometry=geometry)
    frame["track_id"] = frame["track_id"].astype("Int64")
    for key in ("start", "end"):  # reports' times are microseconds (a learned event's: rounded)
        frame[key] = pd.to_datetime(frame[key], utc=True).dt.round("us")
    table = pa.Table.from_pandas(frame, schema=EVENTS_SCHEMA, preserve_index=False)
    return table.replace_schema_metadata({b"geo": json.dumps(GEO_METADATA).encode()})


def events_geojson(events: pd.DataFrame) -> dict[str, Any]:
    """The events as a GeoJSON FeatureCollection (the stretch; properties: the fields)."""
    features = []
    for e in _records(events):
        drawn = shape(e["kind"], e.pop("lons"), e.pop("lats"))
        features.append(
            {"type": "Feature", "geometry": shapely.geometry.mapping(drawn), "properties": e}
        )
    return {"type": "FeatureCollection", "features": features}


def _records(events: pd.DataFrame) -> list[dict[str, Any]]:
    out = []
    for row in events.to_dict("records"):
        row = {k: (None if _missing(v) else v) for k, v in row.items()}
        for key in ("start", "end"):
            row[key] = row[key].isoformat() if row[key] is not None else None
        row["label"] = KINDS[row["kind"]].label
        out.append(row)
    return out


def _missing(v: Any) -> bool:
    return not isinstance(v, list) and pd.isna(v)


def write_events(events: pd.DataFrame, out: Path) -> list[Path]:
    """events.parquet and events.geojson in `out`, each whole or not at all."""
    parquet, geojson = out / "events.parquet", out / "events.geojson"
    atomic_write_bytes(parquet, parquet_bytes(events_arrow(events)))
    atomic_write_bytes(geojson, json.dumps(events_geojson(events), default=str).encode())
    return [parquet, geojson]


def ranked(events: pd.DataFrame) -> pd.DataFrame:
    """What to look at first: the alerts, rarest first (on the training traffic; then the
    strongest where not calibrated), then the activity in time order."""
    alerts = events[events["class"] == ALERT]
    alerts = alerts.sort_values(["rarity_days", "strength"], ascending=False, na_position="last")
    return pd.concat([alerts, events[events["class"] != ALERT].sort_values("start")])


def gaps_by_coverage(events: pd.DataFrame) -> dict[str, int]:
    """How many gaps each coverage has (`aisdati.events.coverage`: heard, quiet; unjudged)."""
    gaps = events[events["kind"] == "gap"] if len(events) else events
    counts = gaps["coverage"].fillna("unjudged").value_counts() if len(gaps) else {}
    return {k: int(counts.get(k, 0)) for k in ("heard", "quiet", "unjudged")}


def events_summary(events: pd.DataFrame, reports_judged: int) -> dict[str, Any]:
    """report.json's events: how many reports were judged, alerts and events per kind, gaps per
    coverage, and
    each event, alerts first and rarest first (`ranked`; its stretch's positions left to
    events.geojson)."""
    return {
        "reports_judged": reports_judged,
        "alerts": int((events["class"] == ALERT).sum()) if len(events) else 0,
        "events_by_kind": events["kind"].value_counts().to_dict() if len(events) else {},
        "gaps_by_coverage": gaps_by_coverage(events),
        "events": [
            {k: v for k, v in e.items() if k not in ("lons", "lats")}
            for e in _records(ranked(events))
        ],
    }
