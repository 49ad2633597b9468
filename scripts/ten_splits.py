"""Draw docs/ten_splits.png: one route's lane ROC AUC per split and detector, marking the splits
that hold out one given normal track, beside that track, the rollouts DATI generates from its
start and DATI's traffic from the training starts (README, "Ten splits of Kitimat"). DATI is
drawn twice: as the run scored it, and rescored with today's defaults (the traffic in the
lane); `nearest` and BC as run.

Run:
    python benchmarks/detection_quality.py --seeds 0,1,2,3,4,5,6,7,8,9 \\
        --detectors dati,nearest,bc --out runs/q10
    python scripts/ten_splits.py runs/q10/kitimat docs/ten_splits.png

Several run folders may be given (each seed is read from the first that has it, per
detector), so seeds measured in separate runs are drawn together.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from aisdati.detectors import ScoreSettings, load_detector
from aisdati.plots import draw_land, save, set_map_limits
from aisdati.tracks.store import load_tracks

COLORS = {
    "dati": "tab:blue",
    "dati, own rollouts only": "lightsteelblue",
    "nearest": "tab:orange",
    "bc, own rollouts only": "tab:green",
}


def route_aucs(runs: list[Path], route: str, track: int) -> pd.DataFrame:
    """Lane AUC of `route` per (seed, detector), and whether the seed held out `track`."""
    rows, seen = [], set()
    for run in runs:
        for seed_dir in sorted(run.glob("seed*")):
            table = seed_dir / "scores.parquet"
            if not table.is_file():
                continue
            s = pd.read_parquet(table)
            s = s[(s["score"] == "lane") & (s["route"] == route)]
            for det, g in s.groupby("detector"):
                seed = int(seed_dir.name[4:])
                if (seed, det) in seen:
                    continue
                seen.add((seed, det))
                held = bool((g["track_id"] == track).any())
                auc = roc_auc_score(g["label"], g["value"])
                label = f"{det}, own rollouts only" if det != "nearest" else det
                rows.append({"seed": seed, "detector": label, "auc": auc, "held": held})
                if det == "dati":  # the scores as run predate the traffic: rescore
                    auc = roc_auc_score(g["label"], rescored(seed_dir, route, g["track_id"]))
                    rows.append({"seed": seed, "detector": det, "auc": auc, "held": held})
    return pd.DataFrame(rows)


def rescored(seed_dir: Path, route: str, ids: pd.Series) -> np.ndarray:
    """DATI's lane scores of these held-out tracks with today's defaults (the traffic too)."""
    det = load_detector(seed_dir / route / "models" / route)
    tracks = load_tracks(seed_dir / route / "data", [int(i) for i in ids])
    return det.score(tracks, ScoreSettings(seed=int(seed_dir.name[4:]))).score


def draw_lane(ax: plt.Axes, seed_dir: Path, route: str, track: int) -> None:
    """The track, DATI's lane from its start and the training tracks, coloured by deviation."""
    det = load_detector(seed_dir / route / "models" / route)
    data = seed_dir / route / "data"
    train = load_tracks(data, [int(i) for i in det.card.data.track_ids])
    (held,) = load_tracks(data, [track])
    how = ScoreSettings(seed=int(seed_dir.name[4:]), lane_traffic=False)
    scored = det.score([held], how)
    policy = det.policy()
    _, _, (lane,) = policy.rollout_scores(
        [held.positions], how.rollouts, how.seed, how.lane_reach, how.lane_rollouts
    )
    draw_land(ax)
    for t in train:
        ax.plot(*t.positions.T, color="0.6", lw=0.6)
    for r in lane:
        ax.plot(*r.T, color="tab:blue", lw=0.5, alpha=0.4)
    for r in det.traffic(policy, how):
        ax.plot(*r.T, color="tab:green", lw=0.6, alpha=0.6)
    p = held.positions
    dots = ax.scatter(*p.T, c=scored.profiles[0] / 1000.0, s=14, cmap="Reds", vmin=0, zorder=3)
    ax.plot(*p[0], "k*", ms=12, zorder=4)
    plt.colorbar(dots, ax=ax, label=f"track {track}: distance to its own rollouts, km")
    profile = scored.profiles[0]
    worst = p[profile >= np.quantile(profile, 1.0 - how.tail)]  # the reports its score averages
    margin = np.array([0.15, 0.08])  # degrees: about 10 km around them
    set_map_limits(ax, worst.min(axis=0) - margin, worst.max(axis=0) + margin)
    ax.set_title(
        f"track {track} (star: its start; {seed_dir.name}): grey training tracks,\nblue DATI's "
        f"{len(lane)} rollouts from its start, green its traffic (one from each training start)",
        fontsize=9,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+", help="detection_quality area folders, then out")
    ap.add_argument("--route", default="route-2")
    ap.add_argument("--track", type=int, default=143, help="the normal track to mark")
    args = ap.parse_args()
    *runs, out = args.runs
    aucs = route_aucs(runs, args.route, args.track)
    if aucs.empty:
        raise SystemExit(f"no scores.parquet under {runs}: run detection_quality.py first")
    fig, (left, right) = plt.subplots(1, 2, figsize=(15, 6.5), width_ratios=(1, 1.3))
    for i, (det, g) in enumerate(aucs.groupby("detector")):
        x = g["seed"] + (i - 1) * 0.2
        for held, marker in ((True, "o"), (False, "s")):
            h = g[g["held"] == held]
            left.scatter(x[h.index], h["auc"], color=COLORS.get(det, "0.3"), marker=marker,
                         facecolors="none" if held else COLORS.get(det, "0.3"))  # fmt: skip
        left.plot([], [], "s", color=COLORS.get(det, "0.3"),
                  label=f"{det}: mean {g['auc'].mean():.3f}")  # fmt: skip
    left.plot([], [], "o", mfc="none", color="0.3", label=f"hollow: track {args.track} held out")
    left.axhline(0.95, color="0.5", ls="--", lw=1)
    left.set(xlabel="seed (split)", ylabel=f"{args.route} lane ROC AUC", ylim=(0.75, 1.01))
    left.set_xticks(sorted(aucs["seed"].unique()))
    left.legend(loc="lower left", fontsize=9)
    first = aucs[(aucs["held"]) & (aucs["detector"] == "dati")]["seed"].min()
    where = next(r / f"seed{first}" for r in runs if (r / f"seed{first}" / args.route).is_dir())
    draw_lane(right, where, args.route, args.track)
    fig.tight_layout()
    save(fig, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
