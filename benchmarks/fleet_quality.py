"""The fleet kinds' quality (`aisdati.events.kinds.FLEET`), measured as the analyst meets them:
cases of each kind asked constructed in real traffic (`aisdati.evaluation.constructed.
CONSTRUCTORS`: e.g. two real vessels' real reports brought together at sea for hours), many
per run on distinct vessels so that the events are found once per batch
(`aisdati.detection.events.model_free_events`, as `detect --models none` finds them, the
ports and anchorages learned from the traffic judged); recall with its 95 % bootstrap interval
over cases, pooled over areas and seeds; and on each area's untouched traffic (its later part:
from the first day of the month of its last report where it spans over 28 days, Kitimat's
August; else all of it) every event of these kinds per 1,000 vessel-days with its interval over
vessels (`aisdati.evaluation.alerts.alert_rates`): false where no case was written.

Ingest first (each whole file, `--roi none --min-points 100`, as /tmp/ab/* are), then:
  python benchmarks/fleet_quality.py /tmp/ab/* --kinds encounter [--seeds 5] [--cases 40]
Not part of the test suite; run it under the shared lock on a loaded machine.
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
from aisdati.evaluation.alerts import alert_rates
from aisdati.evaluation.constructed import CONSTRUCTORS, Case, found
from aisdati.events.anchorages import learned_from
from aisdati.events.fleet import FLEET_FINDERS, Fleet
from aisdati.events.reports import vessels
from aisdati.events.rules import EventRules
from aisdati.metrics import interval
from aisdati.tracks.reports import motion_derived, read_reports, read_vessels

LONG_DAYS = 28
TRIES = 3
"""Draws in a row that make no case before a kind's batch is taken as full."""


def later(reports: pd.DataFrame) -> pd.DataFrame:
    """The untouched traffic judged: from the first day of the last report's month where the
    reports span over `LONG_DAYS`, else all of them."""
    first, last = reports["time"].min(), reports["time"].max()
    if last - first <= pd.Timedelta(days=LONG_DAYS):
        return reports
    month = last.normalize().replace(day=1)
    return reports[reports["time"] >= month].reset_index(drop=True)


def judged(traffic: pd.DataFrame, identity: pd.DataFrame, reported: bool) -> pd.DataFrame:
    """Every event of `traffic` as `detect --models none` finds them on it."""
    rules = EventRules(reported_motion=reported, ports=learned_from(traffic))
    return model_free_events(traffic, identity, rules)


def constructed(
    traffic: pd.DataFrame, identity: pd.DataFrame, kinds: list[str], n: int, seed: int
) -> tuple[pd.DataFrame, list[Case]]:
    """`traffic` with up to `n` cases of each kind written in, each on vessels no other case
    touches (a constructor sees only the untouched vessels)."""
    rng = np.random.default_rng(seed)
    cases: list[Case] = []
    used: set[int] = set()
    for kind in kinds:
        misses = 0
        while sum(c.kind == kind for c in cases) < n and misses < TRIES:
            free = traffic["mmsi"].isin(used)
            made = CONSTRUCTORS[kind](traffic[~free], identity, rng)
            if made is None:
                misses += 1  # none this draw (e.g. no stop as long to lend); the next may
                continue
            out, identity, case = made
            traffic = pd.concat([traffic[free], out], ignore_index=True)
            used |= set(case.mmsis)
            cases.append(case)
            misses = 0
    return traffic, cases


def speed(name: str, traffic: pd.DataFrame, kinds: list[str], table) -> None:
    """Seconds each fleet finder asked takes over every vessel of `traffic`, alone."""
    fleet = Fleet({v.mmsi: v for v in vessels(traffic)}, {})
    rules = EventRules(ports=learned_from(traffic))
    for kind in kinds:
        t0 = time.perf_counter()
        got = FLEET_FINDERS[kind](fleet, rules)
        took = time.perf_counter() - t0
        table.row([name, kind, f"{len(fleet.vessels):,}", f"{len(traffic):,}", len(got),
                   f"{took:.2f}"], {"area": name, "kind": kind, "vessels": len(fleet.vessels),
                   "reports": len(traffic), "events": len(got), "seconds": took})  # fmt: skip


def area(folder: Path, args: argparse.Namespace, report: Report, rates, hits: list, speeds) -> None:
    t0 = time.perf_counter()
    reports, identity = read_reports(folder), read_vessels(folder)
    reported = not motion_derived(folder)
    untouched = later(reports)
    speed(folder.name, untouched, args.kinds, speeds)
    events = judged(untouched, identity, reported)
    counted = alert_rates(events, untouched, np.empty(0, np.int64), args.resamples)
    for kind in args.kinds:
        got = counted["by_kind"].get(kind, {"events": 0, "per_1000": 0.0, "per_1000_ci": (0, 0)})
        lo, hi = got["per_1000_ci"]
        rates.row(
            [folder.name, kind, f"{counted['vessel_days']:,.0f}", got["events"],
             f"{got['per_1000']:.2f} [{lo or 0:.2f}, {hi or 0:.2f}]"],
            {"area": folder.name, "kind": kind, **got},
        )  # fmt: skip
    for seed in range(args.seeds):
        traffic, cases = constructed(untouched, identity, args.kinds, args.cases, seed)
        if not cases:
            report.say(f"{folder.name}: no place for a case of {', '.join(args.kinds)}")
            break
        events = judged(traffic, identity, reported)
        hits += [(folder.name, seed, c.kind, found(c, events)) for c in cases]
        report.say(f"{folder.name} seed {seed}: {len(cases)} cases, "
                   f"{sum(h[3] for h in hits[-len(cases):])} found")  # fmt: skip
    report.say(f"{folder.name}: {time.perf_counter() - t0:.0f} s, load {os.getloadavg()[0]:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("areas", nargs="+", type=Path, help="ingest output folders")
    parser.add_argument("--kinds", default="encounter")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--cases", type=int, default=40, help="per area, seed and kind")
    parser.add_argument("--resamples", type=int, default=1000)
    add_json_option(parser, "fleet_quality")
    args = parser.parse_args()
    args.kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    unknown = [k for k in args.kinds if k not in CONSTRUCTORS]
    if unknown:
        parser.error(f"no constructor for {', '.join(unknown)} (have: {', '.join(CONSTRUCTORS)})")
    with Report.from_args("fleet_quality", args) as report:
        report.say(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        rates = report.table(
            ["area", "kind", "vessel-days", "events", "per 1,000 vessel-days [95 %]"],
            title="Untouched traffic: every event of the kinds asked (no case written)",
        )
        speeds = report.table(
            ["area", "kind", "vessels", "reports", "events", "seconds"],
            title="Each fleet finder alone over an area's untouched traffic",
        )
        hits: list[tuple[str, int, str, bool]] = []
        for folder in args.areas:
            area(folder, args, report, rates, hits, speeds)
        recall = report.table(["kind", "cases", "areas", "found", "recall [95 %]"],
                              title="Constructed cases found")  # fmt: skip
        frame = pd.DataFrame(hits, columns=["area", "seed", "kind", "found"])
        for kind, g in frame.groupby("kind"):
            ok = g["found"].to_numpy(bool)
            lo, hi = interval(lambda i, ok=ok: float(ok[i].mean()), len(ok), args.resamples)
            per_area = ", ".join(f"{a} {n}" for a, n in g.groupby("area").size().items())
            recall.row([kind, len(ok), per_area, int(ok.sum()),
                        f"{ok.mean():.3f} [{lo:.3f}, {hi:.3f}]"],
                       {"kind": kind, "cases": len(ok), "found": int(ok.sum()),
                        "recall": float(ok.mean()), "ci": (lo, hi)})  # fmt: skip
        report.say(f"load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
