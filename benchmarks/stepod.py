"""`stepod` (`aisdati.detectors.od.stepod_scores`: `stepspread` joined with the origin-destination
term by rarity) on stored forward grids, without scoring a track again: each cell's
`scores.parquet` holds every track's `stepspread` and `od`, and the cross-fitted BC card that
judged it holds the training tracks' own, so `stepod` and its threshold follow from them alone.

For each grid (folders written by `benchmarks/detection_quality.py --forward --detectors bc`):
ROC AUC (mean over the cells), and the share of normal tracks and of anomalies flagged at
`--contamination 0.05`, pooled over the cells' tracks (as `benchmarks/pooled_grid.py`), the ashore
rule as the cells were run. `stepspread` is recomputed the same way beside it and checked against
the cell's own evaluation.json, so the two rows differ only by the OD term.

Run: python benchmarks/stepod.py runs/grid13/kitimat/forward-s1-at-sea [more grids] [--pool]
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from pooled_grid import grouped_from_args, pooled  # (this folder: run as a script)

from aisdati.detection.labels import label_metrics
from aisdati.detectors.od import stepod_scores
from aisdati.tracks.ashore import AshoreCheck

CONTAMINATION = 0.05


def card_of(cell: Path) -> dict:
    """The card of the BC model that judged a cell: trained in the cell of its training's own
    seed, in this grid or the one its models came from (`--models-from`)."""
    t = cell.name.split("-")[0].removeprefix("train")
    cards = sorted(cell.parent.parent.glob(f"*/train{t}-seed{t}/models/all-bc.json"))
    if not cards:
        raise SystemExit(f"no BC card for {cell}")
    return json.loads(cards[0].read_text())


def cell_metrics(cell: Path) -> dict[str, dict]:
    """`label_metrics` of stepspread and stepod in one cell, and its evaluation.json row."""
    scores = pd.read_parquet(cell / "scores.parquet")
    scores = scores[scores["detector"] == "bc"]
    wide = scores.pivot(index="track_id", columns="score", values="value")
    meta = scores.drop_duplicates("track_id").set_index("track_id").loc[wide.index]
    cal = card_of(cell)["calibration"]
    rule = AshoreCheck()
    ashore = rule.flags(meta["ashore_reports"].to_numpy())
    values = {
        "stepspread": (wide["stepspread"].to_numpy(), np.asarray(cal["stepspread"])),
        "stepod": (
            stepod_scores(wide["stepspread"], wide["od"], cal["stepspread"], cal["od"]),
            stepod_scores(cal["stepspread"], cal["od"], cal["stepspread"], cal["od"]),
        ),
    }
    out = {}
    for name, (value, own) in values.items():
        flagged = (value > np.quantile(own, 1.0 - CONTAMINATION)) | ashore
        ranked = rule.ranked(value, meta["ashore_reports"], meta["n_points"])
        out[name] = label_metrics(meta["label"].to_numpy(), flagged, ranked)
    out["logged"] = logged_row(cell, "stepspread")
    return out


def logged_row(cell: Path, score: str) -> dict:
    """The cell's own evaluation.json row of BC's `score` over all kinds, to check against."""
    doc = json.loads((cell / "evaluation.json").read_text())
    return next(
        r for r in doc["results"] if (r["detector"], r["score"], r["kind"]) == ("bc", score, "all")
    )


def as_row(metrics: dict) -> dict:
    """`label_metrics` as a row of evaluation.json, which `pooled_grid.pooled` pools."""
    altered = metrics["anomalies_labelled"]
    return {**metrics, "normal": metrics["labelled_tracks"] - altered, "anomalies": altered}


def main() -> None:
    grids, groups = grouped_from_args(__doc__, cell_metrics)
    for grid, cells in groups[:grids]:
        for c in cells:
            logged, mine = c["logged"], c["stepspread"]
            if not np.isclose(logged["roc_auc"], mine["roc_auc"]) or not np.isclose(
                logged["recall"], mine["recall"]
            ):
                raise SystemExit(f"{grid}: stepspread recomputed differs from evaluation.json")
    print("| grid | score | cells | ROC AUC | normal flagged | anomalies flagged |")
    print("|---|---|---|---|---|---|")
    for grid, cells in groups:
        for name in ("stepspread", "stepod"):
            auc, fa, recall = pooled([as_row(c[name]) for c in cells])
            print(f"| {grid} | {name} | {len(cells)} | {auc:.3f} | {fa:.3f} | {recall:.3f} |")


if __name__ == "__main__":
    main()
