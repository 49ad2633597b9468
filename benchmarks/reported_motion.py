"""Does the area model gain from reading the reported motion? The step scores of the area's
default model (cross-fitted BC, `stepspread`) with each one-step prediction judged against the
next position only, and by the larger of its distances to the next position and to where the
report's own SOG and COG put the vessel (`ScoreSettings.reported_motion`), on Kitimat forward in
time, plain and thinned. (The variant that put both distances in the tail, not adopted: this
script at commit 1261ff7.)

Per thinning: one `aisdati evaluate --cluster all --before 2018-08-01 --detectors bc` (its BC
model, trained on July, judges every cell; `--altered 0.05`, so its data hold the August tracks
nearly all normal), then seeds 0, 1, ... of evaluate's own data set (`aisdati.evaluation.dataset.
build`, `--altered 0.95`: the kinds in turn over nearly every August track) until each kind has
`--min-anomalies` altered tracks. Every held-out track is scored each way with the model's
`stepspread` and ranked as evaluate ranks (the ashore rule on). A normal track scores the same in
every data set (its draws are keyed by its reports), so the normal tracks are pooled once and the
altered tracks of every seed against them. Per kind x thinning: ROC AUC each way and the gain
with its 95 % paired bootstrap interval (tracks resampled); then the rule's two groups
(docs/results/reported-motion.md).

Run: python benchmarks/reported_motion.py [--out runs/reported-motion] [--thin none,10min]
     [--min-anomalies 200] [--max-seeds 80] [--resamples 1000] [--json PATH]
Not part of the test suite (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)
from scipy.stats import rankdata

from aisdati.detectors import Detector, load_detector
from aisdati.evaluation import dataset
from aisdati.evaluation.inject import parse_params
from aisdati.preprocess.settings import parse_duration
from aisdati.tracks.ashore import AshoreCheck, ashore_counts
from aisdati.tracks.store import load_tracks

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz"
BEFORE = "2018-08-01"
KINDS = ("detour", "jump", "loiter", "shift", "course-noise", "speed-noise")
GROUPS = {"reported": ("shift", "course-noise", "speed-noise"), "positions": KINDS[:3]}
MODES = {"positions": False, "reported": True}


def aisdati(*args: str) -> None:
    cmd = [sys.executable, "-m", "aisdati.cli", *args]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def reference(processed: Path, cell: Path, thin: str) -> Detector:
    """The cell's BC model, trained by `aisdati evaluate` (read back when it exists)."""
    out = cell / "reference"
    if not (out / "evaluation.json").is_file():
        aisdati("evaluate", "--data", str(processed), "--cluster", "all", "--before", BEFORE,
                "--detectors", "bc", "--kinds", ",".join(KINDS), "--altered", "0.05",
                "--seed", "0", "--out", str(out), "--json",
                *([] if thin == "none" else ["--thin", thin]))  # fmt: skip
    return load_detector(out / "models" / "all-bc")


def scored(det: Detector, data: Path, labels: pd.DataFrame) -> pd.DataFrame:
    """Every track of `labels` (in `data`) scored each way (`MODES`), ranked as evaluate ranks."""
    ids = [int(i) for i in labels["track_id"]]
    tracks = load_tracks(data, ids)
    positions = [t.positions for t in tracks]
    ashore = ashore_counts([det.card.data.ashore], positions, [0] * len(tracks))
    lengths = np.array([len(p) for p in positions])
    out = labels.set_index("track_id").loc[ids].reset_index()
    for name, reads in MODES.items():
        how = replace(det.how, score="stepspread", reported_motion=reads)
        values = det.score(tracks, how).score
        out[name] = AshoreCheck().ranked(values, ashore, lengths)
    return out


def cell_scores(processed: Path, cell: Path, thin: str, args: argparse.Namespace) -> pd.DataFrame:
    """The pooled scores of one thinning: its normal tracks once, the altered tracks of every
    seed (read back from `scores.csv` when it exists)."""
    saved = cell / "scores.csv"
    if saved.is_file():
        return pd.read_csv(saved)
    det = reference(processed, cell, thin)
    thin_s = None if thin == "none" else parse_duration(thin, "--thin")
    first = scored(det, cell / "reference" / "data", _labels(cell / "reference" / "data"))
    frames = [first[first["label"] == 0]]
    for seed in range(args.max_seeds):
        altered = pd.concat(frames).query("label == 1")["kind"].value_counts()
        if all(altered.get(k, 0) >= args.min_anomalies for k in KINDS):
            break
        data = cell / f"seed{seed}"
        split = dataset.build(processed, "all", data, KINDS, parse_params(None), seed=seed,
                              train_ids=[int(i) for i in det.card.data.track_ids],
                              before=pd.Timestamp(BEFORE, tz="UTC"), altered=0.95,
                              thin_s=thin_s)  # fmt: skip
        got = scored(det, data, split.labels).assign(seed=seed)
        seen = pd.concat(frames)["track_id"]
        frames.append(got[(got["label"] == 1) | ~got["track_id"].isin(seen)])  # normal: once
    pooled = pd.concat(frames, ignore_index=True)
    pooled.to_csv(saved, index=False)
    return pooled


def _labels(data: Path) -> pd.DataFrame:
    return pd.read_csv(data / "labels.csv")


def auc(normal: np.ndarray, altered: np.ndarray) -> float:
    """ROC AUC of altered against normal scores (ties count half): the Mann-Whitney U."""
    ranks = rankdata(np.r_[normal, altered])
    u = ranks[len(normal) :].sum() - len(altered) * (len(altered) + 1) / 2
    return float(u / (len(normal) * len(altered)))


def gain(frame: pd.DataFrame, kinds: tuple[str, ...], resamples: int) -> dict:
    """ROC AUC of `kinds`' altered tracks against the normal ones, positions only and reading
    the reported motion, and the gain with its 95 % paired bootstrap interval (normal and
    altered tracks resampled apart)."""
    normal = frame[frame["label"] == 0]
    altered = frame[frame["kind"].isin(kinds)]

    def aucs(n: pd.DataFrame, a: pd.DataFrame) -> tuple[float, float]:
        return tuple(auc(n[m].to_numpy(), a[m].to_numpy()) for m in MODES)

    before, after = aucs(normal, altered)
    rng = np.random.default_rng(0)
    draws = [
        aucs(normal.iloc[rng.integers(0, len(normal), len(normal))],
             altered.iloc[rng.integers(0, len(altered), len(altered))])
        for _ in range(resamples)
    ]  # fmt: skip
    gains = np.array([b - a for a, b in draws])
    low, high = np.percentile(gains, [2.5, 97.5])
    return {"anomalies": len(altered), "normal": len(normal), "auc_positions": before,
            "auc_reported": after, "gain": after - before, "low": float(low),
            "high": float(high), "gains": gains}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/reported-motion"))
    ap.add_argument("--thin", default="none,10min")
    ap.add_argument("--min-anomalies", type=int, default=200)
    ap.add_argument("--max-seeds", type=int, default=80)
    ap.add_argument("--resamples", type=int, default=1000)
    add_json_option(ap, "reported_motion")
    args = ap.parse_args()
    processed = args.out / "processed"
    if not (processed / "tracks.parquet").is_file():
        aisdati("ingest", "--input", str(DATA), "--roi", "none", "--min-points", "100",
                "--out", str(processed), "--json")  # fmt: skip
    thins = args.thin.split(",")
    cells = {t: cell_scores(processed, args.out / f"thin-{t}", t, args) for t in thins}
    with Report.from_args("reported_motion", args) as report:
        table(report, cells, args.resamples)


def table(report: Report, cells: dict[str, pd.DataFrame], resamples: int) -> None:
    """Per kind and group x thinning, then each group's gain averaged over the thinnings (the
    rule's statistic)."""
    columns = ["thin", "kind", "anomalies", "normal", "AUC positions", "AUC reported",
               "gain [95 %]"]  # fmt: skip
    rows = report.table(columns, title="The step scores reading the reported motion")
    groups = {**{k: (k,) for k in KINDS}, **{"+".join(g): g for g in GROUPS.values()}}
    mean: dict[str, list[dict]] = {}
    for thin, frame in cells.items():
        for name, kinds in groups.items():
            g = gain(frame, kinds, resamples)
            mean.setdefault(name, []).append(g)
            values = {k: v for k, v in g.items() if k != "gains"}
            rows.row([thin, name, g["anomalies"], g["normal"], f"{g['auc_positions']:.3f}",
                      f"{g['auc_reported']:.3f}",
                      f"{g['gain']:+.3f} [{g['low']:+.3f}, {g['high']:+.3f}]"],
                     values | {"thin": thin, "kind": name})  # fmt: skip
    for name in ("+".join(g) for g in GROUPS.values()):
        got = mean[name]
        low, high = np.percentile(np.mean([g["gains"] for g in got], axis=0), [2.5, 97.5])
        point = float(np.mean([g["gain"] for g in got]))
        report.note(f"{name}, mean over thinnings: gain {point:+.3f} [{low:+.3f}, {high:+.3f}]")


if __name__ == "__main__":
    main()
