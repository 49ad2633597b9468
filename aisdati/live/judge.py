"""A chunk's vessels judged as the batch judges their reports: each window cleaned as ingest
cleans reports.parquet (`clean.clean_vessels`: duplicates, repeated times and position
outliers out), then every model-free kind of `aisdati.events.find.find_events`, placed as the
rows of events.parquet. Nothing here redefines a kind.

All the chunk's vessels are cleaned, checked for land and screened together, in one pass over
their reports (`aisdati.live.screen`); only a vessel in which some kind may find an event, or
whose events the watch must look at again, goes through the finders one by one. A vessel the
screen clears would have given no event: skipping it changes nothing."""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.events.behaviour import land_mask, silence_limit
from aisdati.events.find import placed_rows
from aisdati.events.identity import change_row, conflict_rows, identity_changes
from aisdati.events.reports import VesselReports
from aisdati.events.rules import EventRules
from aisdati.live.decode import Identity
from aisdati.live.screen import may_find
from aisdati.live.vessels import FIELDS
from aisdati.preprocess.clean import clean_vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings
from aisdati.tracks.schema import TRANSMITTER_STEP

KEPT = (0, CODE["slow"])
"""What reports.parquet keeps of a vessel's cleaned reports: the slow ones are judged too."""


@dataclass(frozen=True)
class LastReport:
    """What a silence is judged by: a vessel's last report, and how long it may be silent
    before it counts as a gap at sea (None: it cannot go dark: too few reports, or not under
    way at its last report)."""

    mmsi: int
    time_s: float
    lon: float
    lat: float
    limit_s: float | None
    usual_s: float
    ashore: bool = False
    """Whether it is ashore (`aisdati.events.behaviour.land_mask`): a silence there is no gap."""


@dataclass(frozen=True)
class Judged:
    """A vessel's events found in its window (records of events.parquet's columns), the
    window's first and last report time, its cleaned reports (what an area model judges), and
    the kinds not looked for this time (their open events stay as they are)."""

    events: list[dict[str, Any]]
    first_s: float
    last_s: float
    reports: VesselReports
    unjudged: frozenset[str] = frozenset()


@dataclass(frozen=True)
class Together:
    """The cleaned reports of many vessels in one set of arrays, vessel after vessel (`all`:
    one `VesselReports` of them, in time order within each vessel), `mmsi[k]`'s reports at
    `bounds[k]:bounds[k + 1]`; `seconds`: the reports of a second transmitter heard under a
    vessel's MMSI (`aisdati.preprocess.transmitters`), by its id (MMSI + `TRANSMITTER_STEP`)."""

    mmsi: list[int]
    all: VesselReports
    bounds: np.ndarray
    seconds: dict[int, VesselReports]

    def of(self, k: int) -> VesselReports:
        """The `k`-th vessel's reports."""
        return part(self.all, self.bounds[k], self.bounds[k + 1], self.mmsi[k])

    @property
    def sizes(self) -> np.ndarray:
        return np.diff(self.bounds)


def clean_together(mmsi: list[int], rows: list[np.ndarray], ingest: IngestSettings) -> Together:
    """The reports that ingest would keep in reports.parquet of each window (`rows`: one row
    of `vessels.FIELDS` per report), all windows cleaned in one pass, as ingest cleans a
    partition of whole vessels: the table's and the cleaning's fixed cost is paid once per
    chunk, not once per vessel."""
    sizes = [len(r) for r in rows]
    data = np.concatenate(rows) if rows else np.zeros((0, len(FIELDS)))
    cols = {k: data[:, i] for i, k in enumerate(FIELDS)}
    status = cols["status"]
    n = len(status)
    table = pa.table(
        [
            np.repeat(np.array(mmsi, np.int64), sizes),
            pa.array(cols["time_us"].astype(np.int64), pa.int64()).view(
                pa.timestamp("us", tz="UTC")
            ),
            cols["lon"], cols["lat"], cols["sog"], cols["cog"],
            cols["heading"].astype(np.float32),
            pa.array(status.astype(np.int16), mask=status < 0),
            np.zeros(n, np.int32),
        ],
        schema=PARTITION_SCHEMA,
    )  # fmt: skip
    table, codes = clean_vessels(table, ingest)
    keep = np.isin(codes, KEPT)
    c = {name: np.asarray(table.column(name).to_numpy(zero_copy_only=False))[keep]
         for name in ("mmsi", "time", "lon", "lat", "sog", "cog", "heading", "status")}  # fmt: skip
    order = sorted(mmsi)
    bounds = np.searchsorted(c["mmsi"], [*order, (order[-1] + 1) if order else 0])
    every = VesselReports(
        -1, c["time"].view(np.int64) / 1e6, c["lon"], c["lat"], c["sog"], c["cog"],
        c["heading"].astype(np.float64),
        np.nan_to_num(c["status"].astype(np.float64), nan=-1.0), np.full(len(c["lon"]), -1.0),
    )  # fmt: skip
    seconds = {}  # second transmitters' ids sort after every MMSI: past bounds[-1]
    for second in np.unique(c["mmsi"][bounds[-1] :]).tolist() if len(order) else []:
        a, b = np.searchsorted(c["mmsi"], [second, second + 1])
        seconds[second] = part(every, a, b, second)
    return Together(order, part(every, 0, bounds[-1], -1), bounds, seconds)


def part(v: VesselReports, a: int, b: int, mmsi: int) -> VesselReports:
    """Reports `a:b` of `v`, as vessel `mmsi`'s."""
    return VesselReports(
        mmsi, v.time_s[a:b], v.lon[a:b], v.lat[a:b], v.sog[a:b], v.cog[a:b], v.heading[a:b],
        v.status[a:b], v.track_id[a:b],
    )  # fmt: skip


@dataclass(frozen=True)
class Verdict:
    """A chunk's judgement: the vessels whose events were looked for, each one's `Judged`; the
    last report of every vessel with a report left (`LastReport`); and all their cleaned
    reports (`Together`)."""

    judged: dict[int, Judged]
    last: dict[int, LastReport]
    reports: Together

    def reports_of(self, mmsi: int) -> VesselReports:
        """A vessel's cleaned reports."""
        return self.reports.of(bisect.bisect_left(self.reports.mmsi, mmsi))

    def quiet(self, mmsi: int) -> Judged:
        """The judgement of a vessel the screen cleared: no event (what the finders give)."""
        v = self.reports_of(mmsi)
        return Judged([], float(v.time_s[0]), float(v.time_s[-1]), v)


def judge(
    windows: dict[int, tuple[np.ndarray, Identity]],
    rules: EventRules,
    ingest: IngestSettings,
) -> Verdict:
    """The model-free events of the vessels (MMSI: its window's rows and identity) in which
    the screen (`aisdati.live.screen.may_find`) says some kind may find one, by those kinds
    alone (the others find nothing there), in MMSI order (the vessels cleared have none:
    `Verdict.quiet`); a vessel with no report left is left out."""
    mmsi = list(windows)
    together = clean_together(mmsi, [rows for rows, _ in windows.values()], ingest)
    land = land_mask(together.all.positions(), rules.seen)
    last = last_reports(together, land, rules)
    busy = may_find(together.all, together.bounds, land, rules)
    judged = {}
    for k, m in enumerate(together.mmsi):
        if together.bounds[k] == together.bounds[k + 1]:
            continue
        v, identity = together.of(k), windows[m][1]
        second = together.seconds.get(m + TRANSMITTER_STEP)
        events = identity_events(v, second, identity, rules)
        if not busy[k] and not events:
            continue
        if busy[k]:
            who = {"name": identity.name, "ship_type": identity.ship_type}
            ashore = None if land is None else land[together.bounds[k] : together.bounds[k + 1]]
            found = rules.events(v, identity.length_m, busy[k], ashore)
            events = placed_rows(v, found, who, rules.thresholds) + events
        judged[m] = Judged(events, float(v.time_s[0]), float(v.time_s[-1]), v)
    return Verdict(judged, last, together)


def identity_events(
    v: VesselReports, second: VesselReports | None, identity: Identity, rules: EventRules
) -> list[dict[str, Any]]:
    """A window's identity events, as the batch finds them (`aisdati.events.identity`): the
    conflict of its two transmitters (`second`: the second's reports, None: one), and each
    change of its identity history within the window (an earlier one was raised by the window
    that held it). The screen does not judge these: they are looked for in every window."""
    who = {"mmsi": v.mmsi, "name": identity.name, "ship_type": identity.ship_type}
    rows = []
    if second is not None:
        rows += conflict_rows(v, second, (who, {**who, "mmsi": second.mmsi}))
    if len(identity.history) > 1:  # one identity changes nothing
        changes = identity_changes(identity.history_table(), rules.settings.identity_repeats)
        at = [pd.Timestamp(after["first"]).timestamp() for _, after in changes]
        rows += [
            change_row(v, a, b, who)
            for (a, b), t in zip(changes, at, strict=True)
            if v.time_s[0] <= t
        ]
    return rows


def last_reports(
    together: Together, land: np.ndarray | None, rules: EventRules
) -> dict[int, LastReport]:
    """Each vessel's last report and its silence limit, by the gap kind's own rule
    (`aisdati.events.behaviour.gap_limit`, here for all vessels at once: `silence_limit`),
    whether it is ashore by the one land check (`land`: `land_mask` of all the reports)."""
    v, sizes = together.all, together.sizes
    has = np.flatnonzero(sizes > 0)
    if not has.size:
        return {}
    ends = together.bounds[1:][has] - 1
    usual = median_steps(v.time_s, together.bounds[:-1][has], sizes[has])
    s = rules.settings
    limit = silence_limit(usual, s)
    can = (sizes[has] >= 3) & (v.sog[ends] >= s.gap_under_way_kn)
    ashore = np.zeros(len(ends), bool) if land is None else land[ends]
    rows = zip(
        has.tolist(), v.time_s[ends].tolist(), v.lon[ends].tolist(), v.lat[ends].tolist(),
        limit.tolist(), usual.tolist(), can.tolist(), ashore.tolist(), strict=True,
    )  # fmt: skip
    return {
        together.mmsi[k]: LastReport(together.mmsi[k], t, x, y, lim if ok else None, u, a)
        for k, t, x, y, lim, u, ok, a in rows
    }


def median_steps(time_s: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Each vessel's median interval between reports (as `np.median` of its `dt_s`; NaN with
    fewer than two reports), for vessels whose reports lie at `starts` (`sizes` of them)."""
    steps = sizes - 1
    out = np.full(len(sizes), np.nan)
    ok = np.flatnonzero(steps > 0)
    if not ok.size:
        return out
    group = np.repeat(np.arange(len(ok)), steps[ok])
    first = np.repeat(starts[ok] - np.cumsum(np.r_[0, steps[ok][:-1]]), steps[ok])
    at = np.arange(len(group)) + first
    dt = time_s[at + 1] - time_s[at]
    dt = dt[np.lexsort((dt, group))]
    base = np.r_[0, np.cumsum(steps[ok])[:-1]]
    lo, hi = base + (steps[ok] - 1) // 2, base + steps[ok] // 2
    out[ok] = (dt[lo] + dt[hi]) / 2
    return out
