"""What `aisdati detect` writes: scores.parquet, profiles.parquet, anomalies.geojson, the maps
(`aisdati.detection.maps`), metrics.json (with labels) and report.json."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from aisdati.ais import score_unit
from aisdati.ais.card import card_warnings
from aisdati.detection.run import Detection
from aisdati.execution import Runner
from aisdati.outdir import atomic_write_bytes, parquet_bytes
from aisdati.tracks.ashore import AshoreCheck

OUTPUTS = (
    "scores.parquet",
    "profiles.parquet",
    "anomalies.geojson",
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
        ("score_m", pa.float64()),
        ("score", pa.float64()),
        ("flagged", pa.bool_()),
        ("rank", pa.int64()),
        ("max_dev_m", pa.float64()),
        ("max_dev_lon", pa.float64()),
        ("max_dev_lat", pa.float64()),
        ("max_dev_index", pa.int64()),
        ("ashore_reports", pa.int64()),
    ]
)
"""scores.parquet, one row per test track, sorted by rank (1 = most abnormal). score_m: best-of-K
mean great-circle distance along the warping path (metres); score: score_m / max over the test
set; max_dev_*: the track point with the largest distance to its matched rollout point;
ashore_reports: reports well inland (`aisdati.tracks.ashore`; 0 with --no-ashore), which flag
the track from `AshoreCheck.min_reports` on and rank it above every track at sea."""

SCORE_DEFINITIONS = {
    "rollout": "best of K free rollouts: great-circle DTW / warping-path length (m)",
    "step": "teacher-forced: mean of the largest 10% of best-of-K one-step prediction errors (m)",
    "steprate": "teacher-forced: mean of the largest 10% of best-of-K one-step prediction "
    "errors, each over its report interval (at least the track's median interval) (m/s)",
    "stepspread": "teacher-forced: mean of the largest 10% of best-of-K one-step prediction "
    "errors, each over the K draws' spread (root mean square distance from their centroid) "
    "plus 10 m (multiples of the spread)",
    "stepod": "the larger of two rarities among the training tracks' own scores, -log10((1 + "
    "training tracks scoring as high) / (training tracks + 1)): of stepspread, and of the "
    "origin-destination distance where it is beyond the 95th percentile of the training "
    "tracks' own (else 0)",
    "lane": "mean of the largest 10% of each report's distance to the nearest point of the "
    "lane_rollouts free rollouts of twice the track's steps and, with lane_traffic, of one rollout "
    "from each training track's start (nearest: of the training tracks starting within "
    "near_km), sqrt(d^2 + (lane_course_km sin(dcourse / 2))^2) for great-circle "
    "distance d and course difference dcourse (m)",
    "both": "rollout / median training rollout score + step / median training step score",
    "steplane": "step / median training step score + lane / median training lane score",
    "steptraffic": "step / median training step score + distance to the training tracks "
    "(their lane, as nearest's) / its median over the training tracks",
    "area": "lane + the track's origin-destination distance to the nearest training track "
    "(the larger of the starts' and the ends' distances) beyond the 95th percentile of the "
    "training tracks' own (m)",
    "nearest": "great-circle DTW / warping-path length (m) to the nearest training "
    "track starting within near_km",
}
"""report.json's `score_definition`: what the score of each kind measures."""


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
    )
    path = out / "scores.parquet"
    atomic_write_bytes(path, parquet_bytes(table))
    files.append(path)
    path = out / "profiles.parquet"
    atomic_write_bytes(path, parquet_bytes(profiles_table(result)))
    files.append(path)
    path = out / "anomalies.geojson"
    atomic_write_bytes(path, json.dumps(anomalies_geojson(result)).encode())
    files.append(path)
    files += write_maps(result, out, runner)
    if result.metrics is not None:
        path = out / "metrics.json"
        atomic_write_bytes(path, json.dumps(result.metrics, indent=2).encode())
        files.append(path)
    path = out / "report.json"
    atomic_write_bytes(path, json.dumps(report_dict(result), indent=2, default=str).encode())
    files.append(path)
    return files


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
            "model": row.model,
            "rank": int(row.rank),
            "score": float(row.score),
            "score_m": float(row.score_m),
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


def thresholds(result: Detection) -> dict[str, Any] | None:
    """With `--contamination`, each judging model's calibrated threshold and its bootstrap
    spread (`Detector.threshold_spread`), in the score's unit."""
    s = result.settings
    if s is None or s.contamination is None:
        return None
    used = set(result.scores["model"])
    out = {}
    for m in result.models:
        if m.name in used:
            lo, hi = m.threshold_spread(s.how, s.contamination)
            out[m.name] = {"threshold": round(m.threshold(s.how, s.contamination), 3),
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
        "warnings": [w for m in result.models for w in card_warnings(m.card, m.name)],
        "test_tracks": len(sc),
        "coverage": result.coverage.as_dict() if result.coverage else None,
        "thresholds": thresholds(result),
        "flagged": int(sc["flagged"].sum()),
        "flagged_ashore": int(AshoreCheck().flags(sc["ashore_reports"]).sum()),
        "max_score_m": float(sc["score_m"].max()) if len(sc) else None,
        "score_unit": score_unit(result.score) if s else None,
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
        "metrics": result.metrics,
        "score_definition": SCORE_DEFINITIONS[
            "nearest" if s.method == "nearest" and s.score != "lane" else s.score
        ]
        if s
        else None,
    }
