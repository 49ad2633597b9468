"""What `aisdati evaluate` writes: evaluation.json, scores.parquet, roc_pr.png, examples.png;
with `--cluster routes`, each route's in <out>/<route>/ and the pooled evaluation.json,
scores.parquet and roc_pr.png in <out>. They are written into the command's staging folder and
land as one set (`aisdati.outdir.OutputSet`); the data and models they describe are written in
place while the evaluation runs. (The table it prints: `aisdati.commands.tables`.)"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.evaluation.metrics import RIGHT_EVENTS
from aisdati.evaluation.run import Evaluation, RoutesEvaluation
from aisdati.outdir import atomic_write_bytes, parquet_bytes
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import load_tracks


def _settings(settings: Any) -> dict[str, Any]:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(settings).items()}


def lane_fidelity(ev: Evaluation) -> dict[str, float]:
    """Per policy detector: the median over held-out normal tracks of the best rollout's mean
    distance along the warping path (m); for `nearest`, the same of the nearest training track."""
    out = {}
    rows = ev.table[(ev.table["kind"] == "all") & ev.table["score"].isin(["rollout", "nearest"])]
    for r in rows.itertuples():
        out[r.detector] = float(r.median_normal)
    return out


def report(ev: Evaluation) -> dict[str, Any]:
    table = ev.table.replace({np.nan: None})
    return {
        "settings": _settings(ev.settings),
        "split": {
            "training_tracks": len(ev.split.train_ids),
            "heldout_tracks": len(ev.split.heldout_ids),
            "injected": int(ev.split.labels["label"].sum()),
            "not_at_sea": ev.split.not_at_sea,
            "training_track_ids": ev.split.train_ids,
        },
        "lane_fidelity_m": lane_fidelity(ev),
        "ashore": ashore_summary(ev.scores),
        "timings_s": {k: {n: round(v, 2) for n, v in t.items()} for k, t in ev.timings.items()},
        "results": table.to_dict(orient="records"),
        "events": event_rows(ev.event_table),
        "alerts": ev.alerts,
        "fleet": ev.fleet,
    }


def event_rows(table: pd.DataFrame) -> dict[str, Any]:
    """evaluation.json's events: which event kinds name each injected kind rightly, and the
    event metrics' rows (`aisdati.evaluation.metrics.event_metrics`; `*_ci`: 95 % bootstrap
    intervals)."""
    return {
        "right_events": {k: list(v) for k, v in RIGHT_EVENTS.items()},
        "results": table.replace({np.nan: None}).to_dict(orient="records"),
    }


def ashore_summary(scores: pd.DataFrame) -> dict[str, int]:
    """Held-out tracks the ashore rule flags (`aisdati.tracks.ashore`), normal and altered:
    the normal ones are false alarms of every detector alike."""
    tracks = scores.drop_duplicates("track_id")
    flagged = AshoreCheck().flags(tracks["ashore_reports"].to_numpy())
    altered = tracks["label"].to_numpy() == 1
    return {"normal": int((flagged & ~altered).sum()), "altered": int((flagged & altered).sum())}


def routes_report(rev: RoutesEvaluation) -> dict[str, Any]:
    """The pooled evaluation.json of `--cluster routes`: each route's split and headline, the
    routes skipped and why, and the pooled table (scores as multiples of each route's
    threshold)."""
    per_route = {
        ev.settings.cluster: {
            "training_tracks": len(ev.split.train_ids),
            "heldout_tracks": len(ev.split.heldout_ids),
            "injected": int(ev.split.labels["label"].sum()),
            "lane_fidelity_m": lane_fidelity(ev),
            "timings_s": {k: {n: round(v, 2) for n, v in t.items()} for k, t in ev.timings.items()},
        }
        for ev in rev.routes
    }
    return {
        "settings": _settings(rev.settings),
        "pooled_by": "score / the route model's calibrated threshold",
        "routes": per_route,
        "skipped": rev.skipped,
        "results": rev.table.replace({np.nan: None}).to_dict(orient="records"),
        "events": event_rows(rev.event_table),
        "fleet": rev.fleet,
    }


RESULTS = ("evaluation.json", "scores.parquet", "roc_pr.png", "examples.png")
"""The results evaluate writes into --out (and, with `--cluster routes`, into each route's
folder): a run replaces them as one set."""
REPORT = "evaluation.json"
"""The report of the set, written last."""


def write(ev: Evaluation, out: Path) -> list[Path]:
    """One evaluation's results in `out`."""
    from aisdati.evaluation.figures import plot_injected_examples

    files = [
        _json(report(ev), out / "evaluation.json"),
        _parquet(ev.scores, out / "scores.parquet"),
        _curves(ev.scores, "value", out / "roc_pr.png"),
    ]
    path = out / "examples.png"
    plot_injected_examples(_examples(ev), path)
    files.append(path)
    return files


def write_routes(rev: RoutesEvaluation, out: Path) -> list[Path]:
    """Each route's results in <out>/<route>/, the pooled ones in <out>; returns the pooled."""
    for ev in rev.routes:
        write(ev, out / ev.settings.out_dir.relative_to(rev.settings.out_dir))
    return [
        _json(routes_report(rev), out / "evaluation.json"),
        _parquet(rev.scores, out / "scores.parquet"),
        _curves(rev.scores, "ratio", out / "roc_pr.png"),
    ]


def _json(doc: dict[str, Any], path: Path) -> Path:
    atomic_write_bytes(path, json.dumps(doc, indent=2, default=str).encode())
    return path


def _parquet(frame: pd.DataFrame, path: Path) -> Path:
    atomic_write_bytes(path, parquet_bytes(pa.Table.from_pandas(frame, preserve_index=False)))
    return path


def _curves(scores: pd.DataFrame, column: str, path: Path) -> Path:
    from aisdati.evaluation.figures import plot_roc_pr

    curves = {}
    check = AshoreCheck()
    for (det, score), g in scores.groupby(["detector", "score"], sort=False):
        curves[det if det == score else f"{det} ({score})"] = (
            g["label"].to_numpy(),
            check.ranked(g[column].to_numpy(), g["ashore_reports"], g["n_points"]),
        )
    plot_roc_pr(curves, path)
    return path


def _examples(ev: Evaluation) -> list[tuple]:
    """The top-scored altered track of each kind under the first detector's lane score (the
    default of `aisdati detect`)."""
    det = ev.settings.detectors[0]
    score = "lane"
    s = ev.scores[(ev.scores["detector"] == det) & (ev.scores["score"] == score)]
    data = ev.settings.out_dir / "data"
    panels = []
    order = {tid: i for i, tid in enumerate(ev.split.heldout_ids)}
    for kind, g in s[s["label"] == 1].groupby("kind", sort=True):
        top = g.sort_values("value", ascending=False).iloc[0]
        track, source = load_tracks(data, [int(top.track_id)])[0], None
        src_id = int(top.source_track_id)
        try:
            source = load_tracks(ev.settings.data_dir, [src_id])[0].positions
        except Exception:  # the source data moved away: draw the altered track alone
            source = track.positions[:0]
        evidence = ev.evidence[(det, score)][order[int(top.track_id)]]
        title = f"{kind}: track {int(top.track_id)}, {det} score {top.value / 1000:.2f} km"
        panels.append((title, source, track.positions, (int(top.start), int(top.end)), evidence))
    return panels
