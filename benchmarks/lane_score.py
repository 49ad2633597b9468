"""How the lane score depends on its settings: rescores the models of a
`detection_quality.py` run (every seed and route) with L lane rollouts, a course weight
(`ScoreSettings.lane_course_km`), a tail fraction (`ScoreSettings.tail`), with or without the
shared traffic rollouts (`ScoreSettings.lane_traffic`) and several latent-noise draws,
recalibrating each model on its own training tracks the same way, and prints one markdown
table of the pooled ROC AUC (mean over the seeds) per draw. The lane is a sample of the
policy's rollouts, so one draw's AUC carries sampling noise; this measures it, and what more
rollouts, the course weight, the tail and the traffic rollouts buy.
`nearest` has no draw (its lane is the training tracks) and no rollouts.

Run: python benchmarks/lane_score.py [--run runs/quality-v7/kitimat] [--rollouts 10,30,100]
     [--course-km 0,2] [--tail 0.1] [--traffic 0,1] [--draws 0,100,200]
     [--detectors dati,bc,nearest]
Needs a finished `python benchmarks/detection_quality.py --out runs/quality-v7` run (its
models and injected data). About a minute per draw at 30 rollouts on 2 cores, three at 100.
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import NearestDetector, ScoreSettings, load_detector
from aisdati.tracks.store import load_tracks

CONTAMINATION = 0.05
"""As `aisdati evaluate`'s default: the pooled ranking divides by this calibrated threshold."""


def scored(seed_dir: Path, detector: str, how: ScoreSettings) -> pd.DataFrame:
    """One seed's held-out tracks of every route (label, kind, route), each lane score divided
    by its route model's calibrated threshold (`ratio`), as `aisdati evaluate` pools them."""
    parts = []
    for route in sorted(p.name for p in seed_dir.iterdir() if (p / "models").is_dir()):
        data = seed_dir / route / "data"
        table = pd.read_csv(data / "labels.csv")
        stem = route if detector == "dati" else f"{route}-{detector}"
        det = load_detector(seed_dir / route / "models" / stem)
        train = load_tracks(data, [int(i) for i in det.card.data.track_ids])
        if isinstance(det, NearestDetector):  # each training track against the other vessels
            own = det.lane_scores([t.positions for t in train], how, det.mmsi)[0]
        else:
            own = det.score(train, how).score_m
        threshold = np.quantile(own, 1.0 - CONTAMINATION)
        held = load_tracks(data, table["track_id"].tolist())
        parts.append(table.assign(route=route, ratio=det.score(held, how).score_m / threshold))
    return pd.concat(parts, ignore_index=True)


def aucs(table: pd.DataFrame) -> dict[str, float]:
    """Pooled ROC AUC, and per route and per anomaly kind (against all normal tracks)."""
    normal = table[table["label"] == 0]
    out = {"pooled": float(roc_auc_score(table["label"], table["ratio"]))}
    for route, group in table.groupby("route"):
        out[str(route)] = float(roc_auc_score(group["label"], group["ratio"]))
    for kind, group in table[table["label"] == 1].groupby("kind"):
        both = pd.concat([normal, group])
        out[str(kind)] = float(roc_auc_score(both["label"], both["ratio"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=Path("runs/quality-v7/kitimat"))
    ap.add_argument("--rollouts", default="10,30,100", help="lane rollouts L, comma-separated")
    ap.add_argument("--course-km", default="0", help="lane course weights, comma-separated")
    ap.add_argument("--tail", default="0.1", help="tail fractions, comma-separated")
    ap.add_argument("--traffic", default="1", help="shared traffic rollouts off/on: 0,1")
    ap.add_argument("--draws", default="0,100,200", help="offsets to each seed's scoring seed")
    ap.add_argument("--detectors", default="dati,bc,nearest")
    args = ap.parse_args()
    seeds = sorted(int(p.name[4:]) for p in args.run.glob("seed*") if p.name[4:].isdigit())
    if not seeds:
        raise SystemExit(f"no seed<k> folders under {args.run}: run detection_quality.py first")
    draws = [int(d) for d in args.draws.split(",")]
    print(f"Pooled lane ROC AUC, mean over seeds {seeds}, per noise draw ({args.run})")
    print(
        "| detector | lane rollouts | course km | tail | traffic | "
        + " | ".join(f"draw {d}" for d in draws)
        + " | mean |"
    )
    print("|---|---|---|---|---|" + "---|" * (len(draws) + 1))
    rows = []
    for detector in args.detectors.split(","):
        lanes = [0] if detector == "nearest" else [int(x) for x in args.rollouts.split(",")]
        courses = [float(x) for x in args.course_km.split(",")]
        tails = [float(x) for x in args.tail.split(",")]
        traffics = [bool(int(x)) for x in args.traffic.split(",")]
        for lane, course, tail, traffic in itertools.product(lanes, courses, tails, traffics):
            means, details = [], []
            for draw in [0] if detector == "nearest" else draws:
                per_seed = [
                    aucs(
                        scored(
                            args.run / f"seed{s}",
                            detector,
                            ScoreSettings(
                                score="lane",
                                rollouts=max(1, min(10, lane)),
                                lane_rollouts=max(1, lane),
                                lane_course_km=course,
                                tail=tail,
                                lane_traffic=traffic,
                                seed=s + draw,
                            ),
                        )
                    )
                    for s in seeds
                ]
                details += per_seed
                means.append(float(np.mean([a["pooled"] for a in per_seed])))
            means += means[-1:] * (len(draws) - len(means))  # nearest: the same every draw
            cells = " | ".join(f"{m:.3f}" for m in means)
            print(
                f"| {detector} | {lane or '-'} | {course:g} | {tail:g} | {traffic:d} | {cells} "
                f"| {np.mean(means):.3f} |",
                flush=True,
            )
            setting = f"{lane or '-'} | {course:g} | {tail:g} | {traffic:d}"
            rows.append((detector, setting, pd.DataFrame(details).mean()))
    print("\nMean over seeds and draws, per route and per anomaly kind (each kind against all")
    print("normal tracks):")
    every = list(dict.fromkeys(n for row in rows for n in row[2].index))
    routes = sorted((n for n in every if n.startswith("route-")), key=lambda n: int(n[6:]))
    names = ["pooled", *routes, *(n for n in every if n != "pooled" and n not in routes)]
    print("| detector | lane rollouts | course km | tail | traffic | " + " | ".join(names) + " |")
    print("|---|---|---|---|---|" + "---|" * len(names))
    for detector, setting, mean in rows:
        cells = " | ".join(f"{mean[n]:.3f}" if n in mean else "-" for n in names)
        print(f"| {detector} | {setting} | {cells} |")


if __name__ == "__main__":
    main()
