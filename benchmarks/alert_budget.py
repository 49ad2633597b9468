"""The alert budget, measured as the analyst meets it: on each area with a forward split, the
earlier period calibrates the alert thresholds (`aisdati.events.calibrate`, as `aisdati train`
does on a model's training period) and the later period's untouched traffic is judged, every
report, every event counted (`aisdati.evaluation.alerts.alert_rates`): alerts and activity per
1,000 vessel-days by kind, tracks and vessels flagged, same-kind overlaps, events over their
kind's bound. Then, at that budget, stretches injected into the later period's tracks
(`aisdati.evaluation.inject`: jump, shift of 1-2 km, drift, gap; seeds pooled until each kind
has `--min-anomalies`): the share an event of the right kind overlaps, with its 95 % bootstrap
interval. `--defaults` judges with the thresholds used where no model is (`detect --models
none`) instead of the calibrated ones.

Ingest first (each whole file, `--roi none --min-points 100`), e.g.:
  .venv/bin/aisdati ingest --input tests/data/AIS_2018_07-08_Kitimat.csv.gz --roi none \\
      --min-points 100 --out /tmp/ab/kitimat
Run: python benchmarks/alert_budget.py kitimat=/tmp/ab/kitimat@2018-08-01 \\
     nyharbor=/tmp/ab/nyharbor@2020-12-05 virginiabeach=/tmp/ab/virginiabeach@2020-06-06 \\
     [--budget 10] [--defaults] [--kinds jump,shift,drift,gap] [--min-anomalies 200]
Not part of the test suite.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.detection.events import model_free_events
from aisdati.evaluation.alerts import alert_rates
from aisdati.evaluation.inject import MIN_POINTS, inject
from aisdati.evaluation.metrics import RIGHT_EVENTS
from aisdati.events.budget import ALERTS_PER_1000, Thresholds
from aisdati.events.calibrate import calibration, thresholds_of, training_period
from aisdati.events.reports import VesselReports, vessels
from aisdati.events.rules import EventRules
from aisdati.metrics import interval
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.reports import motion_derived, read_reports, read_vessels


def split_area(spec: str) -> tuple[str, Path, pd.Timestamp]:
    name, rest = spec.split("=", 1)
    folder, date = rest.rsplit("@", 1)
    return name, Path(folder), pd.Timestamp(date, tz="UTC")


def track_spans(points: pd.DataFrame) -> pd.DataFrame:
    g = points.groupby("track_id")
    return pd.DataFrame({"mmsi": g["mmsi"].first(), "start": g["time"].min(),
                         "end": g["time"].max()}).reset_index()  # fmt: skip


def altered(v: VesselReports, kind: str, rng: np.random.Generator) -> tuple[VesselReports, tuple]:
    """The track with one anomaly of `kind`, and its stretch [start, end)."""
    got = inject(kind, v.positions(), v.time_s - v.time_s[0], rng, None,
                 np.column_stack([v.sog, v.cog, v.heading]))  # fmt: skip
    n = len(got.positions)
    new = VesselReports(
        v.mmsi, v.time_s[0] + got.times_s, got.positions[:, 0], got.positions[:, 1],
        got.motion[:, 0], got.motion[:, 1], got.motion[:, 2], v.status[got.rows],
        np.full(n, v.track_id[0]),
    )  # fmt: skip
    return new, got.stretch


def recall(
    tracks: list[VesselReports], kind: str, rules: EventRules, args
) -> tuple[int, float, tuple]:
    """The share of `kind`'s injected stretches an event of the right kind overlaps."""
    hits: list[float] = []
    for seed in range(args.max_seeds):
        if len(hits) >= args.min_anomalies:
            break
        rng = np.random.default_rng([seed, sum(map(ord, kind))])
        for k in rng.permutation(len(tracks))[: args.min_anomalies - len(hits)]:
            v, (a, b) = altered(tracks[k], kind, rng)
            found = rules.events(v)
            right = [e for e in found if e.kind in RIGHT_EVENTS[kind]]
            hits.append(float(any(e.start < b and e.end >= a for e in right)))
    h = np.asarray(hits)
    return len(h), float(h.mean()), interval(lambda i: float(h[i].mean()), len(h), args.resamples)


def area(spec: str, args, report: Report, rates, found) -> None:
    name, folder, split = split_area(spec)
    t0 = time.perf_counter()
    reports = read_reports(folder)
    points = pd.read_parquet(folder / "points.parquet")
    spans = track_spans(points)
    before, after = reports[reports["time"] < split], reports[reports["time"] >= split]
    train_spans = spans[spans["end"] < split]
    train_ids = set(train_spans["track_id"])
    seen_at = AshoreCheck().seen(
        [g[["lon", "lat"]].to_numpy() for t, g in points.groupby("track_id") if t in train_ids]
    )
    seen = np.asarray(seen_at, np.float64).reshape(-1, 2)
    identity = read_vessels(folder)
    lengths = identity["length_m"].dropna().to_dict()
    reported = not motion_derived(folder)
    recorded = calibration(vessels(training_period(before, train_spans)), lengths=lengths,
                           seen=seen, reported_motion=reported)  # fmt: skip
    how = Thresholds() if args.defaults else thresholds_of([recorded], args.budget)
    rules = EventRules(thresholds=how, seen=seen, reported_motion=reported)
    events = model_free_events(after, identity, rules)
    later_ids = spans.loc[spans["start"] >= split, "track_id"].to_numpy()
    r = alert_rates(events, after, later_ids, args.resamples)
    lo, hi = r["alerts_per_1000_ci"]
    rates.row(
        [name, f"{r['vessel_days']:,.0f}", r["alerts"], f"{r['alerts_per_1000']:.1f} [{lo:.1f}, "
         f"{hi:.1f}]", f"{r['activity_per_1000']:.0f}",
         f"{r['tracks_flagged']}/{r['tracks']} ({100 * (r['tracks_flagged_share'] or 0):.1f} %)",
         r["vessels_alerted"], r["most_alerts_one_vessel"], r["same_kind_overlaps"],
         r["over_bound"]],
        {**r, "area": name, "thresholds": how.minimum},
    )  # fmt: skip
    kinds = ", ".join(
        f"{k} {v['per_1000']:.1f} (longest {v['longest_h']:.1f} h)" for k, v in r["by_kind"].items()
    )
    report.note(f"{name}: per 1,000 vessel-days by kind: {kinds}; thresholds "
                f"{ {k: round(v, 2) for k, v in how.minimum.items()} }")  # fmt: skip
    later = points[points["track_id"].isin(later_ids)].sort_values(["track_id", "time"])
    tracks = [VesselReports.of(g) for _, g in later.groupby("track_id") if len(g) >= MIN_POINTS]
    for kind in args.kinds:
        n, share, (lo, hi) = recall(tracks, kind, rules, args)
        found.row([name, kind, n, f"{share:.2f} [{lo:.2f}, {hi:.2f}]"],
                  {"area": name, "kind": kind, "anomalies": n, "recall": share,
                   "recall_ci": [lo, hi]})  # fmt: skip
    report.note(f"{name}: {time.perf_counter() - t0:.0f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("areas", nargs="+", help="NAME=INGEST_DIR@SPLIT_DATE")
    parser.add_argument("--budget", type=float, default=ALERTS_PER_1000)
    parser.add_argument("--defaults", action="store_true")
    parser.add_argument("--kinds", default="jump,shift,drift,gap")
    parser.add_argument("--min-anomalies", type=int, default=200)
    parser.add_argument("--max-seeds", type=int, default=60)
    parser.add_argument("--resamples", type=int, default=1000)
    add_json_option(parser, "alert_budget")
    args = parser.parse_args()
    args.kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    how = "the defaults (no model)" if args.defaults else f"a budget of {args.budget:g}"
    with Report.from_args("alert_budget", args) as report:
        rates = report.table(
            ["area", "vessel-days", "alerts", "alerts/1000 vd [95 %]", "activity/1000 vd",
             "tracks flagged", "vessels alerted", "most on one vessel", "overlaps",
             "over bound"], title=f"Untouched later period, {how}")  # fmt: skip
        found = report.table(["area", "kind", "injected", "found [95 %]"],
                             title="Injected stretches of the later period found")  # fmt: skip
        for spec in args.areas:
            area(spec, args, report, rates, found)


if __name__ == "__main__":
    main()
