"""What `aisdati detect` writes: scores.parquet, profiles.parquet, anomalies.geojson, the maps
(`aisdati.detection.maps`), metrics.json (with labels) and report.json."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from aisdati.ais.card import card_warnings
from aisdati.detection.run import Detection
from aisdati.events.table import events_geojson, events_summary, write_events
from aisdati.execution import Runner
from aisdati.outdir import atomic_write_bytes, parquet_bytes
from aisdati.tracks.ashore import AshoreCheck

OUTPUTS = (
    "scores.parquet",
    "profiles.parquet",
    "anomalies.geojson",
    "events.parquet",
    "events.geojson",
    "anchorages.geojson",
    "map.png",
    "map.html",
    "metrics.json",
    "report.json",
    "evidence/track-*.png",
)
"""Every file detect may write into --out (relative to it): a run replaces them as one set and
removes those of an earlier run it does not write (`aisdati.outdir.OutputSet`)."""
REPORT = "report.json"
"""The report of the set, written last."""

SCORES_SCHEMA = pa.schema(
    [
        ("track_id", pa.int64()),
        ("mmsi", pa.int64()),
        ("model", pa.string()),
        ("n_points", pa.int64()),
        ("score", pa.float64()),
        ("threshold", pa.float64()),
        ("flagged", pa.bool_()),
        ("rank", pa.int64()),
        ("max_dev_m", pa.float64()),
        ("max_dev_lon", pa.float64()),
        ("max_dev_lat", pa.float64()),
        ("max_dev_index", pa.int64()),
        ("ashore_reports", pa.int64()),
        ("events", pa.int64()),
        ("alerts", pa.int64()),
        ("event_kinds", pa.string()),
        ("name", pa.string()),
        ("ship_type", pa.string()),
    ]
)
"""scores.parquet, one row per test track, sorted by rank (1 = most abnormal). score: the
judging model's score, in the unit the file's metadata (`aisdati.score_unit`) and report.json
name; threshold: what flags it, in the same unit (the model's calibrated threshold, or the
batch-relative one asked for); max_dev_*: the track point with the largest local deviation;
ashore_reports: reports well inland (`aisdati.tracks.ashore`; 0 with --no-ashore), which flag
the track from `AshoreCheck.min_reports` on and rank it above every track at sea; events,
alerts, event_kinds: the track's events (events.parquet) and how many are alerts, any of which
flags it (an activity flags nothing); name, ship_type: its
vessel's, where ingest saw its static messages (vessels.parquet)."""


def write_outputs(result: Detection, out: Path, runner: Runner | None = None) -> list[Path]:
    """Every output of a detection in `out` (the command's staging folder: `OutputSet`), each
    written whole or not at all, report.json last; returns them. The figures are drawn as tasks
    of `runner` (`write_maps`)."""
    from aisdati.detection.maps import write_maps  # matplotlib only when drawing

    out.mkdir(parents=True, exist_ok=True)
    files = []
    table = pa.Table.from_pandas(
        result.scores.sort_values("rank").reset_index(drop=True),
        schema=SCORES_SCHEMA,
        preserve_index=False,
    ).replace_schema_metadata(scores_metadata(result))
    path = out / "scores.parquet"
    atomic_write_bytes(path, parquet_bytes(table))
    files.append(path)
    path = out / "profiles.parquet"
    atomic_write_bytes(path, parquet_bytes(profiles_table(result)))
    files.append(path)
    path = out / "anomalies.geojson"
    atomic_write_bytes(path, json.dumps(anomalies_geojson(result)).encode())
    files.append(path)
    files += write_events(result.events, out)
    files += ports_file(result, out)
    files += write_maps(result, out, runner)
    if result.metrics is not None:
        path = out / "metrics.json"
        atomic_write_bytes(path, json.dumps(result.metrics, indent=2).encode())
        files.append(path)
    path = out / "report.json"
    atomic_write_bytes(path, json.dumps(report_dict(result), indent=2, default=str).encode())
    files.append(path)
    return files


def ports_file(result: Detection, out: Path) -> list[Path]:
    """anchorages.geojson: the ports and anchorages the events were judged by (what `--ports`
    reads back), where there were any."""
    if result.ports is None or not len(result.ports):
        return []
    path = out / "anchorages.geojson"
    atomic_write_bytes(path, json.dumps(result.ports.geojson()).encode())
    return [path]


def write_event_outputs(result: Detection, out: Path) -> list[Path]:
    """What `detect --models none` writes: the events, a map of them and report.json."""
    from aisdati.detection.webmap import html_detection_map

    out.mkdir(parents=True, exist_ok=True)
    files = write_events(result.events, out) + ports_file(result, out)
    page = out / "map.html"
    title = f"aisdati: {len(result.events)} event(s), no model"
    html_detection_map(
        [], [], [], np.zeros(0, bool), [], page, events=events_geojson(result.events), title=title
    )
    path = out / "report.json"
    atomic_write_bytes(path, json.dumps(report_dict(result), indent=2, default=str).encode())
    return [*files, page, path]


def profiles_table(result: Detection) -> pa.Table:
    """profiles.parquet: every test track's local deviation (m) at each of its reports (the
    step error for `--score step`, the distance to the matched rollout point otherwise)."""
    tracks, profiles = result.tracks, result.profiles
    return pa.table(
        {
            "track_id": np.concatenate(
                [np.full(len(t.positions), t.track_id, np.int64) for t in tracks]
            ),
            "index": np.concatenate([np.arange(len(t.positions)) for t in tracks]),
            "lon": np.concatenate([t.positions[:, 0] for t in tracks]),
            "lat": np.concatenate([t.positions[:, 1] for t in tracks]),
            "deviation_m": np.concatenate(profiles),
        }
    )


def _line(coords: np.ndarray) -> dict[str, Any]:
    return {"type": "LineString", "coordinates": np.round(coords, 6).tolist()}


def anomalies_geojson(result: Detection) -> dict[str, Any]:
    """Flagged tracks (kind=track), what each was compared with (kind=evidence: its best
    rollout, the nearest training track or its one-step predictions) and the points of largest
    deviation (kind=max_deviation), as one FeatureCollection in lon/lat (WGS84)."""
    features = []
    what = result.evidence_kind
    by_id = {t.track_id: (t, r) for t, r in zip(result.tracks, result.rollouts, strict=True)}
    for row in result.scores[result.scores["flagged"]].sort_values("rank").itertuples():
        track, roll = by_id[row.track_id]
        props = {
            "track_id": int(row.track_id),
            "mmsi": int(row.mmsi),
            "name": row.name,
            "ship_type": row.ship_type,
            "event_kinds": row.event_kinds,
            "alerts": int(row.alerts),
            "model": row.model,
            "rank": int(row.rank),
            "score": float(row.score),
            "threshold": float(row.threshold),
            "max_dev_m": float(row.max_dev_m),
            "ashore_reports": int(row.ashore_reports),
            "start": str(track.start),
        }
        features.append(
            {
                "type": "Feature",
                "properties": {"kind": "track", **props},
                "geometry": _line(track.positions),
            }
        )
        features.append(
            {
                "type": "Feature",
                "properties": {"kind": "evidence", "what": what, "track_id": props["track_id"]},
                "geometry": _line(roll),
            }
        )
        point = {
            "type": "Point",
            "coordinates": [round(row.max_dev_lon, 6), round(row.max_dev_lat, 6)],
        }
        features.append(
            {
                "type": "Feature",
                "properties": {
                    "kind": "max_deviation",
                    "track_id": props["track_id"],
                    "distance_m": props["max_dev_m"],
                },
                "geometry": point,
            }
        )
    return {"type": "FeatureCollection", "features": features}


def scores_metadata(result: Detection) -> dict[bytes, bytes]:
    """scores.parquet's own account of its `score` column: the score, its unit and the rule
    that flags, so that the file read alone says what its numbers are."""
    s = result.settings
    return {
        b"aisdati.score": (result.score).encode(),
        b"aisdati.score_unit": result.judged_by.unit.encode(),
        b"aisdati.flag_rule": (s.rule if s else "calibrated").encode(),
    }


FLAG_RULES = {
    "calibrated": "score above the judging model's calibrated threshold, which flags "
    "`contamination` of its own training tracks (independent of the batch)",
    "relative": "score above `threshold` x the largest score of the tracks judged together "
    "(the paper's rule, section 6.2; depends on the batch)",
    "top": "the `top_percent` highest scores of the tracks judged together (depends on the batch)",
}
"""report.json's `flag_rule_definition`, by `DetectSettings.rule`."""


def thresholds(result: Detection) -> dict[str, Any] | None:
    """By the calibrated rule, each judging model's threshold and its bootstrap spread
    (`Detector.threshold_spread`), in the score's unit."""
    s = result.settings
    if s is None or s.rule != "calibrated":
        return None
    used = set(result.scores["model"])
    out = {}
    for m in result.models:
        if m.name in used:
            how = s.how_for(m)
            lo, hi = m.threshold_spread(how, s.contamination)
            out[m.name] = {"threshold": round(m.threshold(how, s.contamination), 3),
                           "spread_5_95": [round(lo, 3), round(hi, 3)]}  # fmt: skip
    return out


def report_dict(result: Detection) -> dict[str, Any]:
    """report.json: the settings, models, warnings, counts, timings, metrics and what the
    score measures."""
    s = result.settings
    sc = result.scores
    return {
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in s.__dict__.items()}
        if s
        else {},
        "models": [m.name for m in result.models],
        "warnings": [w for m in result.models for w in card_warnings(m.card, m.name)]
        + result.notes,
        "test_tracks": len(sc),
        "coverage": result.coverage.as_dict() if result.coverage else None,
        "thresholds": thresholds(result),
        "flagged": int(sc["flagged"].sum()),
        "flagged_ashore": int(AshoreCheck().flags(sc["ashore_reports"]).sum()),
        "flag_rule": s.rule if s else None,
        "flag_rule_definition": FLAG_RULES[s.rule] if s else None,
        "max_score": float(sc["score"].max()) if len(sc) else None,
        "score_unit": result.judged_by.unit if s else None,
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
        "metrics": result.metrics,
        "score_definition": result.judged_by.definition if s else None,
        **events_summary(result.events, result.reports_judged),
    }
