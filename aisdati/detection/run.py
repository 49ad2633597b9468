"""Detection of abnormal tracks (section 6.2 of the paper): scores -> flags -> outputs.

Each test track goes to the model whose training tracks start nearest to where it starts, and is
scored by that model's detector (`aisdati.detectors`): by default DATI, judged by the lane its K
free rollouts from the track's first point cover (`--score lane`, the default), by its best
rollout (`--score rollout`, the paper's), by its teacher-forced one-step predictions along the
track (`--score step`) or by rollout and step together (`--score both`). Every score is in
metres and higher means more abnormal. Flags: scores divided by their maximum over the test
set above `threshold` (the paper's Λ = 0.75), or the `top_percent` highest, or scores above the
model's calibrated threshold (`contamination`: the share of its own training tracks it would
flag), which does not depend on the test set. For every track the point of largest local deviation
(the peak of its deviation profile) tells where it strays most.

Default test set (section 6.2): tracks of the `other` cluster, not used in training, whose first
point lies within `near_km` (default 10 km) of some training track's first point.
"""

from __future__ import annotations

import json
import math
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from aisdati.ais.card import card_warnings, training_mask
from aisdati.detectors import SCORES, Detector, ScoreSettings, load_detectors
from aisdati.errors import UserError
from aisdati.geo import haversine_m
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.tracks.store import Track, load_tracks, read_track_table, select_cluster

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
    ]
)
"""scores.parquet, one row per test track, sorted by rank (1 = most abnormal). score_m: best-of-K
mean great-circle distance along the warping path (metres); score: score_m / max over the test
set; max_dev_*: the track point with the largest distance to its matched rollout point."""


@dataclass(frozen=True)
class DetectSettings:
    data_dir: Path
    models_dir: Path
    out_dir: Path
    models: tuple[str, ...] = ()
    """Model names (<models_dir>/<name>.json); empty: every model of `method` in the folder."""
    method: str = "dati"
    cluster: str = "other"
    """Test tracks: a cluster (up, down, other), a route (route-<n>, unrouted) or all."""
    track_ids: tuple[int, ...] = ()
    """Explicit test tracks (overrides the cluster and the start rule)."""
    score: str = "lane"
    rollouts: int = 10
    lane_rollouts: int = ScoreSettings().lane_rollouts
    lane_course_km: float = ScoreSettings().lane_course_km
    lane_traffic: bool = ScoreSettings().lane_traffic
    threshold: float = 0.75
    top_percent: float | None = None
    contamination: float | None = None
    near_km: float = 10.0
    seed: int = 0
    labels: Path | None = None
    """CSV of hand labels (track_id or mmsi + start, label 0/1) for precision/recall/F1/AUC."""

    @property
    def how(self) -> ScoreSettings:
        return ScoreSettings(
            score=self.score,
            rollouts=self.rollouts,
            lane_rollouts=self.lane_rollouts,
            lane_course_km=self.lane_course_km,
            lane_traffic=self.lane_traffic,
            near_km=self.near_km,
            seed=self.seed,
        )


@dataclass
class Detection:
    scores: pd.DataFrame
    tracks: list[Track]
    rollouts: list[np.ndarray]
    """What each track was compared with (best rollout, nearest training track or one-step
    predictions), in the order of `tracks`."""
    models: list[Detector]
    profiles: list[np.ndarray] = field(default_factory=list)
    """Each track's local deviation (m) at each of its points."""
    timings: dict[str, float] = field(default_factory=dict)
    settings: DetectSettings | None = None
    metrics: dict[str, Any] | None = None


SCORE_DEFINITIONS = {
    "rollout": "best of K free rollouts: great-circle DTW / warping-path length (m)",
    "step": "teacher-forced: mean of the largest 10% of best-of-K one-step prediction errors (m)",
    "lane": "mean of the largest 10% of each report's distance to the nearest point of the "
    "lane_rollouts free rollouts of twice the track's steps and, with lane_traffic, of one rollout "
    "from each training track's start (nearest: of the training tracks starting within "
    "near_km), sqrt(d^2 + (lane_course_km sin(dcourse / 2))^2) for great-circle "
    "distance d and course difference dcourse (m)",
    "both": "rollout / median training rollout score + step / median training step score",
    "nearest": "great-circle DTW / warping-path length (m) to the nearest training "
    "track starting within near_km",
}


EVIDENCE = {
    "rollout": "best rollout",
    "both": "best rollout",
    "lane": "best rollout",
    "step": "one-step predictions",
    "nearest": "nearest training track",
}


# ------------------------------------------------------------------------------------ models
def load_models(settings: DetectSettings) -> list[Detector]:
    models = load_detectors(settings.models_dir, settings.models)
    if not settings.models:
        models = [m for m in models if m.method == settings.method]
        if not models:
            raise UserError(
                f"no {settings.method} models in {settings.models_dir}: run "
                f"`aisdati train --method {settings.method} --cluster ...` first"
            )
    return models


# --------------------------------------------------------------------------------- test set
def select_test_tracks(
    settings: DetectSettings, models: Sequence[Detector]
) -> tuple[list[int], list[int]]:
    """Test track ids and, for each, the index of the model that judges it."""
    table = read_track_table(settings.data_dir)
    if settings.track_ids:
        missing = set(settings.track_ids) - set(table["track_id"])
        if missing:
            raise UserError(f"tracks not in {settings.data_dir}: {sorted(missing)[:5]}")
        table = table[table["track_id"].isin(settings.track_ids)]
    elif settings.cluster != "all":
        table = select_cluster(table, settings.cluster, settings.data_dir, needed=1)
    ids = table["track_id"].to_numpy()
    starts = table[["lon0", "lat0"]].to_numpy(np.float64) if "lon0" in table else None
    if starts is None:
        starts = np.array([t.positions[0] for t in load_tracks(settings.data_dir, ids)])
    # distance from each start to each model's nearest training start (km)
    near = np.full((len(ids), len(models)), np.inf)
    for m, model in enumerate(models):
        sp = model.start_points
        for lo in range(0, len(sp), 256):
            chunk = sp[lo : lo + 256]
            d = haversine_m(starts[:, None, 0], starts[:, None, 1], chunk[:, 0], chunk[:, 1])
            near[:, m] = np.minimum(near[:, m], d.min(axis=1) / 1000.0)
        if not settings.track_ids:
            trained = training_mask(model.card, table)  # by vessel and time where it can
            near[trained, m] = np.inf  # a model does not judge its own training tracks
    inside = np.zeros(len(ids), dtype=bool)
    for model in models:
        inside |= model.contains(starts)
    if not inside.any():
        lo, hi = models[0].bounds
        raise UserError(
            f"no test track starts inside the model's region (lon {lo[0]:.2f}..{hi[0]:.2f}, "
            f"lat {lo[1]:.2f}..{hi[1]:.2f}): is the model from another region?"
        )
    best = near.argmin(axis=1)
    dist = near[np.arange(len(ids)), best]
    keep = np.ones(len(ids), dtype=bool) if settings.track_ids else dist <= settings.near_km
    if not keep.any():
        raise UserError(
            f"no test tracks start within {settings.near_km:g} km of the training tracks' starts "
            "(training tracks are never test tracks); raise --near-km or pass --cluster all"
        )
    return [int(i) for i in ids[keep]], [int(b) for b in best[keep]]


def flag(scores: np.ndarray, threshold: float, top_percent: float | None) -> np.ndarray:
    if top_percent is not None:
        count = math.ceil(len(scores) * top_percent / 100.0)
        order = np.argsort(-scores, kind="stable")
        flagged = np.zeros(len(scores), dtype=bool)
        flagged[order[:count]] = True
        return flagged
    return scores > threshold


def check_settings(settings: DetectSettings) -> None:
    if not (0.0 < settings.threshold <= 1.0):
        raise UserError(f"--threshold must be in (0, 1], got {settings.threshold:g}")
    if settings.top_percent is not None and not (0.0 < settings.top_percent <= 100.0):
        raise UserError(f"--top-percent must be in (0, 100], got {settings.top_percent:g}")
    if settings.contamination is not None and not (0.0 < settings.contamination < 1.0):
        raise UserError(f"--contamination must be in (0, 1), got {settings.contamination:g}")
    if settings.top_percent is not None and settings.contamination is not None:
        raise UserError("give --top-percent or --contamination, not both")
    if settings.rollouts < 1 or settings.lane_rollouts < 1:
        raise UserError(
            f"--rollouts and --lane-rollouts must be at least 1, got {settings.rollouts} and "
            f"{settings.lane_rollouts}"
        )
    if not settings.near_km > 0:
        raise UserError(f"--near-km must be positive, got {settings.near_km:g}")
    if settings.score not in SCORES:
        raise UserError(f"--score must be one of {', '.join(SCORES)}, got {settings.score!r}")


def detect(settings: DetectSettings) -> Detection:
    """Score the test tracks; see the module docstring."""
    check_settings(settings)
    if settings.labels is not None:
        read_labels(settings.labels)  # fail on a bad file before the scoring
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    models = load_models(settings)
    ids, owner = select_test_tracks(settings, models)
    tracks = load_tracks(settings.data_dir, ids)
    timings["load_s"] = time.perf_counter() - t0
    n = len(tracks)
    raw = np.full(n, np.nan)
    threshold = np.full(n, np.nan)
    evidence: list[np.ndarray] = [np.empty((0, 2))] * n
    profiles: list[np.ndarray] = [np.empty(0)] * n
    t1 = time.perf_counter()
    cut: dict[int, float] = {}  # calibrated thresholds, before any scoring: fail fast
    if settings.contamination is not None:
        for m in sorted({int(o) for o in owner}):
            cut[m] = models[m].threshold(settings.how, settings.contamination)
    for m, model in enumerate(models):
        idx = [i for i in range(n) if owner[i] == m]
        if not idx:
            continue
        scored = model.score([tracks[i] for i in idx], settings.how)
        if settings.contamination is not None:
            threshold[idx] = cut[m]
        for j, i in enumerate(idx):
            raw[i] = scored.score_m[j]
            evidence[i] = scored.evidence[j]
            profiles[i] = scored.profiles[j]
    timings["score_s"] = time.perf_counter() - t1
    top = float(np.max(raw)) if n else 1.0
    norm = raw / top if top > 0 else np.zeros(n)
    if settings.contamination is not None:
        flagged = raw > threshold
    else:
        flagged = flag(norm, settings.threshold, settings.top_percent)
    order = np.argsort(-norm, kind="stable")
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(1, n + 1)
    peak = [int(np.argmax(p)) for p in profiles]
    scores = pd.DataFrame(
        {
            "track_id": [t.track_id for t in tracks],
            "mmsi": [t.mmsi for t in tracks],
            "model": [models[o].name for o in owner],
            "n_points": [len(t.positions) for t in tracks],
            "score_m": raw,
            "score": norm,
            "flagged": flagged,
            "rank": rank,
            "max_dev_m": [float(p[k]) for p, k in zip(profiles, peak, strict=True)],
            "max_dev_lon": [t.positions[k, 0] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_lat": [t.positions[k, 1] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_index": peak,
        }
    )
    timings["total_s"] = time.perf_counter() - t0
    result = Detection(scores, tracks, evidence, models, profiles, timings, settings)
    if settings.labels is not None:
        result.metrics = evaluate_labels(result, settings.labels)
    return result


# ----------------------------------------------------------------------------------- outputs
def _line(coords: np.ndarray) -> dict[str, Any]:
    return {"type": "LineString", "coordinates": np.round(coords, 6).tolist()}


def _evidence_kind(result: Detection) -> str:
    s = result.settings
    return EVIDENCE.get(s.method if s and s.method == "nearest" else s.score if s else "", "")


def anomalies_geojson(result: Detection) -> dict[str, Any]:
    """Flagged tracks (kind=track), what each was compared with (kind=evidence: its best
    rollout, the nearest training track or its one-step predictions) and the points of largest
    deviation (kind=max_deviation), as one FeatureCollection in lon/lat (WGS84)."""
    features = []
    what = _evidence_kind(result)
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


def write_outputs(result: Detection, out: Path) -> list[Path]:
    from aisdati.plots import html_detection_map, plot_detection_map

    out.mkdir(parents=True, exist_ok=True)
    files = []
    table = pa.Table.from_pandas(
        result.scores.sort_values("rank").reset_index(drop=True),
        schema=SCORES_SCHEMA,
        preserve_index=False,
    )
    path = out / "scores.parquet"
    atomic_write_bytes(path, _parquet_bytes(table))
    files.append(path)
    path = out / "profiles.parquet"
    atomic_write_bytes(path, _parquet_bytes(profiles_table(result)))
    files.append(path)
    path = out / "anomalies.geojson"
    atomic_write_bytes(path, json.dumps(anomalies_geojson(result)).encode())
    files.append(path)
    path = out / "map.png"
    flagged = result.scores["flagged"].to_numpy()
    stretches = [deviation_stretch(p) for p in result.profiles]
    plot_detection_map(
        [t.positions for t in result.tracks],
        result.rollouts,
        flagged,
        result.scores[["max_dev_lon", "max_dev_lat"]].to_numpy(),
        [m.bounds for m in result.models],
        path,
        title=_map_title(result),
        evidence_label=_evidence_kind(result),
    )
    files.append(path)
    path = out / "map.html"
    html_detection_map(
        [t.positions for t in result.tracks],
        result.rollouts,
        [_track_props(r) for r in result.scores.itertuples()],
        flagged,
        [m.bounds for m in result.models],
        path,
        stretches=[
            (f"track {t.track_id}", t.positions[a:b])
            for t, (a, b), f in zip(result.tracks, stretches, flagged, strict=True)
            if f
        ],
        title=_map_title(result),
    )
    files.append(path)
    files += evidence_figures(result, out / "evidence", stretches)
    if result.metrics is not None:
        path = out / "metrics.json"
        atomic_write_bytes(path, json.dumps(result.metrics, indent=2).encode())
        files.append(path)
    path = out / "report.json"
    atomic_write_bytes(path, json.dumps(report_dict(result), indent=2, default=str).encode())
    files.append(path)
    return files


EVIDENCE_FIGURES = 20
"""At most this many flagged tracks (the highest ranked) get an evidence figure."""


def deviation_stretch(profile: np.ndarray) -> tuple[int, int]:
    """The contiguous stretch around a profile's peak where it stays above half the peak: where
    the track strays most, as an index range [start, end)."""
    k = int(np.argmax(profile))
    above = profile >= profile[k] / 2
    a = k
    while a > 0 and above[a - 1]:
        a -= 1
    b = k + 1
    while b < len(profile) and above[b]:
        b += 1
    return a, b


def evidence_figures(
    result: Detection, folder: Path, stretches: list[tuple[int, int]]
) -> list[Path]:
    """evidence/track-<id>.png for the highest-ranked flagged tracks: the track, what it was
    compared with, the stretch of largest deviation and the deviation profile along it."""
    from aisdati.plots import plot_track_evidence

    s = result.settings
    label = "one-step prediction error (m)" if s and s.score == "step" else "deviation (m)"
    if s and s.score == "lane":
        label = "distance to the lane (m)"
    elif s and s.method == "nearest":
        label = "distance to the nearest training track (m)"
    rows = result.scores[result.scores["flagged"]].sort_values("rank").head(EVIDENCE_FIGURES)
    index = {t.track_id: i for i, t in enumerate(result.tracks)}
    files = []
    if len(rows):
        folder.mkdir(parents=True, exist_ok=True)
    for row in rows.itertuples():
        i = index[int(row.track_id)]
        track = result.tracks[i]
        hours = np.r_[0.0, np.cumsum(track.dts)]
        path = folder / f"track-{int(row.track_id)}.png"
        plot_track_evidence(
            track.positions,
            result.rollouts[i],
            result.profiles[i],
            stretches[i],
            f"rank {int(row.rank)}: track {int(row.track_id)} (MMSI {int(row.mmsi)}), "
            f"score {row.score_m / 1000:.2f} km, model {row.model}",
            path,
            hours=hours,
            profile_label=label,
            evidence_label=_evidence_kind(result),
        )
        files.append(path)
    return files


def _parquet_bytes(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


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


def _track_props(row: Any) -> dict[str, Any]:
    return {
        "track_id": int(row.track_id),
        "mmsi": int(row.mmsi),
        "rank": int(row.rank),
        "score": round(float(row.score), 4),
        "score_m": round(float(row.score_m), 1),
        "max_dev_m": round(float(row.max_dev_m), 1),
        "max_dev_lon": float(row.max_dev_lon),
        "max_dev_lat": float(row.max_dev_lat),
    }


def _map_title(result: Detection) -> str:
    s = result.settings
    n, f = len(result.scores), int(result.scores["flagged"].sum())
    rule = f"top {s.top_percent:g}%" if s and s.top_percent else f"score > {s.threshold:g}"
    if s and s.contamination is not None:
        rule = f"calibrated, contamination {s.contamination:g}"
    what = f"{s.method} ({s.score})" if s else "DATI"
    return f"{what} anomalies: {f} of {n} test tracks flagged ({rule})"


def report_dict(result: Detection) -> dict[str, Any]:
    s = result.settings
    sc = result.scores
    return {
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in s.__dict__.items()}
        if s
        else {},
        "models": [m.name for m in result.models],
        "warnings": [w for m in result.models for w in card_warnings(m.card, m.name)],
        "test_tracks": len(sc),
        "flagged": int(sc["flagged"].sum()),
        "max_score_m": float(sc["score_m"].max()) if len(sc) else None,
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
        "metrics": result.metrics,
        "score_definition": SCORE_DEFINITIONS[
            "nearest" if s.method == "nearest" and s.score != "lane" else s.score
        ]
        if s
        else None,
    }


# ------------------------------------------------------------------------------------ labels
def read_labels(path: Path) -> pd.DataFrame:
    """A CSV with `label` (0/1) and either `track_id` or `mmsi` + `start` (UTC time of the
    track's first report; matched within 60 s). Every value is checked here, before any work, and
    the first bad one is named with its row: ids must be integers (track ids >= 0 and within
    int64, MMSIs positive), starts times, labels 0 or 1, and one key may not get two labels."""
    if not path.is_file():
        raise UserError(f"labels file not found: {path}")
    try:
        raw = pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8")
    except (ValueError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read labels {path}: {str(exc).splitlines()[0]}") from None
    raw.columns = [str(c).strip().lower() for c in raw.columns]
    if "label" not in raw:
        raise UserError(f"{path}: no 'label' column (expected track_id,label or mmsi,start,label)")
    if "track_id" not in raw and not {"mmsi", "start"} <= set(raw):
        raise UserError(f"{path}: needs a 'track_id' column, or 'mmsi' and 'start' columns")
    if raw.empty:
        raise UserError(f"{path}: the file holds no labels")
    labels = pd.DataFrame(index=raw.index)
    keys = ["track_id"] if "track_id" in raw else ["mmsi", "start"]
    if "track_id" in raw:
        labels["track_id"] = _label_ints(raw["track_id"], "track_id", 0, 2**63 - 1, path)
    else:
        labels["mmsi"] = _label_ints(raw["mmsi"], "mmsi", 1, 2**53, path)
        start = pd.to_datetime(raw["start"].str.strip(), utc=True, errors="coerce", format="mixed")
        if start.isna().any():
            row = int(np.flatnonzero(start.isna().to_numpy())[0])
            raise UserError(
                f"{path}: row {row + 1}: start must be a time (ISO 8601, UTC), "
                f"got {_shown(raw['start'].iloc[row])}"
            )
        labels["start"] = start
    text = raw["label"].str.strip()
    bad = ~text.isin(["0", "1", "0.0", "1.0"])
    if bad.any():
        row = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(
            f"{path}: row {row + 1}: label must be 0 or 1, got {_shown(raw['label'].iloc[row])}"
        )
    labels["label"] = text.str[0].astype(int)
    conflict = labels.groupby(keys)["label"].nunique() > 1
    if conflict.any():
        key = conflict.index[np.flatnonzero(conflict.to_numpy())[0]]
        raise UserError(f"{path}: {'/'.join(keys)} {key} has both labels 0 and 1")
    return labels


def _shown(value: Any) -> str:
    text = repr(str(value))
    return text if len(text) <= 40 else text[:37] + "..."


def _label_ints(values: pd.Series, column: str, low: int, high: int, path: Path) -> pd.Series:
    """A column of integer ids (written as 12 or 12.0) within [low, high], or a `UserError`
    naming the first row that is not one."""
    out = np.zeros(len(values), dtype=np.int64)
    for row, value in enumerate(values.to_numpy()):
        match = re.fullmatch(r"\s*\+?(\d{1,30})(?:\.0*)?\s*", value)
        number = int(match[1]) if match else None
        if number is None or not low <= number <= high:
            raise UserError(
                f"{path}: row {row + 1}: {column} must be an integer in [{low}, {high}], "
                f"got {_shown(value)}"
            )
        out[row] = number
    return pd.Series(out, index=values.index)


def match_labels(scores: pd.DataFrame, tracks: Sequence[Track], labels: pd.DataFrame) -> np.ndarray:
    """The label of every scored track, -1 where it has none."""
    out = np.full(len(scores), -1)
    if "track_id" in labels:
        lab = dict(zip(labels["track_id"].astype(int), labels["label"], strict=True))
        out = np.array([lab.get(int(t), -1) for t in scores["track_id"]])
    else:
        starts = pd.to_datetime(labels["start"], utc=True, errors="coerce")
        by_mmsi: dict[int, list[tuple[pd.Timestamp, int]]] = {}
        for m, s, v in zip(labels["mmsi"].astype(int), starts, labels["label"], strict=True):
            if pd.notna(s):
                by_mmsi.setdefault(m, []).append((s, int(v)))
        start_of = {t.track_id: pd.Timestamp(t.start) for t in tracks}
        for i, (tid, mmsi) in enumerate(zip(scores["track_id"], scores["mmsi"], strict=True)):
            st = start_of[int(tid)]
            st = st.tz_localize("UTC") if st.tzinfo is None else st
            for s, v in by_mmsi.get(int(mmsi), []):
                if abs((s - st).total_seconds()) <= 60:
                    out[i] = v
    if not (out >= 0).any():
        raise UserError("the labels match no test track (check track_id, or mmsi and start)")
    return out


def roc_auc(y: np.ndarray, s: np.ndarray) -> float | None:
    """Area under the ROC curve (Mann-Whitney U with average ranks for ties)."""
    from scipy.stats import rankdata

    pos, neg = int(y.sum()), int(len(y) - y.sum())
    if pos == 0 or neg == 0:
        return None
    ranks = rankdata(s)
    return float((ranks[y == 1].sum() - pos * (pos + 1) / 2) / (pos * neg))


def label_metrics(y: np.ndarray, flagged: np.ndarray, score: np.ndarray) -> dict[str, Any]:
    """Precision and recall of the anomaly class, weighted F1 (the paper's metric: per-class F1
    weighted by class support) and ROC AUC of the normalised score."""
    y, p = np.asarray(y, int), np.asarray(flagged, int)

    def prf(c: int) -> tuple[float, float, float]:
        tp = int(((p == c) & (y == c)).sum())
        prec = tp / max(int((p == c).sum()), 1)
        rec = tp / max(int((y == c).sum()), 1)
        f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
        return prec, rec, f1

    p1, r1, _ = prf(1)
    support = np.array([(y == 0).sum(), (y == 1).sum()], dtype=float)
    f1s = np.array([prf(0)[2], prf(1)[2]])
    return {
        "labelled_tracks": len(y),
        "anomalies_labelled": int(y.sum()),
        "flagged": int(p.sum()),
        "precision": p1,
        "recall": r1,
        "f1_weighted": float((support * f1s).sum() / support.sum()),
        "roc_auc": roc_auc(y, score),
    }


def evaluate_labels(result: Detection, path: Path) -> dict[str, Any]:
    labels = read_labels(path)
    matched = match_labels(result.scores, result.tracks, labels)
    keep = matched >= 0
    metrics = label_metrics(
        matched[keep], result.scores["flagged"].to_numpy()[keep], result.scores["score"][keep]
    )
    metrics["labels_file"] = str(path)
    metrics["labels_unmatched"] = int(len(labels) - keep.sum())
    return metrics
