"""Speed of DATI on AIS at the paper's scale: training steps per second on 900-step episodes, and
rollout + scoring time for 143 test tracks of 900-1500 points with K rollouts each.

The tracks are synthetic but AIS-like (Florida Straits, ~12 kn, reports every 2-60 s, a slowly
turning course), since speed does not depend on where the ships go; the machinery is exactly the
one `aisdati train` / `aisdati detect --score rollout` run (AISTrackSource + DATITrainer,
`AISPolicy.generate` + `batch_mean_dtw_m`). Training is timed after a short warm-up; scoring
uses an untrained model (the cost does not depend on the weights).

Run: python benchmarks/ais_speed.py [--train-steps 300] [--tracks 143] [--rollouts 10]
[--json PATH]
(not part of the test suite; prints a markdown table, its rows as JSON in
benchmarks/results/ais_speed.json).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.ais.policy import AISPolicy, dati_act, track_keys
from aisdati.ais.source import build_source, make_env
from aisdati.ais.space import LaneConfig
from aisdati.dtw import batch_mean_dtw_m
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.networks import DATINetworks
from aisdati.tracks.store import Track


def synthetic_track(rng: np.random.Generator, n: int, track_id: int) -> Track:
    dt = rng.uniform(2, 60, n - 1) / 3600.0
    cog = np.radians(60 + np.cumsum(rng.normal(0, 1.5, n - 1)))
    sog = 12 + rng.normal(0, 0.5, n - 1)
    lat = np.empty(n)
    lon = np.empty(n)
    lon[0], lat[0] = -82.9 + rng.uniform(0, 0.1), 23.6 + rng.uniform(0, 0.6)
    for i in range(n - 1):
        lat[i + 1] = lat[i] + np.cos(cog[i]) * sog[i] * dt[i] / 60
        lon[i + 1] = lon[i] + np.sin(cog[i]) * sog[i] * dt[i] / 60 / np.cos(np.radians(lat[i]))
    return Track(track_id, 366000000 + track_id, None, np.stack([lon, lat], 1), dt, "up")


def bench_training(steps: int, seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    tracks = [synthetic_track(rng, 901, i) for i in range(4)]
    torch.set_num_threads(1)
    env = make_env(build_source(tracks, LaneConfig()))
    trainer = DATITrainer([env], [seed], DATIConfig(episodes=10))
    for _ in range(20):
        trainer.step()
    t0 = time.perf_counter()
    for _ in range(steps):
        trainer.step()
    wall = time.perf_counter() - t0
    return {"steps": steps, "seconds": wall, "steps_per_s": steps / wall}


def bench_scoring(n_tracks: int, rollouts: int, seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    tracks = [synthetic_track(rng, int(rng.integers(900, 1501)), i) for i in range(n_tracks)]
    source = build_source(tracks, LaneConfig())
    cfg = DATIConfig()
    policy = AISPolicy(source.space, dati_act(DATINetworks(2, 3, cfg.network, [seed]), cfg))
    starts = np.array([t.positions[0] for t in tracks])
    horizons = np.array([t.steps for t in tracks])
    batch_mean_dtw_m(np.zeros((1, 2, 2)), np.array([2]), [np.zeros((2, 2))], np.array([0]))
    t0 = time.perf_counter()
    keys = track_keys([t.positions for t in tracks], seed)
    paths = policy.generate(starts, horizons, keys, range(rollouts))
    t1 = time.perf_counter()
    batch_mean_dtw_m(
        paths,
        np.repeat(horizons + 1, rollouts),
        [t.positions for t in tracks],
        np.repeat(np.arange(n_tracks), rollouts),
    )
    t2 = time.perf_counter()
    cells = float(sum(len(t.positions) ** 2 for t in tracks)) * rollouts  # ~ n x m per pair
    return {"rollout_s": t1 - t0, "dtw_s": t2 - t1, "total_s": t2 - t0, "cells": cells}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train-steps", type=int, default=300)
    ap.add_argument("--tracks", type=int, default=143)
    ap.add_argument("--rollouts", type=int, default=10)
    add_json_option(ap, "ais_speed")
    args = ap.parse_args()
    tr = bench_training(args.train_steps)
    sc = bench_scoring(args.tracks, args.rollouts)
    per_episode = 900 / tr["steps_per_s"]
    with Report.from_args("ais_speed", args) as report:
        report.say(f"AIS speed on {os.cpu_count()} CPU cores, torch {torch.__version__}\n")
        table = report.table(["measure", "value"], title="AIS speed")
        table.row(
            ["training steps/s (E = 1, 900-step episodes)", f"{tr['steps_per_s']:.1f}"],
            {"steps_per_s": tr["steps_per_s"], "steps": tr["steps"], "seconds": tr["seconds"]},
        )
        table.row(["one 900-step episode", f"{per_episode:.0f} s"], {"seconds": per_episode})
        table.row(
            ["paper's budget, 170 episodes", f"{170 * per_episode / 3600:.1f} h"],
            {"hours": 170 * per_episode / 3600},
        )
        table.row(
            [
                f"rollouts: {args.tracks} tracks x K = {args.rollouts}, 900-1500 points",
                f"{sc['rollout_s']:.1f} s",
            ],
            {"seconds": sc["rollout_s"], "tracks": args.tracks, "rollouts": args.rollouts},
        )
        gcells = sc["cells"] / 1e9
        table.row(
            [f"great-circle DTW of all pairs ({gcells:.2f} G cells)", f"{sc['dtw_s']:.1f} s"],
            {"seconds": sc["dtw_s"], "cells": sc["cells"]},
        )
        table.row(
            ["rollout + scoring total (target < 30 s)", f"{sc['total_s']:.1f} s"],
            {"seconds": sc["total_s"], "target_s": 30},
        )


if __name__ == "__main__":
    main()
