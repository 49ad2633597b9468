"""Do the one-step scores' thresholds hold forward in time? Four allowances measured (not a test).

`--score steprate` (the one-step errors over their report intervals) ranks the later tracks
best of every score, but its threshold, the 95th percentile of the training tracks' own
cross-fitted scores, does not hold forward: it flags no anomaly at sea on Kitimat and 12 % of
Virginia Beach's normal tracks (docs/results/forward.md). On the cells of
`benchmarks/detection_quality.py --forward` (DATI's or, `--detector bc`, cross-fitted BC's
models), for `step`, `steprate` and `stepspread` where the models' cards were calibrated with
them, beside the evaluation's own figures:

- `adjusted`: the areas' reporting intervals changed between the periods (Kitimat's median
  240 -> 300 s, Virginia Beach's 79 -> 70 s), so each track's score times (its median report
  interval / the training tracks' median of it)^-g, g the least-squares slope of log(score) on
  log(median interval) over the training tracks' calibration scores, against the 95th
  percentile of the training tracks' adjusted scores;
- `member-wise`: a training track's calibration score comes from one member (K draws of the
  member that did not train on its vessel), a later track's from the ensemble (K draws spread
  over the members, the best kept, a lower statistic); so each later track scored by each
  member alone, its score the mean over the members, against the card's own threshold;
- `speed-adjusted`: fast vessels' one-step errors are larger, in metres and per second, and the
  periods hold different shares of them (Kitimat's July 17 of 134 tracks above 7 m/s, its
  August 2 of 20), so each track's score times (its median speed / the training tracks' median
  of it)^-g, g fitted as the interval's;
- `speed-classes`: a Mondrian calibration, each track against the 95th percentile of the
  training tracks of its class of median speed (three, cut at the training tracks' tertiles).

Tracks the ashore rule flagged in the evaluation are flagged and rank first, as there. The table
gives, per grid and variant, the mean over the cells of ROC AUC, the shares of normal (FA) and
altered (recall) tracks flagged, the later normal tracks' median score against the training
tracks', and g.

Run: python benchmarks/forward_thresholds.py runs/grid2/*/forward-* [--contamination 0.05]
     [--ways adjusted,member-wise,speed-adjusted,speed-classes] [--detector dati|bc]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import ScoreSettings, load_detector, model_name
from aisdati.detectors.policy import PolicyDetector
from aisdati.detectors.scoring import score_chunks
from aisdati.geo import legs_m
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import Track, load_tracks

RULE = AshoreCheck()
SCORES = ("step", "steprate", "stepspread")
"""The scores measured, where the models' cards were calibrated with them."""


def member_wise(detector: PolicyDetector, tracks: list[Track], draws: int, seed: int) -> dict:
    """Each track's `SCORES` from each member alone (K draws of it, as the calibration scores
    a training track: `PolicyDetector.member_wise`), averaged over the members; in the
    evaluation's scoring chunks."""
    how = ScoreSettings(score="step", rollouts=draws, seed=seed)
    out = {k: np.zeros(len(tracks)) for k in SCORES}
    for chunk in score_chunks(len(tracks)):
        got = detector.member_wise(tracks[chunk.start : chunk.stop], how, SCORES)
        for k in SCORES:
            out[k][chunk.start : chunk.stop] = got[k]
    return out


def power_adjusted(cal, cal_x, values, x) -> tuple[np.ndarray, np.ndarray, float]:
    """The training and later scores times (x / the training median of x)^-g, g the slope of
    log(score) on log(x) over the training tracks, and g: what x explains of the scores out."""
    g = float(np.polyfit(np.log(cal_x), np.log(cal), 1)[0])
    ref = float(np.median(cal_x))
    return cal * (cal_x / ref) ** -g, values * (x / ref) ** -g, g


def class_thresholds(cal, cal_x, x, contamination: float) -> np.ndarray:
    """Each later track's threshold: the (1 - contamination) quantile of the training scores
    of its class of x, the classes cut at the training tracks' tertiles of x."""
    cuts = np.quantile(cal_x, [1 / 3, 2 / 3])
    cal_class, cls = np.searchsorted(cuts, cal_x), np.searchsorted(cuts, x)
    per_class = [np.quantile(cal[cal_class == c], 1.0 - contamination) for c in range(3)]
    return np.asarray(per_class)[cls]


def median_intervals(tracks: list[Track]) -> np.ndarray:
    """Each track's median report interval, seconds."""
    return np.array([np.median(t.dts) * 3600.0 for t in tracks])


def median_speeds(tracks: list[Track]) -> np.ndarray:
    """Each track's median leg over its median report interval, m/s (at least 0.1)."""
    return np.array(
        [max(0.1, np.median(legs_m(t.positions)) / (np.median(t.dts) * 3600.0)) for t in tracks]
    )


WAYS = ("adjusted", "member-wise", "speed-adjusted", "speed-classes")


def cell_rows(cell: Path, contamination: float, ways: list[str], method: str) -> list[dict]:
    """Each score's figures on one cell: as evaluated, and each of `ways`."""
    doc = json.loads((cell / "evaluation.json").read_text())
    settings = doc["settings"]
    models = Path(settings["models_dir"] or cell / "models")
    detector = load_detector(models / model_name("all", method))
    labels = pd.read_csv(cell / "data" / "labels.csv")
    later = load_tracks(cell / "data", labels["track_id"].tolist())
    training = load_tracks(cell / "data", doc["split"]["training_track_ids"])
    train_dt, later_dt = median_intervals(training), median_intervals(later)
    train_v, later_v = median_speeds(training), median_speeds(later)
    if "member-wise" in ways:
        mean = member_wise(detector, later, settings["rollouts"], settings["seed"])
    scores = pd.read_parquet(cell / "scores.parquet")
    y = labels["label"].to_numpy()
    rows = []
    for score in [k for k in SCORES if k in detector.card.calibration]:
        got = scores[(scores["detector"] == method) & (scores["score"] == score)]
        got = got.set_index("track_id").loc[labels["track_id"]]
        ashore, lengths = got["ashore_reports"].to_numpy(), got["n_points"].to_numpy()
        cal = np.asarray(detector.card.calibration[score], np.float64)
        values = got["value"].to_numpy()
        cut = np.quantile(cal, 1.0 - contamination)
        variants = {score: (values, cut, np.nan)}
        if "adjusted" in ways:
            c, v, g = power_adjusted(cal, train_dt, values, later_dt)
            variants["adjusted"] = (v, np.quantile(c, 1.0 - contamination), g)
        if "member-wise" in ways:
            variants["member-wise"] = (mean[score], cut, np.nan)
        if "speed-adjusted" in ways:
            c, v, g = power_adjusted(cal, train_v, values, later_v)
            variants["speed-adjusted"] = (v, np.quantile(c, 1.0 - contamination), g)
        if "speed-classes" in ways:
            cuts = class_thresholds(cal, train_v, later_v, contamination)
            variants["speed-classes"] = (values, cuts, np.nan)
        for way, (v, threshold, slope) in variants.items():
            name = score if way == score else f"{score} {way}"
            flagged = (v > threshold) | RULE.flags(ashore)
            rows.append(
                {
                    "score": name,
                    "auc": roc_auc_score(y, RULE.ranked(v, ashore, lengths)),
                    "fa": flagged[y == 0].mean(),
                    "recall": flagged[y == 1].mean(),
                    "normal": float(np.median(v[y == 0])),
                    "training": float(np.median(cal)),
                    "g": slope,
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="folders of evaluate cells")
    ap.add_argument("--contamination", type=float, default=0.05)
    ap.add_argument("--ways", default=",".join(WAYS), help="comma-separated: " + ", ".join(WAYS))
    ap.add_argument("--detector", default="dati", choices=("dati", "bc"), help="whose models")
    args = ap.parse_args()
    ways = args.ways.split(",")
    if set(ways) - set(WAYS):
        ap.error(f"--ways takes {', '.join(WAYS)}")
    print(f"One-step thresholds forward in time at --contamination {args.contamination}")
    print("| grid | score | ROC AUC | FA | recall | later normal median | training median | g |")
    print("|---|---|---|---|---|---|---|---|")
    for grid in args.grids:
        cells = sorted(p.parent for p in grid.glob("*/evaluation.json"))
        rows = [r for c in cells for r in cell_rows(c, args.contamination, ways, args.detector)]
        frame = pd.DataFrame(rows)
        for name, m in frame.groupby("score", sort=False):
            print(
                f"| {grid.parent.name}/{grid.name} | {name} | {m['auc'].mean():.3f} | "
                f"{m['fa'].mean():.3f} | {m['recall'].mean():.2f} | {m['normal'].mean():.3g} | "
                f"{m['training'].mean():.3g} | {m['g'].mean():.2f} |"
            )


if __name__ == "__main__":
    main()
