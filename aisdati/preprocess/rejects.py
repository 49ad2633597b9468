"""Rows of rejects.parquet (`--keep-rejects`): what a stage rejected, with its reason and where
it came from."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from aisdati.preprocess.report import N_CODES, REASONS
from aisdati.tracks.schema import REJECTS_SCHEMA

_REASON_NAMES = np.array([""] + [REASONS[code][1] for code in range(1, N_CODES)], dtype=object)


def reject_rows(table: pa.Table, codes: np.ndarray, source: str | list[str]) -> pa.Table:
    """The rejected rows of a table, with their reason and source (one label, or the labels of
    every source, picked by the rows' `src`), in the rejects schema."""
    idx = np.flatnonzero(codes != 0)
    rows = table.take(pa.array(idx))
    if isinstance(source, str):
        sources = pa.array([source] * len(idx), pa.string())
    else:
        sources = pa.array(np.array(source, dtype=object)[rows.column("src").to_numpy()])
    return pa.table(
        [
            sources,
            pa.array(_REASON_NAMES[codes[idx]], pa.string()),
            rows.column("mmsi"),
            rows.column("time"),
            rows.column("lon"),
            rows.column("lat"),
            rows.column("sog"),
            rows.column("cog"),
            pa.nulls(len(idx), pa.string()),
        ],
        schema=REJECTS_SCHEMA,
    )


def malformed_rows(texts: list[str | None], source: str, reason: str) -> pa.Table:
    """Lines that gave no row (malformed CSV, unusable NMEA): their text, reason and source."""
    n = len(texts)
    columns = {name: pa.nulls(n, REJECTS_SCHEMA.field(name).type) for name in REJECTS_SCHEMA.names}
    columns["source"] = pa.array([source] * n, pa.string())
    columns["reason"] = pa.array([reason] * n, pa.string())
    columns["raw"] = pa.array(texts, pa.string())
    return pa.table(columns, schema=REJECTS_SCHEMA)
