"""Does a threshold that allows for the reporting interval hold forward in time? (not a test)

`--score steprate` (the one-step errors over their report intervals) ranks the later tracks
best of every score, but its threshold, the 95th percentile of the training tracks' own scores,
does not hold forward: it flags no anomaly at sea on Kitimat and 12 % of Virginia Beach's normal
tracks, while the areas' reporting intervals changed between the periods (Kitimat's median
240 -> 300 s, Virginia Beach's 79 -> 70 s); docs/results/forward.md. This measures whether an
allowance for each track's interval mends it (it does not), on the cells of
`benchmarks/detection_quality.py --forward` (their DATI models were trained with `steprate`):
each track's score times (its median report interval / the training tracks' median of it)^g, g
the least-squares slope of log(score) on log(median interval) over the training tracks'
cross-fitted calibration scores, and the threshold the 95th percentile of the training tracks'
adjusted scores. For `steprate` and, beside it, the metre `step` score. Tracks the ashore rule
flags are flagged and rank first, as in the evaluation.

Run: python benchmarks/interval_calibration.py runs/grid2/*/forward-* [--contamination 0.05]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import load_tracks

RULE = AshoreCheck()
SCORES = ("step", "steprate")


def median_intervals(cell: Path, ids: list[int]) -> np.ndarray:
    """Each track's median report interval, seconds, in the order of `ids`."""
    return np.array([np.median(t.dts) * 3600.0 for t in load_tracks(cell / "data", ids)])


def adjusted(cal: np.ndarray, cal_dt: np.ndarray, values: np.ndarray, dt: np.ndarray):
    """The training and later scores times (interval / the training median)^g, and g."""
    g = float(np.polyfit(np.log(cal_dt), np.log(cal), 1)[0])
    ref = float(np.median(cal_dt))
    return cal * (cal_dt / ref) ** g, values * (dt / ref) ** g, g


def cell_rows(cell: Path, contamination: float) -> list[dict]:
    """ROC AUC, false alarms and recall of each score, as evaluated and interval-adjusted."""
    doc = json.loads((cell / "evaluation.json").read_text())
    train_ids = doc["split"]["training_track_ids"]
    models = Path(doc["settings"]["models_dir"] or cell / "models")  # a training's cells share it
    card = json.loads((models / "all.json").read_text())
    labels = pd.read_csv(cell / "data" / "labels.csv")
    later_dt = median_intervals(cell, labels["track_id"].tolist())
    train_dt = median_intervals(cell, train_ids)
    scores = pd.read_parquet(cell / "scores.parquet")
    rows = []
    for score in SCORES:
        cal = np.asarray(card["calibration"][score], np.float64)
        got = scores[(scores["detector"] == "dati") & (scores["score"] == score)]
        got = got.set_index("track_id").loc[labels["track_id"]]
        values, ashore = got["value"].to_numpy(), got["ashore_reports"].to_numpy()
        y = labels["label"].to_numpy()
        cal_adj, values_adj, g = adjusted(cal, train_dt, values, later_dt)
        for name, c, v in ((score, cal, values), (f"{score} adjusted", cal_adj, values_adj)):
            flagged = (v > np.quantile(c, 1.0 - contamination)) | RULE.flags(ashore)
            ranked = RULE.ranked(v, ashore, got["n_points"].to_numpy())
            rows.append(
                {
                    "score": name,
                    "auc": roc_auc_score(y, ranked),
                    "fa": flagged[y == 0].mean(),
                    "recall": flagged[y == 1].mean(),
                    "g": g if name.endswith("adjusted") else np.nan,
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="folders of evaluate cells")
    ap.add_argument("--contamination", type=float, default=0.05)
    args = ap.parse_args()
    print(f"Interval-adjusted thresholds at --contamination {args.contamination} (mean over cells)")
    print("| grid | score | ROC AUC | FA | recall | g (slope) |")
    print("|---|---|---|---|---|---|")
    for grid in args.grids:
        cells = sorted(p.parent for p in grid.glob("*/evaluation.json"))
        frame = pd.DataFrame([r for c in cells for r in cell_rows(c, args.contamination)])
        for name, g in frame.groupby("score", sort=False):
            print(
                f"| {grid.parent.name}/{grid.name} | {name} | {g['auc'].mean():.3f} | "
                f"{g['fa'].mean():.3f} | {g['recall'].mean():.2f} | {g['g'].mean():.2f} |"
            )


if __name__ == "__main__":
    main()
