"""The tasks of `aisdati ingest`: each a module-level function of one picklable description, so
that a Dask worker runs it as well as this process does (`aisdati.execution.runner`).

* `read_source` (`ReadTask`): one input source read, checked and filtered batch by batch, its
  survivors spilled into vessel partitions of its own (its slow reports into partitions of
  their own beside them), its rejects into a part of its own; who its vessels are tallied.
* `vessel_stages` (`VesselTask`): one vessel partition, from the spill files of every source:
  its moving reports cleaned per vessel, segmented and made tracks; its points and its rows of
  tracks.parquet spilled with the partition's own track numbers (0, 1, ...), the rows but their
  geometry returned, with each track's shape for route clustering (`TrackShapes`).
* `report_stages` (`ReportsTask`), beside it: all the partition's reports, slow ones too,
  cleaned per vessel and spilled as rows of reports.parquet (`aisdati.preprocess.reports`).
* `write_part` (`PartTask`): a partition's points, or its reports (each given the track whose
  point it is), as one part of points.parquet or reports.parquet, its track numbers shifted past
  the tracks of the partitions before it: the ids one process numbering the tracks in partition
  order would give.

They share files in folders every worker sees (the spill folder and the staging folder, both
in --out) and return small things only: counts, track summaries, 32-point shapes, vessel
tallies. A task never deletes its inputs: one lost with its worker (even after it ended, before
its result was fetched) is run again on the same files and writes the same outputs.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from rich.progress import Progress

from aisdati.errors import UserError
from aisdati.preprocess.clean import (
    check_values,
    clean_vessels,
    filter_area_speed,
    filter_period,
)
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.inputs import Source, describe_read_error
from aisdati.preprocess.output import PartWriter, build_tracks
from aisdati.preprocess.partition import (
    VesselPartitions,
    partition_tables,
    split_rows,
    write_split,
)
from aisdati.preprocess.read import TableReader, open_reader
from aisdati.preprocess.rejects import malformed_rows, reject_rows
from aisdati.preprocess.report import CODE, IngestCounts
from aisdati.preprocess.reports import point_keys, report_rows, with_track_ids
from aisdati.preprocess.routes import TrackShapes
from aisdati.preprocess.routes import settings_of as route_settings
from aisdati.preprocess.segment import antimeridian_crossing, antimeridian_message, segment
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.stops import Splitter, dwell_rules
from aisdati.preprocess.streams import READ_ERRORS
from aisdati.tracks.schema import POINTS_SCHEMA, REJECTS_SCHEMA, REPORTS_SCHEMA, TRACKS_SCHEMA


@dataclass(frozen=True)
class ReadTask:
    """Source number `src`, its survivors spilled into `n_parts` partition files in the folder
    `spill` (made by the task), its rejects into part `src` of the dataset folder `rejects`."""

    source: Source
    src: int
    spill: Path
    n_parts: int
    settings: IngestSettings
    roi: Any
    rejects: Path | None = None


@dataclass(frozen=True)
class ReadResult:
    counts: IngestCounts
    """Rows read and rejected, and the source's entry of the report's `files`."""
    folder: Path
    """The task's spill folder."""
    spills: tuple[Path, ...]
    """The source's file of each partition (written where `rows` is not 0)."""
    rows: np.ndarray
    """Rows spilled into each partition."""
    slow_spills: tuple[Path, ...]
    """The source's file of each partition's slow reports (written where `slow_rows` is not 0):
    not in the tracks, but in reports.parquet."""
    slow_rows: np.ndarray
    vessels: pa.Table
    """Who the source's vessels are (`vessels.VesselTally.table`)."""


def read_source(task: ReadTask, progress: Progress | None = None) -> ReadResult:
    """Row-wise stages over one source, batch by batch (a bar of its bytes on `progress`)."""
    reader = open_reader(task.source)
    label = task.source.label
    bar = progress.add_task(f"read {label}", total=reader.total) if progress else None
    shutil.rmtree(task.spill, ignore_errors=True)  # what an earlier try of this task left
    task.spill.mkdir()
    parts = VesselPartitions(task.spill, task.n_parts, PARTITION_SCHEMA)
    slow = VesselPartitions(task.spill, task.n_parts, PARTITION_SCHEMA, prefix="slow")
    counts = IngestCounts()
    with contextlib.ExitStack() as stack:
        rejects = _rejects_part(stack, task.rejects, task.src)
        try:
            rows = _spill_rows(reader, task, (parts, slow), rejects, counts, progress, bar)
        except READ_ERRORS as exc:
            raise describe_read_error(task.source, exc) from None
        finally:
            parts.close()
            slow.close()
        skipped = reader.skipped  # lines that gave no row (malformed CSV, bad NMEA), by reason
        for reason, texts in skipped.items():
            counts.add(reason, len(texts))
            if rejects and texts:
                rejects.write(malformed_rows(texts, label, reason))
    counts.rows_read = rows + sum(len(texts) for texts in skipped.values())
    counts.files.append(
        {
            "source": label,
            "rows": counts.rows_read,
            "columns": reader.columns,
            "derived": [c for c in ("sog", "cog") if c not in reader.columns],
        }
    )
    if bar is not None:
        progress.update(bar, completed=reader.total)
    vessels = reader.vessels.table(task.src)
    return ReadResult(
        counts, task.spill, tuple(parts.paths), parts.rows, tuple(slow.paths), slow.rows, vessels
    )


def _spill_rows(
    reader: TableReader,
    task: ReadTask,
    spills: tuple[VesselPartitions, VesselPartitions],
    rejects: PartWriter | None,
    counts: IngestCounts,
    progress: Progress | None,
    bar: Any,
) -> int:
    """The source's rows checked and filtered, the kept ones spilled into the first partitions,
    the slow ones into the second, the others counted (and written to `rejects`); the rows."""
    rows = 0
    for table, codes in reader.tables(task.src):
        table = check_values(table, codes)
        filter_period(table, codes, task.settings)
        filter_area_speed(table, codes, task.roi, task.settings)
        rows += len(codes)
        counts.add_codes(codes)
        which = np.where(codes == 0, 0, np.where(codes == CODE["slow"], 1, -1))
        write_split(table, which, spills)  # the moving reports, and the slow ones beside
        if rejects:
            rejects.write(reject_rows(table, codes, task.source.label))
        if bar is not None:
            progress.update(bar, completed=reader.done)
    return rows


def _rejects_part(
    stack: contextlib.ExitStack, folder: Path | None, index: int
) -> PartWriter | None:
    """Part `index` of the rejects dataset, open for the time of `stack` (None: not kept)."""
    return stack.enter_context(PartWriter(folder, index, REJECTS_SCHEMA)) if folder else None


@dataclass(frozen=True)
class VesselTask:
    """Partition `part`, spilled to `spills` (in source order; `rows` in all), its points
    spilled to `points`, its rejects written as part `reject_part` of the folder `rejects`
    (`labels`: the sources' labels, by source number)."""

    part: int
    spills: tuple[Path, ...]
    rows: int
    points: Path
    settings: IngestSettings
    labels: tuple[str, ...]
    rejects: Path | None = None
    reject_part: int = 0

    @property
    def tracks(self) -> Path:
        """Where the partition's rows of tracks.parquet, geometry and all, are spilled."""
        return self.points.with_name(self.points.stem.replace("points", "tracks") + ".arrow")


@dataclass(frozen=True)
class VesselResult:
    counts: IngestCounts
    tracks: pa.Table
    """One row per track (tracks.parquet's schema but its geometry, which stays in the spill
    file `VesselTask.tracks`), numbered from 0 in the partition."""
    shapes: TrackShapes | None
    """The tracks' shapes for route clustering (None with `--clusters direction`)."""
    vessels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """The MMSIs (sorted) of the partition's points."""


def vessel_stages(task: VesselTask) -> VesselResult:
    """Per-vessel cleaning, segmentation and clustering of one partition (a large one piece by
    piece: `partition_tables`), its points spilled as they come."""
    settings = task.settings
    counts = IngestCounts()
    with contextlib.ExitStack() as stack:
        rejects = _rejects_part(stack, task.rejects, task.reject_part)
        tracks, shapes, vessels = _make_tracks(task, counts, rejects)
    empty = TRACKS_SCHEMA.empty_table().drop_columns(["geometry"])
    table = pa.concat_tables(tracks) if tracks else empty
    samples = route_settings(settings).samples
    joined = TrackShapes.joined(shapes, samples) if settings.clusters == "routes" else None
    return VesselResult(counts, table, joined, vessels)


def _make_tracks(
    task: VesselTask, counts: IngestCounts, rejects: PartWriter | None
) -> tuple[list[pa.Table], list[TrackShapes], np.ndarray]:
    """The partition's reports made tracks: their points and rows spilled; the rows but their
    geometry, the tracks' shapes (with `--clusters routes`) and the points' MMSIs returned."""
    settings = task.settings
    tracks: list[pa.Table] = []
    shapes: list[TrackShapes] = []
    vessels = [np.zeros(0, np.int64)]
    samples = route_settings(settings).samples
    stops = dwell_rules(settings.dwell_radius_m, settings.dwell_time_s, settings.min_sog_kn)
    with (
        pa.ipc.new_stream(str(task.points), POINTS_SCHEMA) as points,
        pa.ipc.new_stream(str(task.tracks), TRACKS_SCHEMA) as spilled,
    ):
        pieces = partition_tables(
            task.spills, PARTITION_SCHEMA, task.rows, settings.rows_per_bucket,
            _independent_s(settings), _flooded(counts, rejects, task.labels),
        )  # fmt: skip
        for table in pieces:
            table, codes = clean_vessels(table, settings)
            track = _segment(table, codes, settings, stops, counts)
            counts.add_codes(codes)
            if rejects:
                rejects.write(reject_rows(table, codes, list(task.labels)))
            if (track >= 0).any():
                first_id = sum(t.num_rows for t in tracks)
                rows = table.take(pa.array(np.flatnonzero(track >= 0)))
                out_points, out_tracks = build_tracks(rows, track[track >= 0], first_id)
                points.write_table(out_points)
                spilled.write_table(out_tracks)
                tracks.append(out_tracks.drop_columns(["geometry"]))
                vessels.append(out_tracks.column("mmsi").to_numpy())
                if settings.clusters == "routes":
                    shapes.append(TrackShapes.of(_lines(out_points), samples))
                counts.kept_points += out_points.num_rows
                for name in out_tracks.column("cluster").to_pylist():
                    counts.tracks[name] += 1
    return tracks, shapes, np.unique(np.concatenate(vessels))


def _independent_s(settings: IngestSettings) -> float:
    """Reports further apart than both the stop gap and the dwell time are independent."""
    return max(settings.stop_gap_s, settings.dwell_time_s)


@dataclass(frozen=True)
class ReportsTask:
    """Partition `part`'s reports, spilled to `spills` (its moving reports' files, then its slow
    reports', each in source order; `rows` in all), as rows of reports.parquet spilled to `out`
    (their tracks given when written: `write_part`)."""

    part: int
    spills: tuple[Path, ...]
    rows: int
    out: Path
    settings: IngestSettings


@dataclass(frozen=True)
class ReportsResult:
    rows: int
    """Rows of reports.parquet spilled to `ReportsTask.out`."""
    vessels: np.ndarray
    """Their MMSIs, sorted."""


def report_stages(task: ReportsTask) -> ReportsResult:
    """Every report of the partition, moving and slow, cleaned per vessel (duplicates, repeated
    times and position outliers rejected; the reports of a flood at one time beyond a piece's
    worth dropped, as the tracks drop them) and spilled as rows of reports.parquet. A moving
    report comes before a slow one of its vessel at its time, so that the report kept there is
    the one a track may hold."""
    settings = task.settings
    slow = CODE["slow"]  # a SOG derived at or below --min-sog: still a report
    written, vessels = 0, [np.zeros(0, np.int64)]
    with pa.ipc.new_stream(str(task.out), REPORTS_SCHEMA) as out:
        pieces = partition_tables(
            task.spills, PARTITION_SCHEMA, task.rows, settings.rows_per_bucket,
            _independent_s(settings), pieces_as="reports",
        )  # fmt: skip
        for piece in pieces:
            ranges = vessel_ranges(piece, REPORT_RANGES)
            del piece  # (a copy in ranges: the piece's rows are freed)
            for table in ranges:
                table, codes = clean_vessels(table, settings)
                rows = table.filter(pa.array((codes == 0) | (codes == slow)))
                out.write_table(report_rows(rows))
                written += rows.num_rows
                mmsi = rows.column("mmsi").to_numpy()  # sorted: each vessel's first row
                first = np.ones(len(mmsi), bool)
                first[1:] = mmsi[1:] != mmsi[:-1]
                vessels.append(mmsi[first])
            del ranges, table, rows  # (not held while the next piece is read)
    return ReportsResult(written, np.unique(np.concatenate(vessels)))


REPORT_RANGES = 4
"""Ranges of MMSIs a partition's reports are cleaned in, one after the other (`vessel_ranges`):
most of the input's rows are reports, and cleaning a whole partition at once (its rows, their
sorted copy, the kept rows, the rows of reports.parquet) held three to four copies of it."""


def vessel_ranges(table: pa.Table, n: int) -> list[pa.Table]:
    """The rows of `table` in `n` ranges of MMSIs (whole vessels, each range's rows in the
    table's order), from the lowest MMSIs up: cleaned one after the other, they give the rows
    and the order the whole table gives (`clean_vessels` sorts by MMSI and time, stably)."""
    mmsi = table.column("mmsi").to_numpy()
    if n < 2 or len(mmsi) < 2 * n:
        return [table]
    cuts = np.quantile(mmsi, np.arange(1, n) / n, method="lower")
    return [chunk for _, chunk in split_rows(table, np.searchsorted(cuts, mmsi, "right"), n)]


def partition_stage(task: VesselTask | ReportsTask) -> VesselResult | ReportsResult:
    """A vessel partition's task, whichever it is: its tracks, or its reports (the two run side
    by side)."""
    return vessel_stages(task) if isinstance(task, VesselTask) else report_stages(task)


def _flooded(
    counts: IngestCounts, rejects: PartWriter | None, labels: tuple[str, ...]
) -> Callable[[pa.Table], None]:
    """Where the reports of a flood at one time that `partition_tables` drops go: counted, and
    with --keep-rejects written, as `same_time_flood`."""

    def dropped(rows: pa.Table) -> None:
        counts.add("same_time_flood", rows.num_rows)
        if rejects:
            codes = np.full(rows.num_rows, CODE["same_time_flood"], dtype=np.uint8)
            rejects.write(reject_rows(rows, codes, list(labels)))

    return dropped


def _lines(points: pa.Table) -> list[np.ndarray]:
    """Each track's [n, 2] lon/lat line, from its rows of points.parquet (by track, in order)."""
    track = points.column("track_id").to_numpy()
    xy = np.column_stack([points.column("lon").to_numpy(), points.column("lat").to_numpy()])
    return np.split(xy, np.flatnonzero(np.diff(track)) + 1)


def _segment(
    table: pa.Table,
    codes: np.ndarray,
    settings: IngestSettings,
    stops: Sequence[Splitter],
    counts: IngestCounts,
) -> np.ndarray:
    """The track index (from 0; -1: in none) of each row of a cleaned piece, its segmentation
    rejects marked in `codes`."""
    kept = np.flatnonzero(codes == 0)
    time_us = table.column("time").to_numpy().view(np.int64)
    mmsi = table.column("mmsi").to_numpy()
    lon, lat, sog = (table.column(c).to_numpy()[kept] for c in ("lon", "lat", "sog"))
    track, seg_codes, n_short = segment(
        mmsi[kept], time_us[kept], settings.stop_gap_s, settings.min_points, stops,
        lon, lat, sog,
    )  # fmt: skip
    codes[kept] = seg_codes
    counts.short_segments += n_short
    out = np.full(len(codes), -1, dtype=np.int64)
    out[kept] = track
    crossing = antimeridian_crossing(mmsi[kept], lon, track)
    if crossing is not None:
        raise UserError(antimeridian_message(crossing))
    return out


@dataclass(frozen=True)
class PartTask:
    """A partition's points or reports, spilled to `spill`, as part `part` of the dataset
    folder `folder` (of that `schema`), their track numbers shifted by `offset`; reports take
    their tracks from the partition's points, spilled to `points`."""

    spill: Path
    folder: Path
    part: int
    offset: int
    schema: pa.Schema = POINTS_SCHEMA
    points: Path | None = None


def write_part(task: PartTask) -> int:
    """Write one part of points.parquet or reports.parquet, batch by batch; the rows written."""
    keys = None
    if task.points is not None:
        with pa.OSFile(str(task.points)) as f:
            keys = point_keys(pa.ipc.open_stream(f).read_all())
    with PartWriter(task.folder, task.part, task.schema) as part, pa.OSFile(str(task.spill)) as f:
        for batch in pa.ipc.open_stream(f):
            table = pa.Table.from_batches([batch])
            if keys is not None:
                table = with_track_ids(table, keys)
            part.write(shift_track_ids(table, task.offset))
    return part.rows


def shift_track_ids(table: pa.Table, offset: int) -> pa.Table:
    """`table` with `offset` added to its track ids (null stays null)."""
    at = table.schema.get_field_index("track_id")
    ids = pc.add(table.column(at), pa.scalar(offset, pa.int64()))
    return table.set_column(at, table.schema.field(at), ids)
