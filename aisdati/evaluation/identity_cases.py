"""Constructed cases of the identity kinds (`aisdati.evaluation.constructed.CONSTRUCTORS`),
written into real traffic: `identity-conflict`, two real vessels' reports under one MMSI while
both sail at places no vessel could join, the merged MMSI cleaned as ingest cleans it
(`aisdati.preprocess.clean.clean_vessels`: what reports.parquet would hold had the input
carried them); `identity-change`, a real vessel's name, type or length changed at one of its
reports, the rest of its reports giving the new one. The identity history (identities.parquet,
`aisdati.tracks.schema.IDENTITY_SCHEMA`) travels as `identity.attrs["history"]` (the
registry's `identity` frame is vessels.parquet by MMSI): evaluate it with
`model_free_events(reports, identity, history=identity.attrs["history"])`."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.evaluation.case import Case
from aisdati.events.identity import REACH_KN, differs
from aisdati.geo import haversine_m
from aisdati.preprocess.clean import clean_vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings
from aisdati.tracks.schema import (
    IDENTITY_SCHEMA,
    KNOT_MPS,
    REPORTS_SCHEMA,
    TRANSMITTER_STEP,
    VESSEL_COLUMNS,
)

MIN_OVERLAP_REPORTS = 20
"""Reports each vessel needs while both sail, for a conflict case (a transmitter of a few is
an outlier, not a case)."""
MIN_APART_M = 1000.0
"""The least distance between the two vessels' reports at once: places apart."""
EPOCH = pd.Timestamp(0, tz="UTC")
AT_ONCE_S = 600.0
"""Reports of the two this close in time are sent at once."""
TRIES = 50
"""Pairs or vessels drawn before giving up on a traffic."""
CHANGED = ("name", "name", "ship_type", "length_m")
"""The field a change case changes, drawn uniformly (a rename is the most common change)."""


def merged_mmsi(reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator):
    """Two vessels sailing at once at places no vessel could join: the second's reports of that
    time under the first's MMSI (the rest of the second's removed), cleaned as ingest would."""
    counts = reports.groupby("mmsi").size()
    vessels = counts[(counts.index < TRANSMITTER_STEP) & (counts >= MIN_OVERLAP_REPORTS)].index
    for _ in range(TRIES):
        if len(vessels) < 2:
            return None
        a, b = (int(m) for m in rng.choice(vessels.to_numpy(), 2, replace=False))
        first, second = (reports[reports["mmsi"] == m] for m in (a, b))
        apart = _out_of_reach(first, second)
        if apart.sum() < MIN_OVERLAP_REPORTS:
            continue
        times = second["time"].to_numpy()[apart]
        start, end = pd.Timestamp(times.min()), pd.Timestamp(times.max())
        if first["time"].between(start, end).sum() < MIN_OVERLAP_REPORTS:
            continue
        moved = second[second["time"].between(start, end)].assign(mmsi=a)
        rest = reports[~reports["mmsi"].isin([a, b])]
        out = pd.concat([rest, cleaned(pd.concat([first, moved]))], ignore_index=True)
        case = Case("identity-conflict", (a,), start, end)
        return out.sort_values(["mmsi", "time"], kind="stable"), identity, case
    return None


def _out_of_reach(first: pd.DataFrame, second: pd.DataFrame) -> np.ndarray:
    """Which of `second`'s reports are within `AT_ONCE_S` of one of `first`'s (the nearest in
    time) and farther from it than `REACH_KN` covers in the time between them."""
    t1, t2 = (_seconds(v["time"]) for v in (first, second))
    at = np.clip(np.searchsorted(t1, t2), 1, len(t1) - 1)
    at = np.where(np.abs(t1[at - 1] - t2) < np.abs(t1[at] - t2), at - 1, at)
    dt = np.abs(t1[at] - t2)
    lon, lat = first["lon"].to_numpy()[at], first["lat"].to_numpy()[at]
    dist = haversine_m(lon, lat, second["lon"].to_numpy(), second["lat"].to_numpy())
    return (dt <= AT_ONCE_S) & (dist > REACH_KN * KNOT_MPS * dt + 50.0) & (dist > MIN_APART_M)


def _seconds(time: pd.Series) -> np.ndarray:
    return (pd.to_datetime(time, utc=True) - EPOCH).dt.total_seconds().to_numpy()


def cleaned(rows: pd.DataFrame) -> pd.DataFrame:
    """Reports as ingest keeps them in reports.parquet (`clean_vessels`, slow ones kept), their
    tracks unknown (null)."""
    frame = rows.assign(src=0)[PARTITION_SCHEMA.names]
    table = pa.Table.from_pandas(frame, PARTITION_SCHEMA, preserve_index=False)
    table, codes = clean_vessels(table, IngestSettings())
    kept = table.filter(pa.array(np.isin(codes, (0, CODE["slow"])))).to_pandas()
    kept["sog"], kept["cog"] = kept["sog"].astype("float32"), kept["cog"].astype("float32")
    return kept.drop(columns="src").assign(track_id=np.nan)[REPORTS_SCHEMA.names]


def renamed(reports: pd.DataFrame, identity: pd.DataFrame, rng: np.random.Generator):
    """A vessel whose name (or type, or length) becomes another real vessel's at one of its
    reports, the identity history written to say so."""
    history = identity.attrs.get("history")
    counts = reports.groupby("mmsi").size()
    for _ in range(TRIES):
        field = CHANGED[rng.integers(len(CHANGED))]
        givers = identity[identity[field].notna()]
        named = givers.index.intersection(counts[counts >= 10].index)
        named = named[named < TRANSMITTER_STEP]
        if len(named) < 1 or givers[field].nunique() < 2:
            continue
        mmsi = int(rng.choice(named.to_numpy()))
        old = identity.loc[mmsi]
        before = {f: old[f] for f in VESSEL_COLUMNS}
        after = {**before, field: givers.loc[rng.choice(givers.index.to_numpy()), field]}
        if not differs(before, after):
            continue
        times = reports.loc[reports["mmsi"] == mmsi, "time"].sort_values().to_numpy()
        k = int(rng.integers(len(times) // 4, 3 * len(times) // 4))
        rows = [
            _history_row(mmsi, before, times[0], times[k - 1], k),
            _history_row(mmsi, after, times[k], times[-1], len(times) - k),
        ]
        kept = history[history["mmsi"] != mmsi] if history is not None else None
        out = identity.copy()
        out.attrs["history"] = pd.concat([kept, pd.DataFrame(rows)], ignore_index=True)
        at = pd.Timestamp(times[k])
        return reports, out, Case("identity-change", (mmsi,), at, at)
    return None


def _history_row(mmsi: int, values: dict, first, last, n: int) -> dict:
    """A row of identities.parquet (`IDENTITY_SCHEMA`)."""
    row = {"mmsi": mmsi, **values, "first": pd.Timestamp(first), "last": pd.Timestamp(last)}
    return {key: row.get(key, n) for key in IDENTITY_SCHEMA.names}
