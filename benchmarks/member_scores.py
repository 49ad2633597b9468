"""Score the later tracks as the threshold is calibrated: one member at a time (not a test).

A cross-fitted area model calibrates its threshold on the training tracks, each scored by the
one member that did not train on its vessel, its K one-step draws all that member's. The later
tracks are scored by the whole ensemble: the K draws spread over the members, the best of them
kept, and the best of draws from several networks lies lower than the best of one network's.
So the threshold and the later scores are different statistics. This rescores the later tracks
of `benchmarks/detection_quality.py --forward` cells member by member (K draws of one member,
as calibrated), a track's score the mean over the members of its member-wise scores, and flags
them against the card's own cross-fitted calibration, for `step` and `steprate`; tracks the
ashore rule flagged in the evaluation are flagged and rank first, as there.

Run: python benchmarks/member_scores.py runs/grid2/*/forward-* [--contamination 0.05]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import load_detector
from aisdati.detectors.scoring import error_rates, score_chunks, tail_mean
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import load_tracks

RULE = AshoreCheck()
SCORES = ("step", "steprate")


def member_wise(cell: Path) -> tuple[dict[str, np.ndarray], pd.DataFrame, dict]:
    """Each later track's member-wise scores averaged over the members, by score kind; the
    evaluation's own rows of those tracks; the model's calibration."""
    doc = json.loads((cell / "evaluation.json").read_text())
    settings = doc["settings"]
    detector = load_detector(Path(settings["models_dir"] or cell / "models") / "all")
    labels = pd.read_csv(cell / "data" / "labels.csv")
    tracks = load_tracks(cell / "data", labels["track_id"].tolist())
    members = detector.card.lane_config.members
    per_member = {k: np.zeros((members, len(tracks))) for k in SCORES}
    for m in range(members):
        policy = detector.policy(m)
        for chunk in score_chunks(len(tracks)):
            part = tracks[chunk.start : chunk.stop]
            dts = [t.dts for t in part]
            errors, _ = policy.step_errors(
                [t.positions for t in part], dts, settings["rollouts"], settings["seed"]
            )
            rows = slice(chunk.start, chunk.stop)
            per_member["step"][m, rows] = [tail_mean(e, 0.1) for e in errors]
            per_member["steprate"][m, rows] = [
                tail_mean(error_rates(e, d), 0.1) for e, d in zip(errors, dts, strict=True)
            ]
    scores = pd.read_parquet(cell / "scores.parquet")
    own = scores[scores["detector"] == "dati"].merge(labels[["track_id"]], on="track_id")
    return {k: v.mean(axis=0) for k, v in per_member.items()}, own, detector.card.calibration


def cell_rows(cell: Path, contamination: float) -> list[dict]:
    """ROC AUC, false alarms and recall of each score, as evaluated (the ensemble's draws) and
    member-wise."""
    mean, own, calibration = member_wise(cell)
    labels = pd.read_csv(cell / "data" / "labels.csv")
    y = labels["label"].to_numpy()
    rows = []
    for score in SCORES:
        got = own[own["score"] == score].set_index("track_id").loc[labels["track_id"]]
        ashore, lengths = got["ashore_reports"].to_numpy(), got["n_points"].to_numpy()
        cut = float(np.quantile(np.asarray(calibration[score], np.float64), 1.0 - contamination))
        for name, values in (
            (score, got["value"].to_numpy()),
            (f"{score} member-wise", mean[score]),
        ):
            flagged = (values > cut) | RULE.flags(ashore)
            rows.append(
                {
                    "score": name,
                    "auc": roc_auc_score(y, RULE.ranked(values, ashore, lengths)),
                    "fa": flagged[y == 0].mean(),
                    "recall": flagged[y == 1].mean(),
                    "normal_median": float(np.median(values[y == 0])),
                    "training_median": float(np.median(calibration[score])),
                }
            )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("grids", nargs="+", type=Path, help="folders of evaluate cells")
    ap.add_argument("--contamination", type=float, default=0.05)
    args = ap.parse_args()
    print(f"Member-wise scores at --contamination {args.contamination} (mean over cells)")
    print("| grid | score | ROC AUC | FA | recall | later normal median | training median |")
    print("|---|---|---|---|---|---|---|")
    for grid in args.grids:
        cells = sorted(p.parent for p in grid.glob("*/evaluation.json"))
        frame = pd.DataFrame([r for c in cells for r in cell_rows(c, args.contamination)])
        for name, g in frame.groupby("score", sort=False):
            print(
                f"| {grid.parent.name}/{grid.name} | {name} | {g['auc'].mean():.3f} | "
                f"{g['fa'].mean():.3f} | {g['recall'].mean():.2f} | "
                f"{g['normal_median'].mean():.3g} | {g['training_median'].mean():.3g} |"
            )


if __name__ == "__main__":
    main()
