"""Interference over an area and gaps' coverage, measured on real traffic: each area's later
period (from its split date on), untouched, judged as `aisdati detect --models none` judges
(every report, the default rules): false interference events per 1,000 vessel-days (every one
is false: the shipped traffic holds no interference), and gaps per coverage; then constructed
cases written into the same later period (`aisdati.evaluation.constructed.CONSTRUCTORS`: a
block of vessels displaced together; a vessel silenced while its neighbours keep reporting; a
vessel silenced with its area), one at a time, the areas in turn and seeds pooled until each
case has `--cases`: the share found (`found`: an event of its kind over its time naming its
vessels, a gap with its expected coverage), with 95 % bootstrap intervals. Each case is judged
over the reports of the vessels heard within `REACH_M` of it, from 12 hours before it to 12
hours after (the events of a vessel depend on its hours around; the fleet's, on its area).

Ingest first (each whole file, `--roi none --min-points 100`), then run:
  python benchmarks/interference_quality.py kitimat=/tmp/ab/kitimat@2018-08-01 \\
      nyharbor=/tmp/ab/nyharbor@2020-12-05 virginiabeach=/tmp/ab/virginiabeach@2020-06-06 \\
      uscoastal=/tmp/ab/uscoastal@2020-06-30T12:00 [--cases 200] [--only "gap heard"]
Not part of the test suite.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.detection.events import model_free_events
from aisdati.evaluation.alerts import alert_rates, vessel_day_table
from aisdati.evaluation.constructed import CONSTRUCTORS, Case, found
from aisdati.events.rules import EventRules
from aisdati.geo import haversine_m
from aisdati.metrics import interval
from aisdati.tracks.reports import motion_derived, read_reports, read_vessels

CASES = ("gnss-interference", "gap heard", "gap quiet")
REACH_M = 100_000.0
AROUND = pd.Timedelta(hours=12)


def split_area(spec: str) -> tuple[str, Path, pd.Timestamp]:
    name, rest = spec.split("=", 1)
    folder, date = rest.rsplit("@", 1)
    return name, Path(folder), pd.Timestamp(date, tz="UTC")


def around(reports: pd.DataFrame, case: Case) -> pd.DataFrame:
    """The reports a case is judged on: of the vessels heard within `REACH_M` of its vessels
    during it, from `AROUND` before it to `AROUND` after."""
    t = reports["time"]
    mine = reports[
        reports["mmsi"].isin(case.mmsis) & (t >= case.start - AROUND) & (t <= case.end + AROUND)
    ]
    places = mine[["lon", "lat"]].to_numpy()[:: max(1, len(mine) // 30)]
    window = reports[(t >= case.start - AROUND) & (t <= case.end + AROUND)]
    close = np.zeros(len(window), bool)
    for lon, lat in places:
        close |= (
            haversine_m(lon, lat, window["lon"].to_numpy(), window["lat"].to_numpy()) <= REACH_M
        )
    return window[window["mmsi"].isin(window["mmsi"][close].unique())]


def untouched(name: str, later: pd.DataFrame, identity: pd.DataFrame, rules: EventRules, args,
              report: Report, table) -> None:  # fmt: skip
    t0 = time.perf_counter()
    events = model_free_events(later, identity, rules)
    days = float(vessel_day_table(later).sum())
    r = alert_rates(events, later, np.zeros(0, np.int64), args.resamples)
    kind = r["by_kind"].get(
        "gnss-interference", {"events": 0, "per_1000": 0.0, "per_1000_ci": (0.0, 0.0)}
    )
    gaps = events[events["kind"] == "gap"]
    cover = gaps["coverage"].fillna("null").value_counts().to_dict()
    lo, hi = kind["per_1000_ci"]
    lo, hi = lo or 0.0, hi or 0.0
    table.row(
        [name, f"{days:,.0f}", kind["events"], f"{kind['per_1000']:.2f} [{lo:.2f}, {hi:.2f}]",
         len(gaps), cover.get("heard", 0), cover.get("quiet", 0), cover.get("null", 0),
         f"{time.perf_counter() - t0:.0f}"],
        {"area": name, "vessel_days": days, "interference": kind, "gaps": len(gaps),
         "coverage": cover},
    )  # fmt: skip


def share_interval(hits: np.ndarray, resamples: int) -> tuple[float | None, float | None]:
    """The 95 % bootstrap interval of the share found (None where no case)."""
    if not len(hits):
        return None, None
    return interval(lambda i: float(hits[i].mean()), len(hits), resamples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("areas", nargs="+", help="NAME=INGEST_DIR@SPLIT_DATE")
    parser.add_argument("--cases", type=int, default=200, help="constructed cases per case kind")
    parser.add_argument("--only", default=",".join(CASES), help="the constructors to run")
    parser.add_argument("--tries", type=int, default=40, help="draws per case before giving up")
    parser.add_argument("--resamples", type=int, default=1000)
    add_json_option(parser, "interference_quality")
    args = parser.parse_args()
    names = [c.strip() for c in args.only.split(",") if c.strip()]
    with Report.from_args("interference_quality", args) as report:
        report.note(f"load average {os.getloadavg()[0]:.1f} (2 cores shared)")
        rates = report.table(
            ["area", "vessel-days", "interference events", "per 1,000 vd [95 %]", "gaps",
             "heard", "quiet", "null", "s"],
            title="Untouched later period (detect --models none)",
        )  # fmt: skip
        areas = []
        for spec in args.areas:
            name, folder, split = split_area(spec)
            reports = read_reports(folder)
            later = reports[reports["time"] >= split].reset_index(drop=True)
            identity = read_vessels(folder)
            rules = EventRules(reported_motion=not motion_derived(folder))
            untouched(name, later, identity, rules, args, report, rates)
            areas.append((name, later, identity, rules))
        shares = report.table(["case", "cases", "found [95 %]", "by area", "s"],
                              title="Constructed cases in the later period found")  # fmt: skip
        for case_name in names:
            t0 = time.perf_counter()
            hits: list[float] = []
            by_area: dict[str, list[float]] = {a[0]: [] for a in areas}
            seed = 0
            while len(hits) < args.cases and seed < args.cases * args.tries:
                name, later, identity, rules = areas[seed % len(areas)]
                rng = np.random.default_rng([seed, sum(map(ord, case_name))])
                seed += 1
                built = CONSTRUCTORS[case_name](later, identity, rng)
                if built is None:
                    continue
                written, known, case = built
                events = model_free_events(around(written, case), known, rules)
                hit = float(found(case, events))
                hits.append(hit)
                by_area[name].append(hit)
            h = np.asarray(hits)
            lo, hi = share_interval(h, args.resamples)
            each = ", ".join(f"{a} {np.mean(v):.2f} ({len(v)})" for a, v in by_area.items() if v)
            shares.row(
                [case_name, len(h), f"{h.mean():.3f} [{lo:.3f}, {hi:.3f}]" if len(h) else "-", each,
                 f"{time.perf_counter() - t0:.0f}"],
                {"case": case_name, "cases": len(h), "found": float(h.mean()) if len(h) else None,
                 "found_ci": [lo, hi], "by_area": {a: [len(v), float(np.mean(v)) if v else None]
                                                    for a, v in by_area.items()}},
            )  # fmt: skip


if __name__ == "__main__":
    main()
