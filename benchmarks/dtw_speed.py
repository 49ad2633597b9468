"""Cost of the DTW reward over a whole episode: incremental exact DTW against recomputation.

The reward needs the DTW between the imitated and the expert prefixes at every step. Three ways:
  (a) `IncrementalDTW`, one push per step (O(t) per step);
  (b) `fastdtw.fastdtw` recomputed on the prefixes at every step, as the paper's official code does;
  (c) exact `dtw` recomputed on the prefixes at every step (O(t²) per step).
Where recomputation would take too long, only every k-th step is timed and the episode total is
extrapolated (each timed step stands for the k steps around it); the table says so.

Run: python benchmarks/dtw_speed.py [--json PATH]   (not part of the test suite; prints a table,
its rows as JSON in benchmarks/results/dtw_speed.json)
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from fastdtw import fastdtw
from haversine import Unit, haversine
from report import Report, add_json_option  # (this folder: run as a script)
from scipy.spatial.distance import euclidean

from aisdati.dtw import IncrementalDTW, dtw

SEED = 0


def random_walk(rng: np.random.Generator, n: int, start: tuple[float, float], step: float):
    return np.asarray(start) + np.cumsum(rng.normal(0.0, step, size=(n, 2)), axis=0)


def haversine_lonlat(p, q) -> float:
    """Great-circle metres between (lon, lat) points via the `haversine` package (lat, lon)."""
    return haversine((p[1], p[0]), (q[1], q[0]), unit=Unit.METERS)


def time_incremental(a: np.ndarray, b: np.ndarray, metric: str, repeats: int = 5) -> float:
    """Best-of-`repeats` seconds to push a whole episode into `IncrementalDTW`."""
    best = np.inf
    for _ in range(repeats):
        inc = IncrementalDTW(metric=metric)
        start = time.perf_counter()
        for t in range(len(a)):
            inc.push(a[t], b[t])
        best = min(best, time.perf_counter() - start)
    return best


def time_per_step(step: Callable[[int], object], n: int, stride: int) -> float:
    """Seconds for calling `step(t)` at every step t = 1..n, timing every `stride`-th step only."""
    total = 0.0
    for t in range(max(stride // 2, 1), n + 1, stride):
        start = time.perf_counter()
        step(t)
        total += (time.perf_counter() - start) * stride
    return total


def bench_case(name: str, a, b, metric: str, fast_dist, fast_stride: int, exact_stride: int):
    n = len(a)
    dtw(a[:2], b[:2], metric=metric)  # compile outside the timings
    t_inc = time_incremental(a, b, metric)
    t_fast = time_per_step(lambda t: fastdtw(a[:t], b[:t], dist=fast_dist), n, fast_stride)
    t_exact = time_per_step(lambda t: dtw(a[:t], b[:t], metric=metric), n, exact_stride)

    def note(stride: int) -> str:
        if stride == 1:
            return f"all {n} steps timed"
        timed = len(range(max(stride // 2, 1), n + 1, stride))
        return f"extrapolated from {timed} of {n} steps"

    return [
        (name, "(a) IncrementalDTW, 1 push/step", t_inc, 1.0, f"all {n} steps, best of 5"),
        (name, "(b) fastdtw on prefixes/step", t_fast, t_fast / t_inc, note(fast_stride)),
        (name, "(c) exact dtw on prefixes/step", t_exact, t_exact / t_inc, note(exact_stride)),
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_json_option(ap, "dtw_speed")
    args = ap.parse_args()
    rng = np.random.default_rng(SEED)
    a, b = random_walk(rng, 900, (0.0, 0.0), 1.0), random_walk(rng, 900, (0.0, 0.0), 1.0)
    rows = bench_case("euclidean, 900 steps", a, b, "euclidean", euclidean, 30, 1)
    lon_lat = (18.0, 57.0)
    a, b = random_walk(rng, 1500, lon_lat, 0.002), random_walk(rng, 1500, lon_lat, 0.002)
    rows += bench_case("haversine, 1500 steps", a, b, "haversine", haversine_lonlat, 75, 15)
    with Report.from_args("dtw_speed", args) as report:
        headers = ("case", "method", "s / episode", "(a) speed-up", "note")
        justify = ["right" if k in (2, 3) else "left" for k in range(len(headers))]
        table = report.table(
            headers, title="DTW reward cost per episode", style="rich", justify=justify, width=140
        )
        for c, m, sec, x, note in rows:
            values = {"case": c, "method": m, "seconds": sec, "speed_up": x, "note": note}
            table.row((c, m, f"{sec:.4g}", f"{x:,.0f}x", note), values)
        table.show()
        t_inc, t_fast = rows[0][2], rows[1][2]
        verdict = "meets" if t_fast / t_inc >= 1000 else "MISSES"
        report.say(
            f"euclidean: (a) is {t_fast / t_inc:,.0f}x faster than (b); {verdict} the 1000x target"
        )


if __name__ == "__main__":
    main()
