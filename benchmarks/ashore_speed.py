"""Speed of the ashore rule (`aisdati.tracks.ashore`), which `detect` and `evaluate` run for every
judged report (as tasks of `aisdati.tracks.ashore.ASHORE_TRACKS` tracks: on the Dask workers
with `--workers`). One core, not a test.

Takes the real reports shipped in tests/data (Kitimat July-August 2018, NY Harbor's first week
of December 2020), repeated to each size asked for, and times `AshoreCheck.counts` on them as
tracks of 100 reports, without and with the water a model's training traffic sailed (`seen`:
the places the first tracks report ashore). The first call in a 1-degree tile clips the land
there (`aisdati.coastline`), so each area is warmed up once before timing.

Run: python benchmarks/ashore_speed.py [--sizes 100000,1000000,10000000] [--json PATH]
(prints a markdown table, its rows as JSON in benchmarks/results/ashore_speed.json)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.tracks.ashore import AshoreCheck

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
AREAS = {
    "Kitimat": DATA / "AIS_2018_07-08_Kitimat.csv.gz",
    "NY Harbor": DATA / "NYHarbor_2020_12_first_week_points.csv.gz",
}
TRACK = 100
"""Reports per track."""


def reports(path: Path) -> np.ndarray:
    frame = pd.read_csv(path, usecols=["LON", "LAT"])
    return frame[["LON", "LAT"]].to_numpy(np.float64)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100000,1000000,10000000")
    add_json_option(ap, "ashore_speed")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    rule = AshoreCheck()
    with Report.from_args("ashore_speed", args) as report:
        columns = ["area", "reports", "ashore", "without seen water", "with it (points)"]
        table = report.table(columns, title="Ashore rule speed")
        for area, path in AREAS.items():
            base = reports(path)
            seen = np.asarray(rule.seen([base[: 20 * TRACK]]), np.float64).reshape(-1, 2)
            rule.counts([base[:TRACK]])  # clip this area's tiles once
            for n in sizes:
                points = np.resize(base, (n, 2))
                tracks = np.split(points, np.arange(TRACK, n, TRACK))
                t0 = time.perf_counter()
                counts = rule.counts(tracks)
                plain = time.perf_counter() - t0
                t0 = time.perf_counter()
                rule.counts(tracks, seen)
                excused = time.perf_counter() - t0
                rate = n / plain / 1e6
                ashore = int(counts.sum())
                table.row(
                    [area, f"{n:,}", f"{ashore:,}", f"{plain:.2f} s ({rate:.2f} M/s)",
                     f"{excused:.2f} s ({len(seen)})"],
                    {"area": area, "reports": n, "ashore": ashore, "plain_s": plain,
                     "reports_per_s": n / plain, "seen_s": excused, "seen_points": len(seen)},
                )  # fmt: skip


if __name__ == "__main__":
    main()
