"""reports.parquet: every report judged, whatever its speed.

The paper's SOG filter (`--min-sog`) shapes what a model learns from: the tracks hold the
reports of vessels under way. What is judged keeps every report, so that a vessel that drifts,
loiters, stops or slows down abruptly is judged on those reports too. The read stage therefore
spills the slow reports beside the others (`tasks.read_source`), and each vessel partition is
cleaned twice, side by side: its moving reports as ever, to make the tracks (points.parquet,
tracks.parquet unchanged), and all its reports (duplicates, repeated times and position
outliers rejected alike) into reports.parquet (`tasks.report_stages`), each given, when written,
the track whose point it is (`with_track_ids`: the same vessel and time).
"""

from __future__ import annotations

import numba
import numpy as np
import pyarrow as pa

from aisdati.preprocess.output import cog32
from aisdati.tracks.schema import REPORTS_SCHEMA

PointKeys = tuple[np.ndarray, np.ndarray, np.ndarray]
"""A partition's points as (MMSI, time in microseconds, track id), sorted by (MMSI, time)."""


def point_keys(points: pa.Table) -> PointKeys:
    """The keys of a partition's rows of points.parquet (as they were made: sorted by MMSI and
    time)."""
    return (
        points.column("mmsi").to_numpy(),
        points.column("time").to_numpy().view(np.int64),
        points.column("track_id").to_numpy(),
    )


def report_rows(rows: pa.Table) -> pa.Table:
    """Cleaned rows of a partition (`convert.PARTITION_SCHEMA`, sorted by MMSI and time) as rows
    of reports.parquet, without their tracks yet."""
    return pa.table(
        [
            rows.column("mmsi"),
            rows.column("time"),
            rows.column("lon"),
            rows.column("lat"),
            rows.column("sog").cast(pa.float32()),
            cog32(rows.column("cog").to_numpy()),
            rows.column("heading"),
            rows.column("status"),
            pa.nulls(rows.num_rows, pa.int64()),
        ],
        schema=REPORTS_SCHEMA,
    )


def with_track_ids(reports: pa.Table, points: PointKeys) -> pa.Table:
    """Rows of reports.parquet (sorted by MMSI and time) with the id of the track whose point
    each is (null: none)."""
    time_us = reports.column("time").to_numpy().view(np.int64)
    track = track_of(reports.column("mmsi").to_numpy(), time_us, *points)
    at = reports.schema.get_field_index("track_id")
    return reports.set_column(at, "track_id", pa.array(track, pa.int64(), mask=track < 0))


@numba.njit(cache=True, nogil=True)
def track_of(mmsi, time_us, point_mmsi, point_time, point_track):  # pragma: no cover - compiled
    """The track of each report (sorted by MMSI and time) that is a point (the same MMSI and
    time; points sorted alike), -1 for the others: one merge of the two sequences, from the
    first point of the reports' first vessel."""
    out = np.full(mmsi.shape[0], -1, np.int64)
    if mmsi.shape[0] == 0:
        return out
    j = np.searchsorted(point_mmsi, mmsi[0])
    for i in range(mmsi.shape[0]):
        while j < point_mmsi.shape[0] and (
            point_mmsi[j] < mmsi[i] or (point_mmsi[j] == mmsi[i] and point_time[j] < time_us[i])
        ):
            j += 1
        if j < point_mmsi.shape[0] and point_mmsi[j] == mmsi[i] and point_time[j] == time_us[i]:
            out[i] = point_track[j]
    return out
