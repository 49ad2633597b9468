"""A threshold matched to the judged period, on stored forward grids (a measurement, not a test).

The card's threshold is the (1 - C) quantile of the training tracks' own cross-fitted scores. A
later period's normal tracks can score lower or higher as a whole: on NY Harbor the default
flags 2-3 % of the later normal tracks at C = 0.05 and misses anomalies that rank above every
one of them. The `period` threshold scales the card's by the judged period's own level:

    threshold x median(the period's scores) / median(the training tracks' calibration scores)

the median because fewer than half of a period's tracks are abnormal, so it follows a drift of
the whole period and not the anomalies' values; with fewer than `MIN_TRACKS` judged tracks the
card's threshold stands. The rule it was judged by was written before any of its values
(docs/results/forward.md, "A threshold matched to the judged period").

For each grid (folders written by `benchmarks/detection_quality.py --forward --detectors bc`):
ROC AUC (the same for all: one period's threshold does not reorder its tracks), and the share of
normal tracks and of anomalies flagged at `--contamination 0.05`, pooled over the cells' tracks,
the ashore rule as the cells were run; the card's row is checked against each cell's
evaluation.json. Two rows more say what any threshold of this ranking could flag: `later 5 %` and
`later 8 %` put it where it flags no more than that share of each cell's own normal later
tracks (a threshold no one can know in advance; 8 % is the issue's bound).

Run: python benchmarks/period_threshold.py runs/grid13/kitimat/forward-s1 [more grids] [--pool]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from pooled_grid import grouped_from_args, pooled  # (this folder: run as a script)
from stepod import as_row, card_of, logged_row

from aisdati.detection.labels import label_metrics
from aisdati.tracks.ashore import AshoreCheck

CONTAMINATION = 0.05
SCORE = "stepspread"
MIN_TRACKS = 10
HINDSIGHT = {"later 5 %": 0.05, "later 8 %": 0.08}
"""The shares of each cell's normal later tracks the hindsight thresholds may flag."""


def hindsight_cut(ranked: np.ndarray, labels: np.ndarray, share: float) -> float:
    """The lowest threshold that flags at most `share` of the normal tracks (ranked values)."""
    normal = np.sort(ranked[labels == 0])[::-1]
    return float(normal[int(np.floor(share * len(normal)))])


def cell_metrics(cell: Path) -> dict[str, dict]:
    """`label_metrics` of the card's and the period's threshold in one cell, its logged row."""
    scores = pd.read_parquet(cell / "scores.parquet")
    rows = scores[(scores["detector"] == "bc") & (scores["score"] == SCORE)]
    value = rows["value"].to_numpy(np.float64)
    own = np.asarray(card_of(cell)["calibration"][SCORE], np.float64)
    card = float(np.quantile(own, 1.0 - CONTAMINATION))
    if not np.allclose(rows["threshold"], card):
        raise SystemExit(f"{cell}: the card's threshold differs from the cell's")
    period = card * np.median(value) / np.median(own) if len(value) >= MIN_TRACKS else card
    rule = AshoreCheck()
    ashore = rule.flags(rows["ashore_reports"].to_numpy())
    ranked = np.asarray(rule.ranked(value, rows["ashore_reports"], rows["n_points"]), np.float64)
    labels = rows["label"].to_numpy()
    out = {
        name: label_metrics(labels, (value > cut) | ashore, ranked)
        for name, cut in (("card", card), ("period", period))
    }
    for name, share in HINDSIGHT.items():
        out[name] = label_metrics(labels, ranked > hindsight_cut(ranked, labels, share), ranked)
    out["ratio"] = period / card
    if not np.isclose(logged_row(cell, SCORE)["recall"], out["card"]["recall"]):
        raise SystemExit(f"{cell}: the card's threshold recomputed differs from evaluation.json")
    return out


def main() -> None:
    _, groups = grouped_from_args(__doc__, cell_metrics)
    print("| grid | threshold | cells | ROC AUC | normal flagged | anomalies flagged "
          "| period / card |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for grid, cells in groups:
        ratio = np.median([c["ratio"] for c in cells])
        for name in ("card", "period", *HINDSIGHT):
            auc, fa, recall = pooled([as_row(c[name]) for c in cells])
            shown = f"{ratio:.2f}" if name == "period" else ""
            print(f"| {grid} | {name} | {len(cells)} | {auc:.3f} | {fa:.3f} | {recall:.3f} "
                  f"| {shown} |")  # fmt: skip


if __name__ == "__main__":
    main()
