"""The fleet kinds' quality (`aisdati.events.kinds.FLEET`), measured as `aisdati evaluate`
measures them (`aisdati.evaluation.fleet`): cases of each kind asked constructed in each
area's untouched later traffic (its later half by time), found by the events `detect --models
none` finds there, recall with its 95 % bootstrap interval over cases; and every event of the
kind on that traffic with no case written, per 1,000 vessel-days with its interval over
vessels (false, except port visits and gaps: the traffic's own). One table: per kind, pooled
over the areas ("all") and per area.

Ingest first (each whole file, `--roi none --min-points 100`, as /tmp/ab/* are), then:
  python benchmarks/fleet_quality.py /tmp/ab/* [--kinds encounter,gap-heard] [--seeds 0,1,2]
      [--cases 40]
Not part of the test suite; run it under the shared lock on a loaded machine.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.errors import UserError
from aisdati.evaluation.fleet import FleetSettings, measure_area, parse_fleet_kinds, read_area
from aisdati.evaluation.fleet import summary as fleet_summary


def _ci(row: dict, key: str, fmt: str) -> str:
    lo, hi = row[f"{key}_ci"]
    if row[key] is None:
        return "-"
    return f"{fmt.format(row[key])} [{fmt.format(lo or 0)}, {fmt.format(hi or 0)}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("areas", nargs="+", type=Path, help="ingest output folders")
    parser.add_argument("--kinds", default="all", help="comma-separated case names, or all")
    parser.add_argument("--seeds", default="0,1,2,3,4", help="comma-separated")
    parser.add_argument("--cases", type=int, default=40, help="per area, seed and kind")
    parser.add_argument("--resamples", type=int, default=1000)
    add_json_option(parser, "fleet_quality")
    args = parser.parse_args()
    try:
        kinds = parse_fleet_kinds(args.kinds)
    except UserError as exc:
        parser.error(str(exc))
    seeds = tuple(int(s) for s in args.seeds.split(","))
    settings = FleetSettings(kinds, args.cases, seeds, None, args.resamples)
    with Report.from_args("fleet_quality", args) as report:
        report.say(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        results = []
        for folder in args.areas:
            t0 = time.perf_counter()
            area = read_area(folder, None)
            results.append(measure_area(area, settings, report.say))
            took = time.perf_counter() - t0
            report.say(f"{folder.name} (from {area.start:%Y-%m-%d %H:%M}): {took:.0f} s, "
                       f"load {os.getloadavg()[0]:.1f}")  # fmt: skip
        table = report.table(
            ["kind", "area", "cases", "found", "recall [95 %]", "vessel-days", "events",
             "per 1,000 vessel-days [95 %]"],
            title="Constructed cases found; the kind's events on untouched later traffic",
        )  # fmt: skip
        for row in fleet_summary(results, settings)["rows"]:
            rate = _ci(row, "per_1000", "{:.2f}") + ("" if row["false"] else " (own)")
            table.row([row["kind"], row["area"], row["cases"], row["found"],
                       _ci(row, "recall", "{:.3f}"), f"{row['vessel_days']:,.0f}",
                       row["events"], rate], row)  # fmt: skip
        report.say(f"load {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
