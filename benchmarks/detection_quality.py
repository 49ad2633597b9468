"""Detection quality over seeds: runs `aisdati evaluate --cluster routes` (every route of an area
that can be split, pooled) on the real data shipped with the project, once per seed (each seed
draws another split, other injected anomalies and another training seed), and prints one markdown
table of ROC AUC per detector and score: the pooled AUC of each seed, their mean ± sd, and each
route's mean. One seed's AUC over ~33 held-out tracks moves by 0.05-0.1 between splits; the
mean over seeds is what the README's choices rest on.

Run: python benchmarks/detection_quality.py [--seeds 0,1,2] [--data kitimat] [--episodes 60]
     [--detectors dati,nearest,bc] [--kinds detour,jump,loiter] [--lane KEY=VALUE ...]
     [--out runs/quality]
Not part of the test suite: DATI's training dominates (4-6 minutes per seed for the two Kitimat
routes on 2 cores). A seed whose `<out>/<data>/seed<k>/evaluation.json` exists is read, not
rerun, so an interrupted run goes on where it stopped (delete the folder to rerun a seed).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
SETS = {
    "kitimat": (DATA / "AIS_2018_07-08_Kitimat.csv.gz", "100"),
    "nyharbor": (DATA / "NYHarbor_2020_12_first_week_points.csv.gz", "10"),
}


def aisdati(*args: str) -> None:
    cmd = [sys.executable, "-m", "aisdati.cli", *args]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def run_seed(data: Path, out: Path, seed: int, args: argparse.Namespace) -> dict:
    if not (out / "evaluation.json").is_file():
        lanes = [x for kv in args.lane for x in ("--lane", kv)]
        aisdati(
            "evaluate",
            "--data",
            str(data),
            "--cluster",
            "routes",
            "--detectors",
            args.detectors,
            "--kinds",
            args.kinds,
            "--episodes",
            str(args.episodes),
            "--seed",
            str(seed),
            "--out",
            str(out),
            "--quiet",
            *lanes,
        )
    return json.loads((out / "evaluation.json").read_text())


def aucs(results: list[dict]) -> dict[tuple[str, str], float]:
    return {(r["detector"], r["score"]): r["roc_auc"] for r in results if r["kind"] == "all"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2", help="comma-separated seeds")
    ap.add_argument("--data", default="kitimat", choices=sorted(SETS))
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--detectors", default="dati,nearest,bc")
    ap.add_argument("--kinds", default="detour,jump,loiter")
    ap.add_argument("--lane", action="append", default=[], help="KEY=VALUE for DATI")
    ap.add_argument("--out", type=Path, default=Path("runs/quality"))
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    path, min_points = SETS[args.data]
    data = args.out / args.data / "processed"
    if not (data / "tracks.parquet").is_file():
        aisdati(
            "ingest",
            "--input",
            str(path),
            "--roi",
            "none",
            "--min-points",
            min_points,
            "--out",
            str(data),
            "--quiet",
        )
    pooled: dict[tuple[str, str], list[float]] = {}
    per_route: dict[tuple[str, str], dict[str, list[float]]] = {}
    for seed in seeds:
        out = args.out / args.data / f"seed{seed}"
        doc = run_seed(data, out, seed, args)
        for key, auc in aucs(doc["results"]).items():
            pooled.setdefault(key, []).append(auc)
        for route in doc["routes"]:
            route_doc = json.loads((out / route / "evaluation.json").read_text())
            for key, auc in aucs(route_doc["results"]).items():
                per_route.setdefault(key, {}).setdefault(route, []).append(auc)
    routes = sorted({r for v in per_route.values() for r in v})
    print(
        f"ROC AUC of {args.kinds} on {args.data}, every route pooled, seeds {args.seeds}"
        + (f", DATI with {' '.join(args.lane)}" if args.lane else "")
    )
    print(
        "| detector | score | "
        + " | ".join(f"seed {s}" for s in seeds)
        + " | mean ± sd | "
        + " | ".join(f"{r} mean" for r in routes)
        + " |"
    )
    print("|---" * (3 + len(seeds) + len(routes)) + "|")
    for (det, score), values in pooled.items():
        v = np.array(values, float)
        sd = v.std(ddof=1) if len(v) > 1 else 0.0
        cells = [f"{x:.3f}" for x in v] + [f"{v.mean():.3f} ± {sd:.3f}"]
        cells += [f"{np.mean(per_route[(det, score)].get(r, [np.nan])):.3f}" for r in routes]
        print(f"| {det} | {'dtw' if score == 'nearest' else score} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
