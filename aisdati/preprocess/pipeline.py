"""`aisdati ingest` end to end: read -> clean and filter (per batch) -> partition by vessel ->
clean per vessel -> segment -> cluster -> write.

The work runs as tasks (`aisdati.preprocess.tasks`) on a runner (`aisdati.execution.runner`):
in this process, or on Dask workers. Tasks are cut by the input alone, never by the number of
workers, so the outputs are the same wherever they ran:

1. one task per input source reads, checks and filters it, spilling its survivors into its own
   files of the vessel partitions (their number set by the input's size: `_partition_count`),
   its slow reports into files of their own, and tallies who its vessels are;
2. here, the tallies merged: each vessel's name, type and length (`vessels.winners`);
3. one task per vessel partition reads that partition's files of every source and makes its
   tracks from the moving reports, numbered from 0, with its points spilled beside them, then
   its rows of reports.parquet from all its reports (`aisdati.preprocess.reports`);
4. here, each partition's track ids are shifted past those of the partitions before it (the
   ids of one process numbering them in partition order), and one task per partition writes
   its points as a part of points.parquet, and one its reports as a part of reports.parquet,
   with the ids shifted the same;
5. here, the route clusters, from the tracks' shapes the tasks returned (`TrackShapes`: the
   ends and 32 points per track, not its reports), vessels.parquet, and tracks.parquet (with
   its vessels' columns), written partition by partition from the tasks' spill files.

Memory is bounded twice over: the row-wise stages see one record batch at a time, and the
per-vessel stages one partition (or piece of one) at a time, each holding at most about
`settings.rows_per_bucket` rows. This process holds a few hundred bytes per track (its row
of tracks.parquet without the geometry, and its shape), never every track's reports.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pyarrow as pa
from rich.progress import Progress

from aisdati.errors import UserError
from aisdati.execution.runner import Execution, InProcess, InThreads, Runner, open_runner
from aisdati.memory import hand_back
from aisdati.outdir import OutputSet, hold_lock, staged_outputs
from aisdati.preprocess.inputs import Source, sources_of
from aisdati.preprocess.output import (
    DATASET_NAMES,
    OUTPUT_NAMES,
    REPORT_NAME,
    StagedDataset,
    StagedFile,
    commit_all,
    route_summary,
    with_routes,
    write_json,
    write_routes,
    write_table,
    write_tracks,
)
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.report import IngestCounts, no_tracks_message
from aisdati.preprocess.routes import TrackShapes, cluster_shapes, lines_from_wkb
from aisdati.preprocess.routes import settings_of as route_settings
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.tasks import (
    PartTask,
    ReadResult,
    ReadTask,
    ReportsResult,
    ReportsTask,
    VesselResult,
    VesselTask,
    partition_stage,
    read_source,
    shift_track_ids,
    write_part,
)
from aisdati.preprocess.vessels import identity_history, vessels_table, winners, with_vessels
from aisdati.tracks.schema import (
    POINTS_SCHEMA,
    REJECTS_SCHEMA,
    REPORTS_SCHEMA,
    is_second_transmitter,
    mmsi_of,
)

T = TypeVar("T")
R = TypeVar("R")

MAX_PARTITIONS = 256
VESSEL_THREADS = min(2, os.cpu_count() or 1)
"""Vessel partitions at once in this process (`_vessel_runner`)."""


@dataclass
class IngestResult:
    """What a run did: counts per reason, tracks per cluster, files written."""

    counts: IngestCounts
    settings: IngestSettings
    roi: str
    outputs: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    stage_seconds: dict[str, float] = field(default_factory=dict)
    routes: dict[str, Any] | None = None
    """Route clusters (`route_summary`), None with `--clusters direction`."""

    def as_dict(self) -> dict[str, Any]:
        return {
            **self.counts.as_dict(),
            "route_clusters": self.routes,
            "settings": self.settings.as_dict(),
            "roi": self.roi,
            "outputs": self.outputs,
            "seconds": round(self.seconds, 3),
            "stage_seconds": self.stage_seconds,
        }


def ingest(
    inputs: list[Path],
    out_dir: Path,
    settings: IngestSettings,
    roi: Any,
    roi_name: str,
    progress: Progress | None = None,
    execution: Execution = Execution(),
) -> IngestResult:
    """Run the whole pipeline on local files and write points.parquet, tracks.parquet,
    reports.parquet, vessels.parquet, ingest_report.json (and rejects.parquet, the route
    files) into `out_dir`, as one set
    (`aisdati.outdir.staged_outputs`), its tasks run where `execution` says. Raises `UserError`
    for bad input; `out_dir` is left as it was unless the run succeeded."""
    started = time.perf_counter()
    if settings.min_points < 2:
        raise UserError("--min-points must be at least 2 (a track is a line)")
    _check_route_settings(settings)
    sources = [s for path in inputs for s in sources_of(path)]
    for source in sources:  # every header checked before any work
        open_reader(source)
    with staged_outputs(out_dir, OUTPUT_NAMES, REPORT_NAME, datasets=DATASET_NAMES) as outputs:
        staged: list[StagedFile] = []
        try:
            result = _run(sources, outputs, staged, settings, (roi, roi_name), progress, execution)
            result.seconds = time.perf_counter() - started
            staged.append(write_json(outputs.folder / REPORT_NAME, result.as_dict()))
        except BaseException:
            for f in staged:
                f.discard()
            raise
        commit_all(staged)
        outputs.commit()
    return result


def _run(
    sources: list[Source],
    outputs: OutputSet,
    staged: list[StagedFile],
    settings: IngestSettings,
    area: tuple[Any, str],
    progress: Progress | None,
    execution: Execution,
) -> IngestResult:
    """Every stage, the outputs written into the staging folder and added to `staged` as they
    come (`area`: the region of interest and its name); the result, but for the report and the
    run's time. The runner is closed (a local cluster's workers stopped) before the spill
    folder is deleted, so that no task still writes there."""
    stage = outputs.folder
    with _spill_folder(outputs.out) as spill, open_runner(execution) as runner:
        started = time.perf_counter()  # the workers' start (the run's seconds hold it) aside
        rejects = _staged_rejects(stage, staged, settings)
        reads = _read_stage(runner, sources, spill, settings, area[0], rejects, progress)
        counts = _read_counts(reads, sources)
        found = winners([read.vessels for read in reads])
        stage_seconds = {"read_clean_filter": time.perf_counter() - started}
        datasets = _staged_datasets(stage, staged)
        labels = tuple(s.label for s in sources)
        tasks = _vessel_tasks(reads, spill, settings, labels, rejects)
        parts, shapes, mmsi = _vessel_stage(
            runner, tasks, reads, counts, datasets, settings, progress
        )
        # the reading and per-vessel stages' freed memory (`aisdati.memory`): route clustering's
        # peak comes next, so hand it back first
        hand_back()
        if not parts and not counts.reports_kept:
            raise UserError(no_tracks_message(counts))
        stage_seconds["vessel_segment_cluster"] = (
            time.perf_counter() - started - stage_seconds["read_clean_filter"]
        )
        routed_at = time.perf_counter()
        labels_of, route_files, routes = _route_stage(
            parts, shapes if parts else None, stage, settings, _inputs_named(labels), progress
        )
        stage_seconds["routes"] = time.perf_counter() - routed_at
        staged.extend(route_files)
        vessels = vessels_table(found, mmsi)
        counts.two_transmitters = [mmsi_of(m) for m in mmsi if is_second_transmitter(m)]
        staged.append(write_table(stage / "vessels.parquet", vessels))
        history = identity_history([read.vessels for read in reads])
        staged.append(write_table(stage / "identities.parquet", history))
        rows = (
            with_vessels(with_routes(shift_track_ids(p.spilled(), p.offset), labels_of(p)), vessels)
            for p in parts
        )
        staged.append(write_tracks(stage / "tracks.parquet", rows))
    if not counts.balanced():
        raise RuntimeError(f"row accounting does not balance: {counts.as_dict()}")
    return IngestResult(
        counts,
        settings,
        area[1],
        outputs=_output_paths(outputs, staged),
        stage_seconds={k: round(v, 3) for k, v in stage_seconds.items()},
        routes=routes,
    )


@contextlib.contextmanager
def _spill_folder(out: Path) -> Iterator[Path]:
    """A temporary folder in --out for the tasks' spill files, as an absolute path (workers may
    run elsewhere), deleted after the block."""
    with (
        tempfile.TemporaryDirectory(
            dir=out, prefix=f".ingest-{os.getpid()}-", ignore_cleanup_errors=True
        ) as tmp,
        hold_lock(Path(tmp)),  # tells the sweep of a later run that this folder is in use
    ):
        yield Path(tmp).absolute()


def _staged_datasets(stage: Path, staged: list[StagedFile]) -> tuple[Path, Path]:
    """points.parquet and reports.parquet staged (and added to `staged`): the folders the
    tasks write their parts into."""
    points = StagedDataset(stage / "points.parquet", POINTS_SCHEMA)
    reports = StagedDataset(stage / "reports.parquet", REPORTS_SCHEMA)
    staged.extend([points, reports])
    return points.tmp.absolute(), reports.tmp.absolute()


def _staged_rejects(stage: Path, staged: list[StagedFile], settings: IngestSettings) -> Path | None:
    """With `--keep-rejects`, rejects.parquet staged (and added to `staged`): the folder the
    tasks write its parts into; else None."""
    if not settings.keep_rejects:
        return None
    kept = StagedDataset(stage / "rejects.parquet", REJECTS_SCHEMA)
    staged.append(kept)
    return kept.tmp.absolute()


def _read_counts(reads: list[ReadResult], sources: list[Source]) -> IngestCounts:
    """The read stage's counts of every source together; a `UserError` where no source had a
    data row."""
    counts = IngestCounts()
    for read in reads:
        counts.merge(read.counts)
    if counts.rows_read == 0:
        raise UserError(
            "no data rows in the input (only headers?): " + ", ".join(s.label for s in sources)
        )
    return counts


def _vessel_stage(
    runner: Runner,
    tasks: list[tuple[VesselTask, ReportsTask]],
    reads: list[ReadResult],
    counts: IngestCounts,
    folders: tuple[Path, Path],
    settings: IngestSettings,
    progress: Progress | None,
) -> tuple[list[PartTracks], TrackShapes | None, np.ndarray]:
    """The vessel partitions' tasks run, each partition's tracks and reports side by side
    (their counts added to `counts`), the read stage's spill files deleted, and their points
    and reports written into the dataset folders `folders`: what `_write_parts` returns, and
    the MMSIs (sorted) of every report and point. The tasks' results are dropped on return:
    their shapes are joined, one copy, not two, through route clustering."""
    on = _vessel_runner(runner)
    both = [task for pair in tasks for task in pair[::-1]]  # a partition's reports take longer
    results = _map(on, partition_stage, both, progress, "clean, segment, cluster")
    for read in reads:  # every vessel task's result is here: its inputs are not needed again
        shutil.rmtree(read.folder)
    vessels = [r for r in results if isinstance(r, VesselResult)]
    reports = [r for r in results if isinstance(r, ReportsResult)]
    for vessel in vessels:
        counts.merge(vessel.counts)
    counts.reports_kept = sum(r.rows for r in reports)
    mmsi = np.unique(np.concatenate([np.zeros(0, np.int64), *(r.vessels for r in results)]))
    return (*_write_parts(on, tasks, (vessels, reports), folders, settings, progress), mmsi)


def _inputs_named(labels: tuple[str, ...]) -> str:
    """What the tracks are, for routes.png's title: the first input, and how many more."""
    return labels[0] + (f" and {len(labels) - 1} more" if len(labels) > 1 else "")


def _output_paths(outputs: OutputSet, staged: list[StagedFile]) -> dict[str, str]:
    """The report's `outputs`: where each staged file lands in --out, and the report itself."""
    paths = {_output_key(f.final): str(outputs.final(f.final)) for f in staged}
    paths["ingest_report"] = str(outputs.out / REPORT_NAME)
    return paths


def _read_stage(
    runner: Runner,
    sources: list[Source],
    spill: Path,
    settings: IngestSettings,
    roi: Any,
    rejects: Path | None,
    progress: Progress | None,
) -> list[ReadResult]:
    """One `read_source` task per source, each spilling into a folder of its own. In this
    process each source has a bar of its bytes, on Dask workers the sources one bar."""
    n_parts = _partition_count(sources, settings)
    tasks = [
        ReadTask(
            replace(source, path=source.path.absolute()),  # workers may run elsewhere
            src,
            spill / f"src-{src:05d}",
            n_parts,
            settings,
            roi,
            rejects,
        )
        for src, source in enumerate(sources)
    ]
    if isinstance(runner, InProcess):
        return runner.map(lambda task: read_source(task, progress), tasks)
    return _map(runner, read_source, tasks, progress, "read, clean, filter")


def _vessel_runner(runner: Runner) -> Runner:
    """In this process the vessel partitions, and then their points' writing, run on
    `VESSEL_THREADS` threads: their sorting, numpy, Arrow and Parquet work releases the GIL, and
    a partition is bounded (`rows_per_bucket`). On 10.1 M rows the stage took a median 1.83 s
    instead of 2.44 s (four runs each), at 80-100 MB more peak memory (686-705 -> 765-797 MB),
    with the same outputs; on Dask each partition is a task."""
    return InThreads(VESSEL_THREADS) if isinstance(runner, InProcess) else runner


def _vessel_tasks(
    reads: list[ReadResult],
    spill: Path,
    settings: IngestSettings,
    labels: tuple[str, ...],
    rejects: Path | None,
) -> list[tuple[VesselTask, ReportsTask]]:
    """Two tasks per vessel partition, reading the partition's file of every source that has
    rows there: its tracks' (its rejects after the sources' in rejects.parquet), and its
    reports' (its slow reports' files too)."""
    rows = np.stack([read.rows for read in reads])
    slow = np.stack([read.slow_rows for read in reads])
    tasks = []
    for part in range(rows.shape[1]):
        moving = tuple(read.spills[part] for read in reads if read.rows[part])
        tracks = VesselTask(
            part, moving, int(rows[:, part].sum()), spill / f"points-{part:05d}.arrow",
            settings, labels, rejects, len(reads) + part,
        )  # fmt: skip
        every = moving + tuple(read.slow_spills[part] for read in reads if read.slow_rows[part])
        total = int(rows[:, part].sum() + slow[:, part].sum())
        out = spill / f"reports-{part:05d}.arrow"
        tasks.append((tracks, ReportsTask(part, every, total, out, settings)))
    return tasks


@dataclass(frozen=True)
class PartTracks:
    """A partition's tracks once numbered: ids from `offset` on, in `table` (without their
    geometry) and, geometry and all, in the spill file `spill` (numbered from 0)."""

    offset: int
    table: pa.Table
    spill: Path

    def spilled(self) -> pa.Table:
        """The partition's rows of tracks.parquet, numbered from 0 as the task wrote them."""
        with pa.OSFile(str(self.spill)) as f:
            return pa.ipc.open_stream(f).read_all()


def _write_parts(
    runner: Runner,
    tasks: list[tuple[VesselTask, ReportsTask]],
    results: tuple[list[VesselResult], list[ReportsResult]],
    folders: tuple[Path, Path],
    settings: IngestSettings,
    progress: Progress | None,
) -> tuple[list[PartTracks], TrackShapes | None]:
    """Each partition's track ids shifted past the tracks of the partitions before it, in
    its track table and (one `write_part` task per partition with tracks, and one per partition
    with reports, into the dataset folders `folders`) its points and reports: the partitions
    with tracks, in partition order, and all their tracks' shapes in that order (None with
    `--clusters direction`)."""
    vessels, reports = results
    parts, writes, offset = [], [], 0
    for (task, report_task), vessel, report in zip(tasks, vessels, reports, strict=True):
        if vessel.tracks.num_rows:
            table = shift_track_ids(vessel.tracks, offset)
            parts.append(PartTracks(offset, table, task.tracks))
            writes.append(PartTask(task.points, folders[0], task.part, offset))
        if report.rows:
            out = report_task.out
            writes.append(PartTask(out, folders[1], task.part, offset, REPORTS_SCHEMA, task.points))
        offset += vessel.tracks.num_rows
    written = _map(runner, write_part, writes, progress, "write points and reports")
    for schema, kept in (
        (POINTS_SCHEMA, sum(vessel.counts.kept_points for vessel in vessels)),
        (REPORTS_SCHEMA, sum(report.rows for report in reports)),
    ):
        rows = sum(n for n, w in zip(written, writes, strict=True) if w.schema is schema)
        if rows != kept:
            raise RuntimeError(f"wrote {rows} rows of the {kept} kept")
    if settings.clusters != "routes":
        return parts, None
    shapes = [v.shapes for v in vessels if v.tracks.num_rows and v.shapes is not None]
    return parts, TrackShapes.joined(shapes, route_settings(settings).samples)


def _lines_of(parts: list[PartTracks]) -> Callable[[np.ndarray], list[np.ndarray]]:
    """Route clustering's `LinesOf` over the spilled partitions: the lines of a few tracks
    (by row, = track id), each partition read only where one of them is."""
    starts = np.array([p.offset for p in parts])

    def lines(rows: np.ndarray) -> list[np.ndarray]:
        found: dict[int, np.ndarray] = {}
        owner = np.searchsorted(starts, rows, side="right") - 1
        for k in np.unique(owner):
            part = parts[k]
            wkb = part.spilled().column("geometry")
            wanted = rows[owner == k]
            got = lines_from_wkb(wkb.take(pa.array(wanted - part.offset)).to_pylist())
            found.update(zip(wanted.tolist(), got, strict=True))
        return [found[int(r)] for r in rows]

    return lines


def _map(
    runner: Runner,
    fn: Callable[[T], R],
    items: Sequence[T],
    progress: Progress | None,
    what: str,
) -> list[R]:
    """`runner.map`, with a bar that advances as each task ends."""
    if progress is None or not items:
        return runner.map(fn, items)
    bar = progress.add_task(what, total=len(items))
    return runner.map(fn, items, on_done=lambda _: progress.advance(bar))


def _check_route_settings(settings: IngestSettings) -> None:
    if settings.clusters not in ("routes", "direction"):
        raise UserError(f"--clusters {settings.clusters!r}: choose routes or direction")
    if settings.route_min_tracks < 2:
        raise UserError(f"--route-min-tracks must be at least 2, got {settings.route_min_tracks}")
    if settings.route_eps_km is not None and not settings.route_eps_km > 0:
        raise UserError(f"--route-eps-km must be positive (or auto), got {settings.route_eps_km}")
    if settings.dwell_time_s < 0 or not settings.dwell_radius_m > 0:
        raise UserError("--dwell-radius must be positive and --dwell-time positive or 0")


def _output_key(path: Path) -> str:
    """Key of an output in the report: its stem, with the suffix for the non-tabular files
    that share a stem (routes.geojson, routes.png)."""
    return path.stem if path.suffix in (".parquet", ".json") else f"{path.stem}_{path.suffix[1:]}"


def _route_stage(
    parts: list[PartTracks],
    shapes: TrackShapes | None,
    out_dir: Path,
    settings: IngestSettings,
    what: str,
    progress: Progress | None,
) -> tuple[Callable[[PartTracks], np.ndarray], list[StagedFile], dict[str, Any] | None]:
    """Route clusters when `settings.clusters` is 'routes', from the tracks' shapes alone:
    each partition's route labels, the staged route files and their summary."""
    if shapes is None:  # --clusters direction
        return lambda p: np.full(p.table.num_rows, None, dtype=object), [], None
    task = progress.add_task("route clusters", total=None) if progress else None
    how = route_settings(settings)
    table = pa.concat_tables([p.table for p in parts])
    routes = cluster_shapes(
        shapes,
        table.column("track_id").to_numpy(),
        table.column("length_km").to_numpy(),
        _lines_of(parts),
        how,
    )
    files = write_routes(out_dir, routes, shapes, what)
    if task is not None:
        progress.update(task, total=1, completed=1)
    return (
        lambda p: routes.labels[p.offset : p.offset + p.table.num_rows],
        files,
        route_summary(routes),
    )


def _partition_count(sources: list[Source], settings: IngestSettings) -> int:
    rows = sum(s.estimated_rows() for s in sources)
    return max(1, min(MAX_PARTITIONS, math.ceil(rows / settings.rows_per_bucket)))
