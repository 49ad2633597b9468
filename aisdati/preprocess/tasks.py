"""The tasks of `aisdati ingest`: each a module-level function of one picklable description, so
that a Dask worker runs it as well as this process does (`aisdati.execution.runner`).

* `read_source` (`ReadTask`): one input source read, checked and filtered batch by batch, its
  survivors spilled into vessel partitions of its own, its rejects into a part of its own.
* `vessel_stages` (`VesselTask`): one vessel partition, from the spill files of every source:
  cleaned per vessel, segmented and made tracks; its points and its rows of tracks.parquet
  spilled with the partition's own track numbers (0, 1, ...), the rows but their geometry
  returned, with each track's shape for route clustering (`TrackShapes`).
* `write_points` (`PointsTask`): a partition's points as one part of points.parquet, its track
  numbers shifted past the tracks of the partitions before it: the ids one process numbering
  the tracks in partition order would give.

They share files in folders every worker sees (the spill folder and the staging folder, both
in --out) and return small things only: counts, track summaries, 32-point shapes. A task never
deletes its inputs: one lost with its worker (even after it ended, before its result was
fetched) is run again on the same files and writes the same outputs.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from rich.progress import Progress

from aisdati.errors import UserError
from aisdati.preprocess.clean import check_values, clean_vessels, filter_area_speed
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.inputs import Source, describe_read_error
from aisdati.preprocess.output import PartWriter, build_tracks
from aisdati.preprocess.partition import VesselPartitions, partition_tables
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.rejects import malformed_rows, reject_rows
from aisdati.preprocess.report import CODE, IngestCounts
from aisdati.preprocess.routes import TrackShapes
from aisdati.preprocess.routes import settings_of as route_settings
from aisdati.preprocess.segment import antimeridian_crossing, antimeridian_message, segment
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.stops import Splitter, dwell_rules
from aisdati.preprocess.streams import READ_ERRORS
from aisdati.tracks.schema import POINTS_SCHEMA, REJECTS_SCHEMA, TRACKS_SCHEMA


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


def read_source(task: ReadTask, progress: Progress | None = None) -> ReadResult:
    """Row-wise stages over one source, batch by batch (a bar of its bytes on `progress`)."""
    reader = open_reader(task.source)
    label = task.source.label
    bar = progress.add_task(f"read {label}", total=reader.total) if progress else None
    shutil.rmtree(task.spill, ignore_errors=True)  # what an earlier try of this task left
    task.spill.mkdir()
    parts = VesselPartitions(task.spill, task.n_parts, PARTITION_SCHEMA)
    counts, rows = IngestCounts(), 0
    with contextlib.ExitStack() as stack:
        rejects = _rejects_part(stack, task.rejects, task.src)
        try:
            for table, codes in reader.tables(task.src):
                table = check_values(table, codes)
                filter_area_speed(table, codes, task.roi, task.settings)
                rows += len(codes)
                counts.add_codes(codes)
                parts.write(table.filter(pa.array(codes == 0)))
                if rejects:
                    rejects.write(reject_rows(table, codes, label))
                if bar is not None:
                    progress.update(bar, completed=reader.done)
        except READ_ERRORS as exc:
            raise describe_read_error(task.source, exc) from None
        finally:
            parts.close()
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
    return ReadResult(counts, task.spill, tuple(parts.paths), parts.rows)


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


def vessel_stages(task: VesselTask) -> VesselResult:
    """Per-vessel cleaning, segmentation and clustering of one partition (a large one piece by
    piece: `partition_tables`), its points spilled as they come."""
    settings = task.settings
    counts = IngestCounts()
    tracks: list[pa.Table] = []
    shapes: list[TrackShapes] = []
    samples = route_settings(settings).samples
    stops = dwell_rules(settings.dwell_radius_m, settings.dwell_time_s, settings.min_sog_kn)
    # reports further apart than both the stop gap and the dwell time are independent
    independent_s = max(settings.stop_gap_s, settings.dwell_time_s)
    with (
        contextlib.ExitStack() as stack,
        pa.ipc.new_stream(str(task.points), POINTS_SCHEMA) as points,
        pa.ipc.new_stream(str(task.tracks), TRACKS_SCHEMA) as spilled,
    ):
        rejects = _rejects_part(stack, task.rejects, task.reject_part)
        pieces = partition_tables(
            task.spills, PARTITION_SCHEMA, task.rows, settings.rows_per_bucket, independent_s,
            _flooded(counts, rejects, task.labels),
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
                if settings.clusters == "routes":
                    shapes.append(TrackShapes.of(_lines(out_points), samples))
                counts.kept_points += out_points.num_rows
                for name in out_tracks.column("cluster").to_pylist():
                    counts.tracks[name] += 1
    empty = TRACKS_SCHEMA.empty_table().drop_columns(["geometry"])
    table = pa.concat_tables(tracks) if tracks else empty
    joined = TrackShapes.joined(shapes, samples) if settings.clusters == "routes" else None
    return VesselResult(counts, table, joined)


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
class PointsTask:
    """A partition's points, spilled to `spill`, as part `part` of the dataset folder `folder`,
    their track numbers shifted by `offset`."""

    spill: Path
    folder: Path
    part: int
    offset: int


def write_points(task: PointsTask) -> int:
    """Write one part of points.parquet, batch by batch; the rows written."""
    with PartWriter(task.folder, task.part, POINTS_SCHEMA) as part, pa.OSFile(str(task.spill)) as f:
        for batch in pa.ipc.open_stream(f):
            part.write(shift_track_ids(pa.Table.from_batches([batch]), task.offset))
    return part.rows


def shift_track_ids(table: pa.Table, offset: int) -> pa.Table:
    """`table` with `offset` added to its track ids."""
    at = table.schema.get_field_index("track_id")
    ids = pc.add(table.column(at), pa.scalar(offset, pa.int64()))
    return table.set_column(at, table.schema.field(at), ids)
