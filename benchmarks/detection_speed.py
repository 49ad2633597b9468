"""Speed of scoring at the issue's scale: teacher-forced step scoring of 1,000 tracks of 500 reports
with K = 10 draws (target <= 20 s on 2 cores), the area default's score (cross-fitted BC by
`stepspread`, member by member) of the same tracks, lane scoring of the same tracks (30 free
rollouts, `ScoreSettings.lane_rollouts`, of twice the track's steps; the best of the first
K = 10 by DTW for the map; each report's distance to the lane), and the exact nearest-track
search of 1,000 test tracks among 1,000 training tracks of 500 points (target <= 60 s on 2
cores).

The tracks are synthetic lanes (a few shared routes, each track jittered around its route, ~12 kn,
3-minute reports), so that many training tracks start near every test track, as in real traffic;
speed does not depend on where the ships are. Step scoring uses an untrained DATI actor (its cost
does not depend on the weights), with the default lane model's number of members.

The "Scoring at scale" table times the `nearest` detector's two searches against 1,000 training
tracks, as `NearestDetector.search` and `lane_scores` run them: the exact DTW search and each
report's course-weighed distance to the candidates' lane. "Before" is the brute force (every
pair's full DTW; a fresh k-d tree of every candidate point per track, as `lane_distances` was),
measured on the first `--before` test tracks and extrapolated linearly to all of them (both
cost the same per test track).

The events row times the model-free event finders on the test tracks' reports (reported
motion as the positions show it; the target: detect with events within 2x the area default's
time).

Run: python benchmarks/detection_speed.py [--tracks 1000] [--points 500] [--draws 10]
[--before 20] [--only-scale] [--json PATH] (not part of the test suite; prints markdown tables,
their rows as JSON in benchmarks/results/detection_speed.json).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pandas as pd
import torch
from report import Report, add_json_option  # (this folder: run as a script)
from scipy.spatial import cKDTree

from aisdati.ais import AREA_PRESET, DEFAULT_PRESET
from aisdati.ais.policy import AISPolicy, dati_act
from aisdati.ais.source import build_source
from aisdati.ais.space import PRESETS, LaneConfig
from aisdati.ais.training import TrainSettings
from aisdati.detection.events import model_free_events
from aisdati.detectors.bc import BCDetector
from aisdati.detectors.nearest import NearestDetector
from aisdati.detectors.scoring import ScoreSettings, tail_mean
from aisdati.detectors.traffic import Traffic
from aisdati.dtw import batch_mean_dtw_m
from aisdati.geo import (
    EARTH_RADIUS_M,
    courses_deg,
    lane_distances,
    spherical_decision,
    unit_vectors,
)
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks
from aisdati.tracks.store import Track

ROUTE = "up"
"""The tracks' cluster: a route's, so candidates start within near_km of the track's start."""


def lanes(rng: np.random.Generator, n_tracks: int, points: int, heads: np.ndarray) -> list[Track]:
    """Tracks along the routes that leave (-129, 53) on the courses `heads` (test and training
    tracks share them, as a detector's test tracks share its training tracks' lanes)."""
    out = []
    for i in range(n_tracks):
        r = i % len(heads)
        dt = np.full(points - 1, 0.05)
        cog = np.radians(heads[r] + 20 * np.sin(np.linspace(0, 3, points - 1)) + rng.normal(0, 2))
        step = 12 * dt / 60
        lat = 53.0 + np.r_[0, np.cumsum(np.cos(cog) * step)] + rng.normal(0, 0.003)
        lon = -129.0 + np.r_[0, np.cumsum(np.sin(cog) * step)] / np.cos(np.radians(53.0))
        lon = lon + rng.normal(0, 0.004)
        out.append(Track(i, 100000000 + i, None, np.stack([lon, lat], 1), dt, "other"))
    return out


def bench_events(tracks: list[Track]) -> float:
    """Seconds to find the model-free events of every track's reports, as `detect` does
    (`aisdati.detection.events.model_free_events`): reported SOG and COG those the positions
    show, times from the tracks' steps, one vessel per track."""
    rows = []
    for t in tracks:
        hours = np.r_[0.0, np.cumsum(t.dts)]
        sog, cog = spherical_decision(*t.positions[:-1].T, *t.positions[1:].T, t.dts)
        rows.append(
            pd.DataFrame({
                "mmsi": t.mmsi, "track_id": t.track_id, "lon": t.positions[:, 0],
                "lat": t.positions[:, 1], "sog": np.r_[sog, sog[-1]], "cog": np.r_[cog, cog[-1]],
                "time": pd.Timestamp("2020-01-01", tz="UTC") + pd.to_timedelta(hours, unit="h"),
            })
        )  # fmt: skip
    reports = pd.concat(rows, ignore_index=True)
    t0 = time.perf_counter()
    model_free_events(reports, read_vessels_none())
    return time.perf_counter() - t0


def read_vessels_none() -> pd.DataFrame:
    """No vessel identities (as an ingest output without vessels.parquet)."""
    return pd.DataFrame(columns=["name", "ship_type", "length_m"], index=pd.Index([], name="mmsi"))


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


def bench_area(train: list[Track], test: list[Track], draws: int) -> float:
    """The area's default score: cross-fitted BC (the area preset's members) judged by
    `stepspread`, member by member, as `detect` runs it (`PolicyDetector.score_tracks`). BC is
    fitted for a few episodes to 30 training tracks: scoring's cost does not depend on the
    weights."""
    lane = PRESETS[AREA_PRESET]
    settings = TrainSettings(cluster="all", episodes=5, lane=lane, preset=AREA_PRESET)
    how = ScoreSettings(score="stepspread", rollouts=draws)
    det = BCDetector(settings, how).fit(train[:30])
    det.score_tracks(test[:2], how, ())  # compile
    t0 = time.perf_counter()
    det.score_tracks(test, how, ())
    return time.perf_counter() - t0


def bench_nearest(train: list[Track], test: list[Track]) -> tuple[float, float]:
    det = NearestDetector()  # the search alone: the tracks, without fitting (calibration)
    det.training_tracks = Traffic.of(train, ROUTE)
    det.search([t.positions for t in test[:2]], 10.0)  # compile
    t0 = time.perf_counter()
    dist, _ = det.search([t.positions for t in test], ScoreSettings().near_km)
    return time.perf_counter() - t0, float(np.median(dist))


def brute_nearest(train: list[Track], test: list[Track]) -> float:
    """Every candidate's full DTW (the plain per-pair kernel, no bounds or abandoning)."""
    traffic = Traffic.of(train, ROUTE)
    cands = traffic.candidates([t.positions for t in test], ScoreSettings().near_km)
    batch_mean_dtw_m(test[0].positions[None], [2], traffic.tracks[:1], [0])  # compile
    t0 = time.perf_counter()
    for t, c in zip(test, cands, strict=True):
        p = t.positions
        n = np.full(len(c), len(p))
        batch_mean_dtw_m(np.repeat(p[None], len(c), 0), n, traffic.tracks, c)
    return time.perf_counter() - t0


def brute_lane(train: list[Track], test: list[Track], course_m: float) -> float:
    """A fresh k-d tree of every candidate point per test track, queried for the nearest."""
    traffic = Traffic.of(train, ROUTE)
    cands = traffic.candidates([t.positions for t in test], ScoreSettings().near_km)
    t0 = time.perf_counter()
    for t, c in zip(test, cands, strict=True):
        lane = [traffic.tracks[j] for j in c]
        cKDTree(keys(lane, course_m)).query(keys([t.positions], course_m))
    return time.perf_counter() - t0


def keys(polylines: list[np.ndarray], course_m: float) -> np.ndarray:
    """The k-d tree's coordinates: unit vectors in metres and course vectors x course_m / 2."""
    theta = np.radians(np.concatenate([courses_deg(p) for p in polylines]))
    course = course_m / 2 * np.column_stack([np.cos(theta), np.sin(theta)])
    return np.hstack([EARTH_RADIUS_M * unit_vectors(np.concatenate(polylines)), course])


def bench_scale(train: list[Track], test: list[Track], before: int, report: Report) -> None:
    """The "Scoring at scale" table: both searches of all test tracks, after and before."""
    how = ScoreSettings(score="lane")
    det = NearestDetector()
    det.training_tracks = Traffic.of(train, ROUTE)
    positions = [t.positions for t in test]
    det.search(positions[:2], how.near_km)  # compile
    t0 = time.perf_counter()
    det.search(positions, how.near_km)
    near_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    det.training_tracks.lane_scores(positions, how)
    lane_s = time.perf_counter() - t0
    scale = len(test) / before
    old_near = brute_nearest(train, test[:before]) * scale
    old_lane = brute_lane(train, test[:before], how.lane_course_km * 1000.0) * scale
    n, m, p = len(test), len(train), len(test[0].positions)
    report.say(f"\nScoring at scale on {os.cpu_count()} CPU cores ({p} reports a track; before:")
    report.say(f"measured on {before} test tracks and extrapolated to {n})\n")
    columns = ["test x training tracks", "nearest before", "nearest after", "lane before"]
    table = report.table([*columns, "lane after"], title="Scoring at scale")
    table.row(
        [f"{n:,} x {m:,}", f"{old_near:,.0f} s (extrapolated)", f"{near_s:.1f} s",
         f"{old_lane:,.0f} s (extrapolated)", f"{lane_s:.1f} s"],
        {"test_tracks": n, "training_tracks": m, "reports_per_track": p,
         "before_measured_on": before, "nearest_before_s": old_near, "nearest_after_s": near_s,
         "lane_before_s": old_lane, "lane_after_s": lane_s},
    )  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tracks", type=int, default=1000)
    ap.add_argument("--points", type=int, default=500)
    ap.add_argument("--draws", type=int, default=10)
    ap.add_argument("--before", type=int, default=20, help="test tracks the brute force scores")
    ap.add_argument("--only-scale", action="store_true", help="only the Scoring at scale table")
    add_json_option(ap, "detection_speed")
    args = ap.parse_args()
    if min(args.tracks, args.points, args.draws, args.before) < 1:
        ap.error("--tracks, --points, --draws and --before must be at least 1")
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    heads = rng.uniform(0, 360, 5)
    test = lanes(rng, args.tracks, args.points, heads)
    train = lanes(rng, args.tracks, args.points, heads)
    with Report.from_args("detection_speed", args) as report:
        bench_scale(train, test, min(args.before, args.tracks), report)
        if not args.only_scale:
            bench_scores(train, test, args, report)


def bench_scores(
    train: list[Track], test: list[Track], args: argparse.Namespace, report: Report
) -> None:
    """The "Detection speed" table: step, area default, lane and nearest scoring."""
    step_s = bench_step(test, args.draws)
    area_s = bench_area(train, test, args.draws)
    lane_s = bench_lane(test, args.draws)
    near_s, med = bench_nearest(train, test)
    events_s = bench_events(test)
    n, p = args.tracks, args.points
    report.say(f"Detection speed on {os.cpu_count()} CPU cores, torch {torch.__version__}\n")
    table = report.table(["what", "measured", "target"], title="Detection speed")
    k = args.draws
    size = {"tracks": n, "reports": p, "draws": k}
    table.row(
        [f"step scoring: {n} tracks x {p} reports, K = {k}", f"{step_s:.1f} s", "<= 20 s"],
        {"what": "step", **size, "seconds": step_s, "target_s": 20},
    )
    table.row(
        [
            f"the area's default: cross-fitted BC ({PRESETS[AREA_PRESET].members} members) by "
            f"`stepspread`, member by member: {n} tracks x {p} reports, K = {k}",
            f"{area_s:.1f} s",
            "",
        ],
        {"what": "area default (bc, stepspread)", **size, "seconds": area_s},
    )
    table.row(
        [
            f"events that need no model (`model_free_events`) of the same reports; with the "
            f"area default: {(area_s + events_s) / area_s:.2f}x its time",
            f"{events_s:.1f} s",
            "<= 2x",
        ],
        {"what": "events", **size, "seconds": events_s, "ratio": (area_s + events_s) / area_s},
    )
    table.row(
        [
            f"lane scoring: {n} tracks x {p} reports, {ScoreSettings().lane_rollouts} rollouts "
            f"of 2x the steps (best of the first K = {k})",
            f"{lane_s:.1f} s",
            "",
        ],
        {"what": "lane", **size, "seconds": lane_s},
    )
    table.row(
        [
            f"nearest: {n} test x {n} training tracks of {p} points (exact, pruned; median "
            f"distance {med:,.0f} m)",
            f"{near_s:.1f} s",
            "<= 60 s",
        ],
        {"what": "nearest", **size, "seconds": near_s, "median_m": med, "target_s": 60},
    )


if __name__ == "__main__":
    main()
