"""Speed of scoring at the issue's scale: teacher-forced step scoring of 1,000 tracks of 500 reports
with K = 10 draws (target <= 20 s on 2 cores), lane scoring of the same tracks (30 free rollouts,
`ScoreSettings.lane_rollouts`, of twice the track's steps; the best of the first K = 10 by DTW
for the map; each report's distance to the lane), and the exact nearest-track search of 1,000
test tracks among 1,000 training tracks of 500 points (target <= 60 s on 2 cores).

The tracks are synthetic lanes (a few shared routes, each track jittered around its route, ~12 kn,
3-minute reports), so that many training tracks start near every test track, as in real traffic;
speed does not depend on where the ships are. Step scoring uses an untrained DATI actor (its cost
does not depend on the weights), with the default lane model's number of members.

Run: python benchmarks/detection_speed.py [--tracks 1000] [--points 500] [--draws 10]
(not part of the test suite; prints a markdown table).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from aisdati.ais import DEFAULT_PRESET
from aisdati.ais.policy import AISPolicy, dati_act
from aisdati.ais.source import build_source
from aisdati.ais.space import PRESETS, LaneConfig
from aisdati.detectors.nearest import NearestDetector
from aisdati.detectors.scoring import ScoreSettings, tail_mean
from aisdati.geo import lane_distances
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks
from aisdati.tracks.store import Track


def lanes(rng: np.random.Generator, n_tracks: int, points: int, routes: int = 5) -> list[Track]:
    out = []
    heads = rng.uniform(0, 360, routes)
    for i in range(n_tracks):
        r = i % routes
        dt = np.full(points - 1, 0.05)
        cog = np.radians(heads[r] + 20 * np.sin(np.linspace(0, 3, points - 1)) + rng.normal(0, 2))
        step = 12 * dt / 60
        lat = 53.0 + np.r_[0, np.cumsum(np.cos(cog) * step)] + rng.normal(0, 0.003)
        lon = -129.0 + np.r_[0, np.cumsum(np.sin(cog) * step)] / np.cos(np.radians(53.0))
        lon = lon + rng.normal(0, 0.004)
        out.append(Track(i, 100000000 + i, None, np.stack([lon, lat], 1), dt, "other"))
    return out


def untrained_policy(tracks: list[Track]) -> AISPolicy:
    """An untrained actor with as many members as the default lane model (its draws spread over
    them, each member computing its own rows)."""
    source = build_source(tracks[:50], LaneConfig())
    cfg = DATIConfig()
    seeds = list(range(PRESETS[DEFAULT_PRESET].members))
    return AISPolicy(source.space, dati_act(DATINetworks(2, 3, cfg.network, seeds), cfg))


def bench_lane(tracks: list[Track], rollouts: int) -> float:
    policy = untrained_policy(tracks)
    how = ScoreSettings(score="lane", rollouts=rollouts)
    positions = [t.positions for t in tracks]
    policy.rollout_scores(positions[:2], rollouts, 0, how.lane_reach)  # compile
    t0 = time.perf_counter()
    _, _, every = policy.rollout_scores(positions, rollouts, 0, how.lane_reach, how.lane_rollouts)
    [
        tail_mean(lane_distances(p, list(e), how.lane_course_km * 1000.0), how.tail)
        for p, e in zip(positions, every, strict=True)
    ]
    return time.perf_counter() - t0


def bench_step(tracks: list[Track], draws: int) -> float:
    policy = untrained_policy(tracks)
    policy.step_errors([t.positions for t in tracks[:2]], [t.dts for t in tracks[:2]], draws)
    t0 = time.perf_counter()
    errors, _ = policy.step_errors([t.positions for t in tracks], [t.dts for t in tracks], draws)
    [tail_mean(e, ScoreSettings().tail) for e in errors]
    return time.perf_counter() - t0


def bench_nearest(train: list[Track], test: list[Track]) -> tuple[float, float]:
    det = NearestDetector()  # the search alone: the tracks, without fitting (calibration)
    det.tracks, det.mmsi = [t.positions for t in train], np.array([t.mmsi for t in train])
    det.search([t.positions for t in test[:2]], 10.0)  # compile
    t0 = time.perf_counter()
    dist, _ = det.search([t.positions for t in test], ScoreSettings().near_km)
    return time.perf_counter() - t0, float(np.median(dist))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", type=int, default=1000)
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--draws", type=int, default=10)
    args = ap.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    test = lanes(rng, args.tracks, args.points)
    train = lanes(rng, args.tracks, args.points)
    step_s = bench_step(test, args.draws)
    lane_s = bench_lane(test, args.draws)
    near_s, med = bench_nearest(train, test)
    n, p = args.tracks, args.points
    print(f"Detection speed on {os.cpu_count()} CPU cores, torch {torch.__version__}\n")
    print("| what | measured | target |")
    print("|---|---|---|")
    k = args.draws
    print(f"| step scoring: {n} tracks x {p} reports, K = {k} | {step_s:.1f} s | <= 20 s |")
    print(
        f"| lane scoring: {n} tracks x {p} reports, {ScoreSettings().lane_rollouts} rollouts "
        f"of 2x the steps (best of the first K = {k}) | "
        f"{lane_s:.1f} s | |"
    )
    print(
        f"| nearest: {n} test x {n} training tracks of {p} points (exact, pruned; median "
        f"distance {med:,.0f} m) | {near_s:.1f} s | <= 60 s |"
    )


if __name__ == "__main__":
    main()
