"""A vessel's window judged as the batch judges its reports: cleaned per vessel as ingest
cleans reports.parquet (`clean.clean_vessels`: duplicates, repeated times and position
outliers out), then every model-free kind of `aisdati.events.find.find_events`, placed as the
rows of events.parquet. Nothing here redefines a kind."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.events.find import find_events, placed
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.live.decode import Identity
from aisdati.preprocess.clean import clean_vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings

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


@dataclass(frozen=True)
class Judged:
    """A vessel's events found in its window, and the window's first and last report time."""

    events: pd.DataFrame
    first_s: float
    last_s: float
    last: LastReport


def cleaned(mmsi: int, cols: dict[str, np.ndarray], ingest: IngestSettings) -> VesselReports:
    """The window's reports that ingest would keep in reports.parquet, sorted by time."""
    n = len(cols["time_us"])
    status = cols["status"]
    table = pa.table(
        [
            np.full(n, mmsi, np.int64),
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
         for name in ("time", "lon", "lat", "sog", "cog", "heading", "status")}  # fmt: skip
    return VesselReports(
        mmsi, c["time"].view(np.int64) / 1e6, c["lon"], c["lat"], c["sog"], c["cog"],
        c["heading"].astype(np.float64), np.nan_to_num(c["status"].astype(np.float64), nan=-1.0),
        np.full(int(keep.sum()), -1.0),
    )  # fmt: skip


def judge(
    mmsi: int,
    cols: dict[str, np.ndarray],
    identity: Identity,
    settings: EventSettings,
    ingest: IngestSettings,
) -> Judged | None:
    """The model-free events of a vessel's window (None: no report left to judge)."""
    if len(cols["time_us"]) == 0:
        return None
    v = cleaned(mmsi, cols, ingest)
    if len(v) == 0:
        return None
    who = {"name": identity.name, "ship_type": identity.ship_type}
    events = placed(v, find_events(v, settings, identity.length_m), who)
    return Judged(events, float(v.time_s[0]), float(v.time_s[-1]), last_report(v, settings))


def last_report(v: VesselReports, settings: EventSettings) -> LastReport:
    """The vessel's last report and its silence limit, by the gap kind's own rule
    (`aisdati.events.behaviour.gaps`)."""
    usual = float(np.median(v.dt_s)) if len(v) > 1 else np.nan
    limit = None
    if len(v) >= 3 and v.sog[-1] >= settings.gap_under_way_kn:
        limit = max(settings.gap_min_s, settings.gap_factor * usual)
    return LastReport(v.mmsi, float(v.time_s[-1]), float(v.lon[-1]), float(v.lat[-1]), limit, usual)
