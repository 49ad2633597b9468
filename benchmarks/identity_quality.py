"""Identity kinds' quality on real traffic: recall of `identity-conflict` and `identity-change`
on cases constructed in real ingest outputs (`aisdati.evaluation.identity_cases`: two real
vessels' reports under one MMSI, cleaned as ingest cleans them; a real vessel's name, type or
length changed), and the false events of those kinds per 1,000 vessel-days on the untouched
later half of each area (every event counted, each MMSI's vessel-days once), each with a 95 %
bootstrap interval (`aisdati.metrics.interval`; recall over cases, rates over vessels).

Each case is judged by the kind's own fleet finder over the case's vessels (the MMSI and its
second transmitter's id), as `model_free_events` runs it; the one-vessel kinds are not run
(they neither find nor fold these kinds). Known-shared MMSIs (`KNOWN_SHARED`: numbers that
default or test configurations carry) are counted apart from the rest.

Run (each DIR an `aisdati ingest --roi none --min-points 100 --out DIR` output of this code):
    python benchmarks/identity_quality.py DIR [DIR ...] [--cases 60] [--seeds 0,1,2,3]
Prints markdown tables and the machine's load.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd

from aisdati.evaluation.alerts import vessel_day_table
from aisdati.evaluation.constructed import CONSTRUCTORS, found
from aisdati.events.fleet import FLEET_FINDERS, Fleet
from aisdati.events.reports import vessels
from aisdati.events.rules import EventRules
from aisdati.metrics import interval
from aisdati.tracks.reports import read_identities, read_reports, read_vessels
from aisdati.tracks.schema import TRANSMITTER_STEP, mmsi_of

KINDS = ("identity-conflict", "identity-change")
KNOWN_SHARED = frozenset({0, 1, 111111111, 123456789, 999999999, 987654321})
"""MMSIs that many transmitters carry by default or by mistake: a conflict on one is known."""


def fleet_of(reports: pd.DataFrame, identity: pd.DataFrame, history) -> Fleet:
    who = {
        int(m): {k: (None if pd.isna(v) else v) for k, v in row.items()}
        for m, row in identity.iterrows()
    }
    return Fleet({v.mmsi: v for v in vessels(reports)}, who, history)


def recall(area: Path, kind: str, n: int, seeds: list[int]) -> list[tuple[str, int, bool]]:
    """(area, seed, found) of up to `n` cases per seed of `kind` written into `area`."""
    reports, identity = read_reports(area), read_vessels(area)
    identity.attrs["history"] = read_identities(area)
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for _ in range(n):
            made = CONSTRUCTORS[kind](reports, identity, rng)
            if made is None:
                break
            rows, ident, case = made
            ids = [*case.mmsis, *(m + TRANSMITTER_STEP for m in case.mmsis)]
            mine = rows[rows["mmsi"].isin(ids)]
            fleet = fleet_of(mine, ident, ident.attrs.get("history"))
            events = pd.DataFrame(FLEET_FINDERS[kind](fleet, EventRules()))
            out.append((area.name, seed, bool(len(events)) and found(case, events)))
    return out


def false_events(area: Path) -> dict:
    """Every identity event over the later half of the area's untouched reports, per 1,000
    vessel-days (vessels by MMSI: a second transmitter is its MMSI's)."""
    reports, identity = read_reports(area), read_vessels(area)
    mid = reports["time"].min() + (reports["time"].max() - reports["time"].min()) / 2
    later = reports[reports["time"] >= mid]
    history = read_identities(area)
    if history is not None:
        history = history[history["first"].isna() | (history["first"] >= mid)]
    fleet = fleet_of(later, identity, history)
    rows = [r for kind in KINDS for r in FLEET_FINDERS[kind](fleet, EventRules())]
    events = pd.DataFrame(rows, columns=["mmsi", "kind", "evidence"] if not rows else None)
    days = vessel_day_table(later.assign(mmsi=later["mmsi"].map(mmsi_of)))
    out = {"area": area.name, "vessel_days": float(days.sum()), "events": events}
    for kind in KINDS:
        mine = events[events["kind"] == kind] if len(events) else events
        shared = mine["mmsi"].isin(KNOWN_SHARED) if len(mine) else pd.Series(dtype=bool)
        counts = (
            mine[~shared].groupby("mmsi").size() if len(mine) else pd.Series(dtype=float)
        ).reindex(days.index, fill_value=0)
        c, d = counts.to_numpy(np.float64), days.to_numpy(np.float64)
        rate = 1000.0 * c.sum() / d.sum()
        ci = interval(lambda i, c=c, d=d: 1000.0 * c[i].sum() / d[i].sum(), len(d))
        out[kind] = (int(c.sum()), int(shared.sum()) if len(mine) else 0, rate, ci)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("areas", nargs="+", type=Path)
    parser.add_argument("--cases", type=int, default=60, help="cases per seed, kind and area")
    parser.add_argument("--seeds", default="0,1,2,3")
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    started = time.perf_counter()
    print("| kind | area | cases | found | recall | 95 % interval |\n|---|---|---|---|---|---|")
    for kind in KINDS:
        every = []
        for area in args.areas:
            got = recall(area, kind, args.cases, seeds)
            every += got
            hits = np.array([f for *_, f in got], float)
            if len(hits):
                ci = interval(lambda i, h=hits: h[i].mean(), len(hits))
                print(f"| {kind} | {area.name} | {len(hits)} | {int(hits.sum())} | "
                      f"{hits.mean():.3f} | {ci[0]:.3f}-{ci[1]:.3f} |")  # fmt: skip
        hits = np.array([f for *_, f in every], float)
        ci = interval(lambda i, h=hits: h[i].mean(), len(hits))
        print(f"| {kind} | all | {len(hits)} | {int(hits.sum())} | {hits.mean():.3f} | "
              f"{ci[0]:.3f}-{ci[1]:.3f} |")  # fmt: skip
    print("\n| area | vessel-days (later half) | kind | events | on known-shared MMSIs | "
          "per 1,000 vessel-days | 95 % interval |\n|---|---|---|---|---|---|---|")  # fmt: skip
    listed = []
    for area in args.areas:
        got = false_events(area)
        for kind in KINDS:
            n, shared, rate, ci = got[kind]
            print(f"| {area.name} | {got['vessel_days']:,.0f} | {kind} | {n} | {shared} | "
                  f"{rate:.2f} | {ci[0]:.2f}-{ci[1]:.2f} |")  # fmt: skip
        listed.append(got["events"])
    events = pd.concat([e for e in listed if len(e)] or [pd.DataFrame()])
    if len(events):
        print("\nEvery false event:\n")
        for e in events.itertuples():
            print(f"- {e.kind} {e.mmsi}: {e.evidence}")
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"\n{time.perf_counter() - started:.0f} s; load average {load} ({os.cpu_count()} CPUs)")


if __name__ == "__main__":
    main()
