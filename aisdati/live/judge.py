"""A vessel's window judged as the batch judges its reports: cleaned per vessel as ingest
cleans reports.parquet (`clean.clean_vessels`: duplicates, repeated times and position
outliers out), then every model-free kind of `aisdati.events.find.find_events`, placed as the
rows of events.parquet. Nothing here redefines a kind."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.events.behaviour import gap_limit, land_mask
from aisdati.events.find import placed_rows
from aisdati.events.identity import change_row, conflict_rows, identity_changes
from aisdati.events.reports import VesselReports
from aisdati.events.rules import EventRules
from aisdati.live.decode import Identity
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
    last: LastReport
    reports: VesselReports
    unjudged: frozenset[str] = frozenset()


def cleaned(
    windows: dict[int, dict[str, np.ndarray]], ingest: IngestSettings
) -> dict[int, VesselReports]:
    """Each window's reports that ingest would keep in reports.parquet, sorted by time; all
    windows cleaned in one pass, as ingest cleans a partition of whole vessels: the table's and
    the cleaning's fixed cost is paid once per chunk, not once per vessel. A window heard from
    two transmitters (`aisdati.preprocess.transmitters`) gives its second's reports under the
    second's id (MMSI + `TRANSMITTER_STEP`) too."""
    sizes = [len(w["time_us"]) for w in windows.values()]
    status = np.concatenate([w["status"] for w in windows.values()])
    n = len(status)
    cols = {k: np.concatenate([w[k] for w in windows.values()]) for k in FIELDS}
    table = pa.table(
        [
            np.repeat(np.array(list(windows), np.int64), sizes),
            pa.array(cols["time_us"], pa.int64()).view(pa.timestamp("us", tz="UTC")),
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
    time_s = c["time"].view(np.int64) / 1e6
    heading = c["heading"].astype(np.float64)
    status_code = np.nan_to_num(c["status"].astype(np.float64), nan=-1.0)
    out = {}
    present = set(np.unique(c["mmsi"]).tolist())
    for mmsi in [*windows, *(m + TRANSMITTER_STEP for m in windows)]:
        if mmsi >= TRANSMITTER_STEP and mmsi not in present:
            continue
        lo, hi = np.searchsorted(c["mmsi"], [mmsi, mmsi + 1])
        out[mmsi] = VesselReports(
            mmsi, time_s[lo:hi], c["lon"][lo:hi], c["lat"][lo:hi], c["sog"][lo:hi],
            c["cog"][lo:hi], heading[lo:hi], status_code[lo:hi], np.full(hi - lo, -1.0),
        )  # fmt: skip
    return out


def judge(
    windows: dict[int, tuple[dict[str, np.ndarray], Identity]],
    rules: EventRules,
    ingest: IngestSettings,
) -> dict[int, Judged]:
    """The model-free events of each vessel's window (MMSI: its window and identity), in the
    windows' order, with its `identity-conflict` where two transmitters share its MMSI (the
    batch's rule, `aisdati.events.identity.conflict_rows`) and its `identity-change`s by its
    identity history (`identity.history`, `aisdati.events.identity.identity_changes`); a
    vessel with no report left to judge is left out."""
    if not windows:
        return {}
    reports = cleaned({m: cols for m, (cols, _) in windows.items()}, ingest)
    out = {}
    for mmsi, (_, identity) in windows.items():
        v = reports[mmsi]
        if len(v) == 0:
            continue
        who = {"name": identity.name, "ship_type": identity.ship_type}
        events = placed_rows(v, rules.events(v, identity.length_m), who, rules.thresholds)
        events += identity_events(v, reports.get(mmsi + TRANSMITTER_STEP), identity, rules)
        out[mmsi] = Judged(
            events, float(v.time_s[0]), float(v.time_s[-1]), last_report(v, rules), v
        )
    return out


def last_report(v: VesselReports, rules: EventRules) -> LastReport:
    """The vessel's last report and its silence limit, by the gap kind's own rule
    (`aisdati.events.behaviour.gap_limit`)."""
    usual = float(np.median(v.dt_s)) if len(v) > 1 else np.nan
    limit = None
    if len(v) >= 3 and v.sog[-1] >= rules.settings.gap_under_way_kn:
        limit = gap_limit(v, rules.settings)
    land = land_mask(v.positions(slice(-1, None)), rules.seen)
    return LastReport(
        v.mmsi, float(v.time_s[-1]), float(v.lon[-1]), float(v.lat[-1]), limit, usual,
        land is not None and bool(land[0]),
    )  # fmt: skip


def identity_events(
    v: VesselReports, second: VesselReports | None, identity: Identity, rules: EventRules
) -> list[dict[str, Any]]:
    """A window's identity events, as the batch finds them (`aisdati.events.identity`): the
    conflict of its two transmitters (`second`: the second's reports, None: one), and each
    change of its identity history within the window (an earlier one was raised by the window
    that held it)."""
    who = {"mmsi": v.mmsi, "name": identity.name, "ship_type": identity.ship_type}
    rows = []
    if second is not None:
        rows += conflict_rows(v, second, (who, {**who, "mmsi": second.mmsi}))
    history = identity.history_table()
    if history is not None:
        repeats = rules.settings.identity_repeats
        changes = identity_changes(history, repeats)
        at = [pd.Timestamp(after["first"]).timestamp() for _, after in changes]
        rows += [
            change_row(v, a, b, who)
            for (a, b), t in zip(changes, at, strict=True)
            if v.time_s[0] <= t
        ]
    return rows
