"""How the lane score depends on its number of rollouts and on the noise draw: rescores the
models of a `detection_quality.py` run (DATI and BC, every seed and route) with L lane rollouts
and several latent-noise draws, recalibrating each model on its own training tracks the same
way, and prints one markdown table of the pooled ROC AUC (mean over the seeds) per draw. The
lane is a sample of the policy's rollouts, so one draw's AUC carries sampling noise; this
measures it and what more rollouts buy.

Run: python benchmarks/lane_rollouts.py [--run runs/quality-v7/kitimat] [--rollouts 10,30,100]
     [--draws 0,100,200] [--detectors dati,bc]
Needs a finished `python benchmarks/detection_quality.py --out runs/quality-v7` run (its
models and injected data). About a minute per draw at 30 rollouts on 2 cores, three at 100.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import ScoreSettings, load_detector
from aisdati.trackdata import load_tracks

CONTAMINATION = 0.05
"""As `aisdati evaluate`'s default: the pooled ranking divides by this calibrated threshold."""


def pooled_auc(seed_dir: Path, detector: str, how: ScoreSettings) -> float:
    """Pooled lane AUC of one seed: every route's held-out tracks, each score divided by its
    route model's calibrated threshold."""
    labels, ratios = [], []
    for route in sorted(p.name for p in seed_dir.iterdir() if (p / "models").is_dir()):
        data = seed_dir / route / "data"
        table = pd.read_csv(data / "labels.csv")
        stem = route if detector == "dati" else f"{route}-{detector}"
        det = load_detector(seed_dir / route / "models" / stem)
        train = load_tracks(data, [int(i) for i in det.card["data"]["track_ids"]])
        threshold = np.quantile(det.score(train, how).score_m, 1.0 - CONTAMINATION)
        held = load_tracks(data, table["track_id"].tolist())
        ratios += list(det.score(held, how).score_m / threshold)
        labels += list(table["label"].to_numpy() == 1)
    return float(roc_auc_score(labels, ratios))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=Path("runs/quality-v7/kitimat"))
    ap.add_argument("--rollouts", default="10,30,100", help="lane rollouts L, comma-separated")
    ap.add_argument("--draws", default="0,100,200", help="offsets to each seed's scoring seed")
    ap.add_argument("--detectors", default="dati,bc")
    args = ap.parse_args()
    seeds = sorted(int(p.name[4:]) for p in args.run.glob("seed*") if p.name[4:].isdigit())
    if not seeds:
        raise SystemExit(f"no seed<k> folders under {args.run}: run detection_quality.py first")
    draws = [int(d) for d in args.draws.split(",")]
    print(f"Pooled lane ROC AUC, mean over seeds {seeds}, per noise draw ({args.run})")
    print("| detector | lane rollouts | " + " | ".join(f"draw {d}" for d in draws) + " | mean |")
    print("|---|---|" + "---|" * (len(draws) + 1))
    for detector in args.detectors.split(","):
        for lane in (int(x) for x in args.rollouts.split(",")):
            means = []
            for draw in draws:
                aucs = [
                    pooled_auc(
                        args.run / f"seed{s}",
                        detector,
                        ScoreSettings(
                            score="lane", rollouts=min(10, lane), lane_rollouts=lane, seed=s + draw
                        ),
                    )
                    for s in seeds
                ]
                means.append(float(np.mean(aucs)))
            cells = " | ".join(f"{m:.3f}" for m in means)
            print(f"| {detector} | {lane} | {cells} | {np.mean(means):.3f} |", flush=True)


if __name__ == "__main__":
    main()
