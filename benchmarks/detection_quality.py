"""Detection quality of the three detectors on the real data shipped with the project: runs
`aisdati evaluate` (dati, nearest, bc; all six anomaly kinds) on the Kitimat lanes (route-1 and
route-2, one per direction) and on the busiest New York Harbor ferry route, for one or more seeds,
and prints one markdown table of ROC AUC per detector, score and kind.

Run: python benchmarks/detection_quality.py [--seeds 1] [--episodes 60] [--out runs/quality]
(not part of the test suite; DATI's training dominates: several minutes per route and seed on
2 cores). The README's tables come from single runs of the same `aisdati evaluate` command.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
SETS = {
    "kitimat": (DATA / "AIS_2018_07-08_Kitimat.csv.gz", "100", ("route-1", "route-2")),
    "nyharbor": (DATA / "NYHarbor_2020_12_first_week_points.csv.gz", "10", ("route-1",)),
}


def aisdati(*args: str) -> None:
    cmd = [sys.executable, "-m", "aisdati.cli", *args]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--episodes", type=int, default=60)
    ap.add_argument("--out", type=Path, default=Path("runs/quality"))
    args = ap.parse_args()
    rows = []
    for name, (path, min_points, routes) in SETS.items():
        data = args.out / name / "processed"
        if not (data / "tracks.parquet").is_file():
            aisdati("ingest", "--input", str(path), "--roi", "none", "--min-points", min_points,
                    "--out", str(data), "--quiet")
        for route in routes:
            for seed in range(args.seeds):
                out = args.out / name / f"{route}-seed{seed}"
                aisdati("evaluate", "--data", str(data), "--cluster", route, "--detectors",
                        "dati,nearest,bc", "--episodes", str(args.episodes), "--seed", str(seed),
                        "--out", str(out), "--quiet")
                doc = json.loads((out / "evaluation.json").read_text())
                for r in doc["results"]:
                    rows.append((name, route, seed, r))
    kinds = list(dict.fromkeys(r["kind"] for *_, r in rows))
    print("| data | route | seed | detector | score | " + " | ".join(kinds) + " |")
    print("|---" * (5 + len(kinds)) + "|")
    groups: dict[tuple, dict[str, float | None]] = {}
    for name, route, seed, r in rows:
        groups.setdefault((name, route, seed, r["detector"], r["score"]), {})[r["kind"]] = r[
            "roc_auc"
        ]
    for key, aucs in groups.items():
        cells = ["-" if aucs.get(k) is None else f"{aucs[k]:.3f}" for k in kinds]
        print("| " + " | ".join(str(k) for k in key) + " | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
