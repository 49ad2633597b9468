"""Speed of route clustering against the number of tracks (not a test). Target: linear growth,
1,000,000 tracks in at most 2 minutes on 2 cores.

The tracks are synthesised from the real ones of tests/data: both samples are ingested with the
defaults (Kitimat: tracks of at least 100 reports; NY Harbor: at least 10, so that ferry crossings
count), then each synthetic track copies a real track picked at random, keeps a random 70-100% of
its reports (so lengths and report counts vary), moves the whole track by a random offset
(σ = 150 m) and every report by noise (σ = 50 m). So the busy lanes and crossings of the real data
are there, thickened, at the scale of a month to years of a busy area. The sets are nested (the
first n tracks of the largest), so each row adds tracks to the same traffic.

The first call compiles the kernels (numba caches them on disk); a warm-up on 200 tracks runs
first, then one timed run per size.

Usage: python benchmarks/routes_speed.py [--tracks 10000,100000,1000000] [--seed 0] [--json PATH]
Prints a markdown table, its rows as JSON in benchmarks/results/routes_speed.json.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.routes import RouteSettings, cluster_routes, lines_from_wkb
from aisdati.preprocess.settings import IngestSettings

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = {
    "AIS_2018_07-08_Kitimat.csv.gz": 100,
    "NYHarbor_2020_12_first_week_points.csv.gz": 10,
}
M_PER_DEG = 111_195.0


def real_tracks(work: Path) -> tuple[list[np.ndarray], list[float]]:
    lines: list[np.ndarray] = []
    lengths: list[float] = []
    for name, min_points in SAMPLES.items():
        out = work / name.split(".")[0]
        settings = IngestSettings(min_points=min_points, clusters="direction")
        ingest([ROOT / "tests" / "data" / name], out, settings, None, "none")
        table = pq.read_table(out / "tracks.parquet", columns=["geometry", "length_km"])
        lines += lines_from_wkb(table.column("geometry").to_pylist())
        lengths += table.column("length_km").to_pylist()
    return lines, lengths


def synthesise(
    lines: list[np.ndarray], lengths: list[float], n: int, rng: np.random.Generator
) -> tuple[list[np.ndarray], np.ndarray]:
    out, out_len = [], []
    for i in rng.integers(0, len(lines), n):
        xy = lines[i]
        keep = np.sort(rng.choice(len(xy), max(2, int(len(xy) * rng.uniform(0.7, 1.0))), False))
        keep[0], keep[-1] = 0, len(xy) - 1
        xy = xy[np.unique(keep)]
        scale = np.array([1.0 / np.cos(np.radians(xy[:, 1].mean())), 1.0]) / M_PER_DEG
        moved = xy + rng.normal(0, 150.0, 2) * scale + rng.normal(0, 50.0, xy.shape) * scale
        out.append(moved)
        out_len.append(lengths[i])
    return out, np.array(out_len)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", default="10000,100000,1000000", help="comma-separated sizes")
    parser.add_argument("--seed", type=int, default=0)
    add_json_option(parser, "routes_speed")
    args = parser.parse_args()
    sizes = sorted(int(n) for n in args.tracks.split(","))
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        lines, lengths = real_tracks(Path(tmp))
    tracks, length_km = synthesise(lines, lengths, sizes[-1], rng)
    ids = np.arange(len(tracks))
    settings = RouteSettings(seed=args.seed)
    warm = time.perf_counter()
    cluster_routes(tracks[:200], ids[:200], length_km[:200], settings)
    warm = time.perf_counter() - warm
    with Report.from_args("routes_speed", args) as report:
        report.say(
            f"route clustering of up to {sizes[-1]:,} tracks synthesised from {len(lines)} real "
            f"tracks; {os.cpu_count()} CPUs; warm-up (200 tracks, compiles on first use) "
            f"{warm:.1f} s\n"
        )
        cols = ["tracks", "points", "resample", "endpoints", "split", "merge", "describe",
                "total", "s per 100k tracks", "routes", "routed tracks"]  # fmt: skip
        table = report.table(cols, title="Route clustering")
        for n in sizes:
            start = time.perf_counter()
            routes = cluster_routes(tracks[:n], ids[:n], length_km[:n], settings)
            total = time.perf_counter() - start
            s = routes.seconds
            routed = int(sum(label is not None for label in routes.labels))
            points = sum(len(t) for t in tracks[:n])
            row = [f"{n:,}", f"{points:,}"]
            row += [f"{s[k]:.1f} s" for k in cols[2:7]]
            row += [f"**{total:.1f} s**", f"{total / n * 1e5:.1f}", str(len(routes.table))]
            row += [f"{routed:,}"]
            values = {"tracks": n, "points": points, **{f"{k}_s": s[k] for k in cols[2:7]}}
            values |= {"total_s": total, "routes": len(routes.table), "routed_tracks": routed}
            table.row(row, values)


if __name__ == "__main__":
    main()
