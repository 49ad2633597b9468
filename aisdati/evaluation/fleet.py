"""The fleet kinds measured as the other kinds are (`aisdati evaluate`, benchmarks/
fleet_quality.py): cases constructed in an area's real traffic (`aisdati.evaluation.
constructed.CONSTRUCTORS`), found by the events `detect --models none` finds there
(`model_free_events`: the default rules, the ports and anchorages learned from the traffic
judged, the identity history), recall with its 95 % bootstrap interval over cases; and every
event of the same kinds on the area's untouched later traffic per 1,000 vessel-days with its
interval over vessels (false where no case was written, except the kinds the traffic holds for
real: `OWN`).

One definition of the traffic, as `evaluate --before` defines its later period: the
**untouched later traffic** is every report from `before` on, or, with no `before`, from the
middle of the area's time span on (its later half by time). Events are counted where they end
in it (an identity change that ended before it is the earlier period's), every event counted
(no MMSI set apart), a second transmitter's reports and days its MMSI's. The cases are written
into a copy of that same traffic, so what is found is judged on the traffic the false events
are counted on.

Cases that touch only their own vessels (`BATCHED`) are written many to a traffic, each on
vessels no other case touches (a constructor sees only the untouched vessels), and judged in
one pass; cases that displace or silence an area, or whose truth is their neighbours'
reports (gnss-interference, a gap's coverage), are written one to a traffic and judged over
the reports of the vessels heard within `REACH_M` of them from `AROUND` before to `AROUND`
after (what the events there depend on), as two such cases side by side would change each
other's truth."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.detection.events import model_free_events
from aisdati.errors import UserError
from aisdati.evaluation.alerts import per_1000, vessel_day_table
from aisdati.evaluation.constructed import CONSTRUCTORS, Case, found
from aisdati.events.rules import EventRules
from aisdati.geo import haversine_m
from aisdati.metrics import interval
from aisdati.tracks.reports import motion_derived, read_identities, read_reports, read_vessels
from aisdati.tracks.schema import mmsi_of

BATCHED = frozenset({"encounter", "port-visit", "identity-conflict", "identity-change"})
"""Cases that change and name only their own vessels: many written to one traffic."""
OWN = frozenset({"port-visit", "gap-heard", "gap-quiet"})
"""Kinds the untouched traffic holds for real (calls, gaps): listed per 1,000 vessel-days,
not false."""
TRIES = 3
"""Draws in a row that make no case before a batch of a kind is taken as full."""
ALONE_TRIES = 10
"""Draws per case asked before a kind written one case at a time gives up on a seed."""
REACH_M = 100_000.0
AROUND = pd.Timedelta(hours=12)


def parse_fleet_kinds(text: str) -> tuple[str, ...]:
    """`--fleet-kinds`: comma-separated names of `CONSTRUCTORS`, `all`, or `none`."""
    names = [k.strip() for k in text.split(",") if k.strip()]
    if names in (["none"], []):
        return ()
    if names == ["all"]:
        return tuple(CONSTRUCTORS)
    unknown = [k for k in names if k not in CONSTRUCTORS]
    if unknown:
        raise UserError(
            f"unknown fleet kind {unknown[0]!r} (known: {', '.join(CONSTRUCTORS)}, all, none)"
        )
    return tuple(dict.fromkeys(names))


@dataclass(frozen=True)
class FleetSettings:
    kinds: tuple[str, ...] = tuple(CONSTRUCTORS)
    cases: int = 20
    """Cases asked per kind, seed and area."""
    seeds: tuple[int, ...] = (0,)
    before: pd.Timestamp | None = None
    """The untouched later traffic starts here; None: the middle of the area's time span."""
    resamples: int = 1000


@dataclass
class Area:
    """An area's untouched later traffic, as the cases and the false events are judged on."""

    name: str
    reports: pd.DataFrame
    identity: pd.DataFrame
    """vessels.parquet by MMSI, the identity history as `attrs["history"]`."""
    reported: bool
    start: pd.Timestamp


def later_start(reports: pd.DataFrame, before: pd.Timestamp | None) -> pd.Timestamp:
    """Where the untouched later traffic starts: `before`, else the middle of the time span."""
    if before is not None:
        return before
    first, last = reports["time"].min(), reports["time"].max()
    return first + (last - first) / 2


def read_area(folder: Path, before: pd.Timestamp | None) -> Area:
    """The untouched later traffic of an ingest output (`later_start`)."""
    reports = read_reports(folder)
    if not len(reports):
        raise UserError(f"{folder} has no reports to construct fleet cases in")
    start = later_start(reports, before)
    later = reports[reports["time"] >= start].reset_index(drop=True)
    if not len(later):
        raise UserError(f"{folder} has no report from {start:%Y-%m-%d %H:%M} on")
    identity = read_vessels(folder)
    identity.attrs["history"] = read_identities(folder)
    return Area(folder.name, later, identity, not motion_derived(folder), start)


def judged(reports: pd.DataFrame, identity: pd.DataFrame, area: Area) -> pd.DataFrame:
    """Every event `detect --models none` finds on `reports` that ends in the later traffic."""
    rules = EventRules(reported_motion=area.reported)
    events = model_free_events(reports, identity, rules, identity.attrs.get("history"))
    return events[pd.to_datetime(events["end"], utc=True) >= area.start]


def of_case(events: pd.DataFrame, name: str) -> pd.DataFrame:
    """The events of a case name's kind (a gap case: the gaps of its coverage)."""
    if name.startswith("gap-"):
        return events[(events["kind"] == "gap") & (events["coverage"] == name[4:])]
    return events[events["kind"] == name]


def batch(
    area: Area, kinds: Sequence[str], n: int, rng: np.random.Generator
) -> tuple[pd.DataFrame, pd.DataFrame, list[Case]]:
    """The area's traffic with up to `n` cases of each of `kinds` written in, each on vessels
    no other case touches."""
    traffic, identity = area.reports, area.identity
    cases: list[Case] = []
    used: set[int] = set()
    for kind in kinds:
        made_n, misses = 0, 0
        while made_n < n and misses < TRIES:
            taken = traffic["mmsi"].map(mmsi_of).isin(used)
            made = CONSTRUCTORS[kind](traffic[~taken], identity, rng)
            if made is None:
                misses += 1  # none this draw (e.g. no stop as long to lend); the next may
                continue
            out, identity, case = made
            traffic = pd.concat([traffic[taken], out], ignore_index=True)
            used |= set(case.mmsis)
            cases.append(case)
            made_n, misses = made_n + 1, 0
    return traffic, identity, cases


def around(reports: pd.DataFrame, case: Case) -> pd.DataFrame:
    """The reports a case written alone is judged on: of the vessels heard within `REACH_M` of
    its vessels during it, from `AROUND` before it to `AROUND` after."""
    t = reports["time"]
    window = reports[(t >= case.start - AROUND) & (t <= case.end + AROUND)]
    mine = window[window["mmsi"].isin(case.mmsis)]
    places = mine[["lon", "lat"]].to_numpy()[:: max(1, len(mine) // 30)]
    lon, lat = window["lon"].to_numpy(), window["lat"].to_numpy()
    close = np.zeros(len(window), bool)
    for x, y in places:
        close |= haversine_m(x, y, lon, lat) <= REACH_M
    return window[window["mmsi"].isin(window["mmsi"][close].unique())]


@dataclass
class AreaResult:
    """One area's cases found (kind, seed, found) and its untouched events and vessel-days."""

    name: str
    hits: list[tuple[str, int, bool]] = field(default_factory=list)
    counts: dict[str, pd.Series] = field(default_factory=dict)
    """Events of each kind per vessel (by MMSI) on the untouched traffic."""
    days: pd.Series = field(default_factory=pd.Series)
    """Vessel-days per MMSI of the untouched traffic."""


def measure_area(
    area: Area, settings: FleetSettings, say: Callable[[str], None] = lambda _: None
) -> AreaResult:
    """The cases of `settings.kinds` found in `area` and its untouched events."""
    result = AreaResult(area.name)
    events = judged(area.reports, area.identity, area)
    mmsi = area.reports["mmsi"].map(mmsi_of)
    result.days = vessel_day_table(area.reports.assign(mmsi=mmsi))
    for kind in settings.kinds:
        mine = of_case(events, kind)
        result.counts[kind] = mine["mmsi"].map(mmsi_of).value_counts()
    batched = [k for k in settings.kinds if k in BATCHED]
    for seed in settings.seeds:
        rng = np.random.default_rng(seed)
        if batched:
            traffic, identity, cases = batch(area, batched, settings.cases, rng)
            got = judged(traffic, identity, area) if cases else events
            result.hits += [(c.kind, seed, found(c, got)) for c in cases]
        for kind in settings.kinds:
            if kind not in BATCHED:
                result.hits += alone(area, kind, settings.cases, seed)
        these = [h for h in result.hits if h[1] == seed]
        say(f"{area.name} seed {seed}: {len(these)} cases, {sum(h[2] for h in these)} found")
    return result


def alone(area: Area, kind: str, n: int, seed: int) -> list[tuple[str, int, bool]]:
    """Up to `n` cases of `kind`, each written alone into the area and judged around it."""
    rng = np.random.default_rng([seed, sum(map(ord, kind))])
    out: list[tuple[str, int, bool]] = []
    for _ in range(n * ALONE_TRIES):
        if len(out) == n:
            break
        made = CONSTRUCTORS[kind](area.reports, area.identity, rng)
        if made is None:
            continue
        written, identity, case = made
        out.append((kind, seed, found(case, judged(around(written, case), identity, area))))
    return out


def measure(
    areas: Sequence[Area], settings: FleetSettings, say: Callable[[str], None] = lambda _: None
) -> dict[str, Any]:
    """Recall and untouched events per kind, per area and pooled (`summary`)."""
    return summary([measure_area(a, settings, say) for a in areas], settings)


def summary(results: Sequence[AreaResult], settings: FleetSettings) -> dict[str, Any]:
    """evaluation.json's `fleet`: per kind, pooled over areas ("area": "all") and per area,
    cases, found, recall [95 %], and events per 1,000 untouched vessel-days [95 %] (`false`:
    whether they are false events, `OWN`)."""
    rows = []
    for kind in settings.kinds:
        per_area = [_row(kind, [r], settings.resamples) for r in results]
        pooled = [_row(kind, results, settings.resamples)] if len(results) > 1 else []
        rows += pooled + per_area
    return {
        "kinds": list(settings.kinds),
        "cases_asked": settings.cases,
        "seeds": list(settings.seeds),
        "untouched": "every report from --before on, else from the middle of the time span",
        "rows": rows,
    }


def _row(kind: str, results: Sequence[AreaResult], resamples: int) -> dict[str, Any]:
    hits = np.array([f for r in results for k, _, f in r.hits if k == kind], bool)
    lo, hi = interval(lambda i: float(hits[i].mean()), len(hits), resamples)
    counts = np.concatenate(
        [r.counts[kind].reindex(r.days.index, fill_value=0).to_numpy(np.float64) for r in results]
    )
    days = np.concatenate([r.days.to_numpy(np.float64) for r in results])
    rate, ci = per_1000(counts, days, resamples)
    return {
        "kind": kind,
        "area": results[0].name if len(results) == 1 else "all",
        "cases": len(hits),
        "found": int(hits.sum()),
        "recall": float(hits.mean()) if len(hits) else None,
        "recall_ci": [lo, hi],
        "vessel_days": float(days.sum()),
        "events": int(counts.sum()),
        "per_1000": rate,
        "per_1000_ci": list(ci),
        "false": kind not in OWN,
    }
