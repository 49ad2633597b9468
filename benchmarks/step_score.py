"""Variants of the one-step score, rescored on evaluate runs (not a test).

The step score (`aisdati.ais.policy`) draws K decisions at every real report, moves each over
the real time step and keeps the best draw's error (best-of-K, as the paper's rollout score
keeps the best of K rollouts). Two questions, each answered without retraining:

- `--aggregate`: does another statistic of a report's K errors rank the altered tracks better?
  The median (the typical draw: a model unsure where a vessel goes spreads its draws, and the
  best of a wide spread lands near anything) or the mean.
- `--tails`: does another share of a track's largest per-report errors (the score's tail mean,
  0.1 by default; `max`: the largest alone) rank better? A position jump is two large errors,
  which the mean of the largest tenth of a long track dilutes.
- `--normalise`: does a one-step error in the track's own units rank better? `track` divides a
  track's errors by its median step (metres between consecutive reports, at least 10 m): a
  fast ferry's metres of error weigh as a slow tug's; `velocity` divides each report's error by
  its time step, at least the track's median one (an error in m/s), so a gap's long prediction
  weighs no more than a typical report's: the tool's `--score steprate` (`error_rates`).
  `spread` divides each report's best error by the K draws' own spread (the root mean square of
  their distances from their centroid, plus 10 m, an AIS position's accuracy): the surprise of
  the report under the model's predictive spread, which is wide where the members disagree or a
  fast vessel's next report is uncertain (the tool's `--score stepspread`, `error_surprises`);
  `centre` the same for the report's distance from the draws' centroid instead of the best
  draw's error.
- `--ahead`: does predicting h reports ahead (the policy moved h times from the real report,
  over the real time steps, its own moves feeding its state) see more than one step? A loiter
  comes back to where it was while the policy sails on, and a detour bends away from where the
  policy goes for several reports; one step sees each as a small turn.

It reads the cells of `benchmarks/detection_quality.py --forward` (or any `aisdati evaluate`
folders), rescores their judged tracks with the model that judged them (`--detector`: dati,
or bc, whose draws come from its Gaussian, wide where it learnt a report is uncertain; one
scoring chunk per 64 tracks with the evaluation's seed, so `best h=1` reproduces the
evaluation's own step AUC, printed beside it), aggregates each track's per-report values by the
score's tail mean, ranks the tracks the ashore rule flagged in the evaluation first (as it did),
and prints ROC AUC per variant: per cell, and the mean over each grid's cells.

Run: python benchmarks/step_score.py runs/quality/kitimat/forward-s1-at-sea [more grid folders]
     [--ahead 1,2,3,5] [--aggregate best,median,mean] [--tails 0.02,0.05,0.1,0.2,max]
     [--normalise none,track,velocity,spread,centre] [--detector dati|bc]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import load_detector, model_name
from aisdati.detectors.scoring import (
    POSITION_ACCURACY_M,
    SCORE_CHUNK,
    ScoreSettings,
    error_rates,
    error_surprises,
    score_chunks,
    tail_mean,
)
from aisdati.geo import arc_m, draw_spread, legs_m, unit_vectors
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import Track, load_tracks

RULE = AshoreCheck()
"""Tracks the ashore rule flags rank first, as in the evaluation (`AshoreCheck.ranked`)."""

AGGREGATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "best": lambda e: e.min(axis=1),
    "median": lambda e: np.median(e, axis=1),
    "mean": lambda e: e.mean(axis=1),
}
"""Statistics of a report's K draw errors ([n, K] -> [n])."""


MIN_STEP_M = 10.0
"""`track`'s floor on a track's median step, so a near-still track's errors stay finite."""


def _divisor(track: Track, normalise: str) -> float:
    """What a track's per-report errors are divided by: its median step (`track`), or 1."""
    if normalise == "track":
        return max(MIN_STEP_M, float(np.median(legs_m(track.positions))))
    return 1.0


def _normalised(
    errors: np.ndarray, track: Track, normalise: str, h: int, predicted: np.ndarray
) -> np.ndarray:
    """A track's per-report errors in the unit `normalise` asks for; `velocity` is the tool's
    `steprate` (`error_rates`), over the h time steps from each anchor to its target."""
    if normalise == "velocity":
        return error_rates(errors, np.convolve(track.dts, np.ones(h), "valid"))
    if normalise == "spread":
        return error_surprises(errors, predicted)
    if normalise == "centre":
        centre, spread = draw_spread(predicted)
        off = arc_m(np.linalg.norm(unit_vectors(track.positions[h:]) - centre, axis=1))
        return off / (spread + POSITION_ACCURACY_M)
    return errors / _divisor(track, normalise)


NORMALISATIONS = ("none", "track", "velocity", "spread", "centre")


def _tailed(values: np.ndarray, tail: str) -> float:
    """A track's per-report values aggregated: the tail mean of the largest share `tail`, or
    their largest (`max`)."""
    return float(values.max()) if tail == "max" else tail_mean(values, float(tail))


def _name(aggregate: str, h: int, tail: str, tails: list[str], normalise: str = "none") -> str:
    return (
        f"{aggregate} h={h}"
        + (f" tail={tail}" if len(tails) > 1 else "")
        + ("" if normalise == "none" else f" /{normalise}")
    )


def cell_aucs(
    cell: Path,
    ahead: list[int],
    aggregate: list[str],
    tails: list[str],
    normalise: list[str],
    method: str = "dati",
) -> dict[str, float]:
    """ROC AUC of each variant on one evaluate folder, and the evaluation's own step AUC."""
    doc = json.loads((cell / "evaluation.json").read_text())
    settings = doc["settings"]
    models = Path(settings["models_dir"] or cell / "models")
    detector = load_detector(models / model_name("all", method))
    labels = pd.read_csv(cell / "data" / "labels.csv")
    tracks = load_tracks(cell / "data", labels["track_id"].tolist())
    scores: dict[str, list[float]] = {}
    policy = detector.policy()
    for h in ahead:
        for chunk in score_chunks(len(tracks)):
            part = tracks[chunk.start : chunk.stop]
            errors, predicted = policy.step_draws(
                [t.positions for t in part], [t.dts for t in part], settings["rollouts"],
                settings["seed"], ahead=h,
            )  # fmt: skip
            for name in aggregate:
                per_report = [AGGREGATIONS[name](e) for e in errors]
                for norm in normalise:
                    scaled = [
                        _normalised(v, t, norm, h, q)
                        for v, t, q in zip(per_report, part, predicted, strict=True)
                    ]
                    for tail in tails:
                        scores.setdefault(_name(name, h, tail, tails, norm), []).extend(
                            _tailed(v, tail) for v in scaled
                        )
    y = labels["label"].to_numpy()
    judged = pd.read_parquet(cell / "scores.parquet")  # the ashore rule's counts, as evaluated
    judged = judged[(judged["detector"] == method) & (judged["score"] == "step")]
    judged = judged.set_index("track_id").loc[labels["track_id"]]
    ashore = judged["ashore_reports"].to_numpy()  # zero where the evaluation ran --no-ashore
    out = {
        name: float(roc_auc_score(y, RULE.ranked(np.asarray(s), ashore, judged["n_points"])))
        for name, s in scores.items()
    }
    own = next(
        r["roc_auc"]
        for r in doc["results"]
        if (r["detector"], r["score"], r["kind"]) == (method, "step", "all")
    )
    out["evaluation"] = float(own)
    return out


def _valid_tail(text: str) -> bool:
    try:
        return text == "max" or 0 < float(text) <= 1
    except ValueError:
        return False


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="folders of evaluate runs (cells)")
    ap.add_argument("--ahead", default="1", help="comma-separated h: reports predicted ahead")
    ap.add_argument("--aggregate", default="best,median,mean", help="statistics of the K draws")
    ap.add_argument(
        "--normalise",
        default="none",
        help=f"comma-separated divisors of the errors: {', '.join(NORMALISATIONS)}",
    )
    ap.add_argument(
        "--tails",
        default=str(ScoreSettings().tail),
        help="comma-separated shares of a track's largest per-report errors averaged, or max",
    )
    ap.add_argument("--detector", default="dati", choices=("dati", "bc"), help="whose model")
    args = ap.parse_args()
    tails = args.tails.split(",")
    ahead = [int(h) for h in args.ahead.split(",")]
    aggregate = args.aggregate.split(",")
    normalise = args.normalise.split(",")
    unknown = set(aggregate) - AGGREGATIONS.keys() | set(normalise) - set(NORMALISATIONS)
    if unknown or min(ahead) < 1 or not all(_valid_tail(t) for t in tails):
        ap.error(
            f"--aggregate takes {', '.join(AGGREGATIONS)}; --normalise "
            f"{', '.join(NORMALISATIONS)}; --ahead positive integers; "
            "--tails shares in (0, 1] or max"
        )
    columns = [
        _name(a, h, t, tails, n) for h in ahead for a in aggregate for n in normalise for t in tails
    ]
    columns.append("evaluation")
    print(f"ROC AUC of the one-step score's variants (tail mean of the largest {args.tails}; "
          f"scoring chunks of {SCORE_CHUNK})")  # fmt: skip
    print("| cell | " + " | ".join(columns) + " |")
    print("|---" * (1 + len(columns)) + "|")
    for grid in args.grids:
        cells = sorted(p.parent for p in grid.glob("*/evaluation.json"))
        rows = [cell_aucs(c, ahead, aggregate, tails, normalise, args.detector) for c in cells]
        for cell, row in zip(cells, rows, strict=True):
            values = " | ".join(f"{row[c]:.3f}" for c in columns)
            print(f"| {grid.parent.name}/{cell.name} | {values} |")
        means = [f"**{np.mean([r[c] for r in rows]):.3f}**" for c in columns]
        print(f"| {grid} ({len(rows)} cells) | " + " | ".join(means) + " |")


if __name__ == "__main__":
    main()
