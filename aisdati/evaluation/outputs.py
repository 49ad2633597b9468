"""What `aisdati evaluate` writes: evaluation.json, scores.parquet, roc_pr.png, examples.png,
and the table it prints; with `--cluster routes`, each route's in <out>/<route>/ and the pooled
evaluation.json, scores.parquet and roc_pr.png in <out>."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from rich import box
from rich.table import Table

from aisdati.evaluation.run import Evaluation, RoutesEvaluation
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.tracks.store import load_tracks


def _settings(settings: Any) -> dict[str, Any]:
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(settings).items()}


def lane_fidelity(ev: Evaluation) -> dict[str, float]:
    """Per policy detector: the median over held-out normal tracks of the best rollout's mean
    distance along the warping path (m); for `nearest`, the same of the nearest training track."""
    out = {}
    rows = ev.table[(ev.table["kind"] == "all") & ev.table["score"].isin(["rollout", "nearest"])]
    for r in rows.itertuples():
        out[r.detector] = float(r.median_normal_m)
    return out


def report(ev: Evaluation) -> dict[str, Any]:
    table = ev.table.replace({np.nan: None})
    return {
        "settings": _settings(ev.settings),
        "split": {
            "training_tracks": len(ev.split.train_ids),
            "heldout_tracks": len(ev.split.heldout_ids),
            "injected": int(ev.split.labels["label"].sum()),
            "training_track_ids": ev.split.train_ids,
        },
        "lane_fidelity_m": lane_fidelity(ev),
        "timings_s": {k: {n: round(v, 2) for n, v in t.items()} for k, t in ev.timings.items()},
        "results": table.to_dict(orient="records"),
    }


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
            "timings_s": {
                k: {n: round(v, 2) for n, v in t.items()} for k, t in ev.timings.items()
            },
        }
        for ev in rev.routes
    }
    return {
        "settings": _settings(rev.settings),
        "pooled_by": "score / the route model's calibrated threshold",
        "routes": per_route,
        "skipped": rev.skipped,
        "results": rev.table.replace({np.nan: None}).to_dict(orient="records"),
    }


def write(ev: Evaluation, out: Path) -> list[Path]:
    from aisdati.plots import plot_injected_examples

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
    """Each route's outputs in <out>/<route>/, the pooled ones in <out>."""
    for ev in rev.routes:
        write(ev, ev.settings.out_dir)
    return [
        _json(routes_report(rev), out / "evaluation.json"),
        _parquet(rev.scores, out / "scores.parquet"),
        _curves(rev.scores, "ratio", out / "roc_pr.png"),
    ]


def _json(doc: dict[str, Any], path: Path) -> Path:
    atomic_write_bytes(path, json.dumps(doc, indent=2, default=str).encode())
    return path


def _parquet(frame: pd.DataFrame, path: Path) -> Path:
    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), sink)
    atomic_write_bytes(path, sink.getvalue().to_pybytes())
    return path


def _curves(scores: pd.DataFrame, column: str, path: Path) -> Path:
    from aisdati.plots import plot_roc_pr

    curves = {}
    for (det, score), g in scores.groupby(["detector", "score"], sort=False):
        curves[det if det == score else f"{det} ({score})"] = (
            g["label"].to_numpy(),
            g[column].to_numpy(),
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


def distance(value: float | None, score: str, ratio: bool = False) -> str:
    if value is None or value != value:
        return "-"
    return f"{value:.2f}" if ratio or score == "both" else f"{value / 1000:.2f}"


def results_table(ev: Evaluation, width: int = 120) -> Table:
    """The table; on a terminal narrower than 100 columns, without AP, P and R (they stay in
    evaluation.json)."""
    title = (
        f"Detection of injected anomalies: cluster {ev.settings.cluster!r}, "
        f"{len(ev.split.train_ids)} training / {len(ev.split.heldout_ids)} held-out tracks "
        f"({int(ev.split.labels['label'].sum())} altered)"
    )
    caption = (
        "AUC (ROC) and AP (average precision) rank altered against normal held-out tracks; "
        "P/R/F1 at each detector's calibrated threshold; normal/altered: median scores in km "
        "('both' is unitless)"
    )
    return _table(ev.table, title, caption, width, ratio=False)


def pooled_table(rev: RoutesEvaluation, width: int = 120) -> Table:
    """The pooled table of `--cluster routes` (scores in multiples of each route's threshold)."""
    held = sum(len(ev.split.heldout_ids) for ev in rev.routes)
    altered = sum(int(ev.split.labels["label"].sum()) for ev in rev.routes)
    names = ", ".join(ev.settings.cluster for ev in rev.routes)
    title = (
        f"Detection of injected anomalies over {len(rev.routes)} routes ({names}): "
        f"{held} held-out tracks ({altered} altered), each judged by its route's model"
    )
    caption = (
        "Pooled: each score divided by its route model's calibrated threshold, then ranked "
        "together; normal/altered: median multiples of the threshold (above 1 is flagged)"
    )
    if rev.skipped:
        caption += f"; skipped (too few tracks to split): {', '.join(rev.skipped)}"
    return _table(rev.table, title, caption, width, ratio=True)


def _table(frame: pd.DataFrame, title: str, caption: str, width: int, ratio: bool) -> Table:
    t = Table(title=title, box=box.SIMPLE_HEAD)
    cols = ["detector", "score", "kind", "n", "AUC", "AP", "P", "R", "F1", "normal", "altered"]
    narrow = width < 100
    if narrow:
        cols = [c for c in cols if c not in ("AP", "P", "R")]
    for c in cols:
        left = c in ("detector", "score", "kind")
        t.add_column(c, justify="left" if left else "right", no_wrap=True)

    def fmt(v: float | None, digits: int = 3) -> str:
        return "-" if v is None or v != v else f"{v:.{digits}f}"

    last = None
    for r in frame.itertuples():
        if last is not None and (r.detector, r.score) != last:
            t.add_section()
        last = (r.detector, r.score)
        auc = fmt(r.roc_auc)
        if r.roc_auc is not None and r.roc_auc == r.roc_auc:
            style = "green" if r.roc_auc >= 0.9 else "yellow" if r.roc_auc >= 0.7 else "red"
            auc = f"[{style}]{auc}[/]"
        cells = {
            "detector": r.detector,
            "score": "dtw" if r.score == "nearest" else r.score,
            "kind": "d+j+l" if narrow and "+" in r.kind else r.kind,
            "n": str(r.anomalies),
            "AUC": auc,
            "AP": fmt(r.average_precision),
            "P": fmt(r.precision, 2),
            "R": fmt(r.recall, 2),
            "F1": fmt(r.f1, 2),
            "normal": distance(r.median_normal_m, r.score, ratio),
            "altered": distance(r.median_anomalous_m, r.score, ratio),
        }
        t.add_row(*(cells[c] for c in cols))
    t.caption = caption
    return t
