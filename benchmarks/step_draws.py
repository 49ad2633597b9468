"""How the one-step score's K draws are aggregated at each report, on evaluate runs (not a test).

The step score (`aisdati.ais.policy`) draws K decisions at every real report and keeps the
best draw's error (best-of-K, as the paper's rollout score keeps the best of K rollouts). This
rescoring asks whether another statistic of the K errors ranks the altered tracks better: the
median (the typical draw: a model unsure where a vessel goes spreads its draws, and the best
of a wide spread lands near anything) or the mean. It reads the cells of
`benchmarks/detection_quality.py --forward` (or any `aisdati evaluate` folders), rescores their
judged tracks with the DATI model that judged them (the same draws as the evaluation: one
scoring chunk per 64 tracks, the evaluation's seed), aggregates each track's per-report values
by the score's tail mean, and prints ROC AUC per aggregation: per cell, and the mean over the
cells of each area. The `best` column reproduces the evaluation's own step AUC.

Run: python benchmarks/step_draws.py runs/quality/kitimat/forward-s1-at-sea [more grid folders]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import load_detector
from aisdati.detectors.scoring import SCORE_CHUNK, ScoreSettings, score_chunks, tail_mean
from aisdati.tracks.store import load_tracks

AGGREGATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "best": lambda e: e.min(axis=1),
    "median": lambda e: np.median(e, axis=1),
    "mean": lambda e: e.mean(axis=1),
}
"""Statistics of a report's K draw errors ([n, K] -> [n])."""


def cell_aucs(cell: Path) -> dict[str, float]:
    """ROC AUC of each aggregation on one evaluate folder, and the evaluation's own step AUC."""
    doc = json.loads((cell / "evaluation.json").read_text())
    settings = doc["settings"]
    models = Path(settings["models_dir"] or cell / "models")
    detector = load_detector(models / "all")
    labels = pd.read_csv(cell / "data" / "labels.csv")
    tracks = load_tracks(cell / "data", labels["track_id"].tolist())
    how = ScoreSettings()
    scores: dict[str, list[float]] = {name: [] for name in AGGREGATIONS}
    policy = detector.policy()
    for chunk in score_chunks(len(tracks)):
        part = tracks[chunk.start : chunk.stop]
        errors, _ = policy.step_draws(
            [t.positions for t in part], [t.dts for t in part], settings["rollouts"],
            settings["seed"],
        )  # fmt: skip
        for name, aggregate in AGGREGATIONS.items():
            scores[name] += [tail_mean(aggregate(e), how.tail) for e in errors]
    y = labels["label"].to_numpy()
    out = {name: float(roc_auc_score(y, s)) for name, s in scores.items()}
    own = next(
        r["roc_auc"]
        for r in doc["results"]
        if (r["detector"], r["score"], r["kind"]) == ("dati", "step", "all")
    )
    out["evaluation"] = float(own)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="folders of evaluate runs (cells)")
    args = ap.parse_args()
    columns = [*AGGREGATIONS, "evaluation"]
    tail = ScoreSettings().tail
    print(f"ROC AUC of the one-step score by how each report's K draws are aggregated (tail "
          f"mean of the largest {tail:g}; scoring chunks of {SCORE_CHUNK})")  # fmt: skip
    print("| cell | " + " | ".join(columns) + " |")
    print("|---" * (1 + len(columns)) + "|")
    for grid in args.grids:
        cells = sorted(p.parent for p in grid.glob("*/evaluation.json"))
        rows = [cell_aucs(c) for c in cells]
        for cell, row in zip(cells, rows, strict=True):
            print(
                f"| {grid.name}/{cell.name} | "
                + " | ".join(f"{row[c]:.3f}" for c in columns)
                + " |"
            )
        means = [f"**{np.mean([r[c] for r in rows]):.3f}**" for c in columns]
        print(f"| {grid} ({len(rows)} cells) | " + " | ".join(means) + " |")


if __name__ == "__main__":
    main()
