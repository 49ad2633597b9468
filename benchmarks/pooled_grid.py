"""Forward grids of small areas pooled (not a test): one false alarm among a small area's 10-25
normal later tracks moves its rate by 4-10 points, so a bound on the share of normal tracks
flagged is judged over several areas' tracks together.

Reads the cells (`train<t>-seed<s>/evaluation.json`) of each grid folder written by
`benchmarks/detection_quality.py --forward` and prints, per detector and score, for each grid
and for all of them: ROC AUC (the mean over a grid's cells; for all, the mean of the grids'
means, each area weighing alike) and, at the calibrated threshold, the share of the normal
tracks flagged and of the anomalies flagged, pooled: the flagged tracks of every cell over the
tracks of every cell.

Run: python benchmarks/pooled_grid.py runs/grid12/losangeles/forward-s1-at-sea [more grids]
     [--json PATH]
(prints a markdown table, its rows as JSON in benchmarks/results/pooled_grid.json)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from report import Report, add_json_option  # (this folder: run as a script)


def all_rows(cell: Path) -> dict[tuple[str, str], dict]:
    """A cell's rows over all kinds, by (detector, score)."""
    doc = json.loads((cell / "evaluation.json").read_text())
    return {(r["detector"], r["score"]): r for r in doc["results"] if r["kind"] == "all"}


def pooled(rows: list[dict]) -> tuple[float, float, float]:
    """Mean ROC AUC, and the false-alarm rate and recall pooled over the cells' tracks."""
    normal = sum(r["normal"] for r in rows)
    altered = sum(r["anomalies"] for r in rows)
    false_alarms = sum(r["false_alarm_rate"] * r["normal"] for r in rows)
    caught = sum(r["recall"] * r["anomalies"] for r in rows)
    auc = float(np.mean([r["roc_auc"] for r in rows]))
    return auc, false_alarms / max(normal, 1), caught / max(altered, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="grid folders of forward cells")
    add_json_option(ap, "pooled_grid")
    args = ap.parse_args()
    cells = {g: [all_rows(c) for c in sorted(g.glob("train*-seed*"))] for g in args.grids}
    if empty := [str(g) for g, c in cells.items() if not c]:
        raise SystemExit(f"no cells (train<t>-seed<s>/evaluation.json) in {', '.join(empty)}")
    keys = sorted(set.intersection(*(set(c[0]) for c in cells.values())))
    with Report.from_args("pooled_grid", args) as report:
        columns = ["grid", "detector", "score", "cells", "ROC AUC", "normal flagged"]
        table = report.table([*columns, "anomalies flagged"], title="Forward grids pooled")
        for det, score in keys:
            aucs, rows = [], []
            for grid, got in cells.items():
                mine = [c[(det, score)] for c in got]
                auc, fa, recall = pooled(mine)
                aucs.append(auc)
                rows += mine
                table.row(
                    [grid, det, score, len(mine), f"{auc:.3f}", f"{fa:.3f}", f"{recall:.3f}"],
                    {"grid": str(grid), "detector": det, "score": score, "cells": len(mine),
                     "roc_auc": auc, "false_alarm_rate": fa, "recall": recall},
                )  # fmt: skip
            _, fa, recall = pooled(rows)
            table.row(
                [f"**all {len(cells)}**", det, score, len(rows), f"**{np.mean(aucs):.3f}**",
                 f"**{fa:.3f}**", f"**{recall:.3f}**"],
                {"grid": f"all {len(cells)}", "detector": det, "score": score, "cells": len(rows),
                 "roc_auc": np.mean(aucs), "false_alarm_rate": fa, "recall": recall},
            )  # fmt: skip


if __name__ == "__main__":
    main()
