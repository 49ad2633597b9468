"""`aisdati ingest` end to end: read -> clean and filter (per batch) -> partition by vessel ->
clean per vessel -> segment -> cluster -> write.

Memory is bounded twice over: the row-wise stages see one record batch at a time, and the
per-vessel stages one partition at a time (partitions are sized from the input so that each
holds at most about `settings.rows_per_bucket` rows). Every stage is a function of a pyarrow
table holding whole vessels, so a distributed engine could map the same functions over
partitions.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from rich.progress import Progress

from aisdati.errors import UserError
from aisdati.outdir import OutputSet, hold_lock, staged_outputs
from aisdati.preprocess.clean import check_values, clean_vessels, filter_area_speed
from aisdati.preprocess.convert import PARTITION_SCHEMA, to_canonical
from aisdati.preprocess.inputs import Source, describe_read_error, sources_of
from aisdati.preprocess.output import (
    OUTPUT_NAMES,
    REPORT_NAME,
    StagedFile,
    StagedParquet,
    build_tracks,
    commit_all,
    write_json,
    write_tracks,
)
from aisdati.preprocess.partition import VesselPartitions
from aisdati.preprocess.read import TableReader, open_reader
from aisdati.preprocess.report import REASONS, IngestCounts, no_tracks_message
from aisdati.preprocess.routes import (
    route_summary,
    route_tracks,
    write_routes,
)
from aisdati.preprocess.routes import settings_of as route_settings
from aisdati.preprocess.segment import segment
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.stops import dwell_rules
from aisdati.preprocess.streams import READ_ERRORS
from aisdati.tracks.schema import POINTS_SCHEMA, REJECTS_SCHEMA, TRACKS_SCHEMA

MAX_PARTITIONS = 256


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
) -> IngestResult:
    """Run the whole pipeline on local files and write points.parquet, tracks.parquet,
    ingest_report.json (and rejects.parquet, the route files) into `out_dir`, as one set
    (`aisdati.outdir.staged_outputs`). Raises `UserError` for bad input; `out_dir` is left as it
    was unless the run succeeded."""
    started = time.perf_counter()
    if settings.min_points < 2:
        raise UserError("--min-points must be at least 2 (a track is a line)")
    _check_route_settings(settings)
    sources = [s for path in inputs for s in sources_of(path)]
    readers = [open_reader(s) for s in sources]  # every header checked before any work
    with staged_outputs(out_dir, OUTPUT_NAMES, REPORT_NAME) as outputs:
        staged: list[StagedFile] = []
        try:
            result = _run(readers, sources, outputs, staged, settings, (roi, roi_name), progress)
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
    readers: list[TableReader],
    sources: list[Source],
    outputs: OutputSet,
    staged: list[StagedFile],
    settings: IngestSettings,
    area: tuple[Any, str],
    progress: Progress | None,
) -> IngestResult:
    """Every stage, the outputs written into the staging folder and added to `staged` as they
    come (`area`: the region of interest and its name); the result, but for the report and the
    run's time."""
    started = time.perf_counter()
    roi, roi_name = area
    stage = outputs.folder
    counts = IngestCounts()
    with (
        tempfile.TemporaryDirectory(dir=outputs.out, prefix=f".ingest-{os.getpid()}-") as tmp,
        hold_lock(Path(tmp)),  # tells the sweep of a later run that this folder is in use
    ):
        rejects = (
            StagedParquet(stage / "rejects.parquet", REJECTS_SCHEMA)
            if settings.keep_rejects
            else None
        )
        if rejects:
            staged.append(rejects)
        # reports further apart than both the stop gap and the dwell time are independent
        independent_s = max(settings.stop_gap_s, settings.dwell_time_s)
        n_parts = _partition_count(sources, settings)
        parts = VesselPartitions(
            Path(tmp), n_parts, PARTITION_SCHEMA, settings.rows_per_bucket, independent_s
        )
        for src, reader in enumerate(readers):
            _read_source(reader, src, parts, counts, settings, roi, rejects, progress)
        parts.close()
        stage_seconds = {"read_clean_filter": time.perf_counter() - started}
        if counts.rows_read == 0:
            raise UserError(
                "no data rows in the input (only headers?): " + ", ".join(s.label for s in sources)
            )
        points = StagedParquet(stage / "points.parquet", POINTS_SCHEMA)
        staged.append(points)
        labels = [s.label for s in sources]
        tracks = _vessel_stages(parts, counts, settings, points, rejects, labels, progress)
        if not tracks:
            raise UserError(no_tracks_message(counts))
        points.close()
        stage_seconds["vessel_segment_cluster"] = (
            time.perf_counter() - started - stage_seconds["read_clean_filter"]
        )
        if rejects:
            rejects.close()
        routed_at = time.perf_counter()
        what = labels[0] + (f" and {len(labels) - 1} more" if len(labels) > 1 else "")
        table, route_files, routes = _route_stage(tracks, stage, settings, what, progress)
        stage_seconds["routes"] = time.perf_counter() - routed_at
        staged.extend(route_files)
        staged.append(write_tracks(stage / "tracks.parquet", [table]))
    if not counts.balanced():
        raise RuntimeError(f"row accounting does not balance: {counts.as_dict()}")
    result = IngestResult(counts, settings, roi_name)
    result.stage_seconds = {k: round(v, 3) for k, v in stage_seconds.items()}
    result.routes = routes
    result.outputs = {_output_key(f.final): str(outputs.final(f.final)) for f in staged}
    result.outputs["ingest_report"] = str(outputs.out / REPORT_NAME)
    return result


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
    tracks: list[pa.Table],
    out_dir: Path,
    settings: IngestSettings,
    what: str,
    progress: Progress | None,
) -> tuple[pa.Table, list[StagedFile], dict[str, Any] | None]:
    """All tracks as one table, with route clusters when `settings.clusters` is 'routes' (and
    their staged files and summary)."""
    table = pa.concat_tables(tracks) if tracks else TRACKS_SCHEMA.empty_table()
    if settings.clusters == "direction":
        return table, [], None
    task = progress.add_task("route clusters", total=None) if progress else None
    table, routes, lines = route_tracks(table, route_settings(settings))
    files = write_routes(out_dir, routes, lines, what)
    if task is not None:
        progress.update(task, total=1, completed=1)
    return table, files, route_summary(routes)


def _partition_count(sources: list[Source], settings: IngestSettings) -> int:
    rows = sum(s.estimated_rows() for s in sources)
    return max(1, min(MAX_PARTITIONS, math.ceil(rows / settings.rows_per_bucket)))


def _read_source(
    reader: TableReader,
    src: int,
    parts: VesselPartitions,
    counts: IngestCounts,
    settings: IngestSettings,
    roi: Any,
    rejects: StagedParquet | None,
    progress: Progress | None,
) -> None:
    """Row-wise stages over one source, batch by batch; survivors go to the vessel partitions."""
    label = reader.source.label
    task = progress.add_task(f"read {label}", total=reader.total) if progress else None
    rows = 0
    try:
        for batch in reader.batches():
            table, codes = to_canonical(batch, reader.columns, src, reader.time_format)
            table = check_values(table, codes)
            filter_area_speed(table, codes, roi, settings)
            rows += len(codes)
            counts.add_codes(codes)
            parts.write(table.filter(pa.array(codes == 0)))
            if rejects:
                rejects.write(_reject_rows(table, codes, label))
            if task is not None:
                progress.update(task, completed=reader.done)
    except READ_ERRORS as exc:
        raise describe_read_error(reader.source, exc) from None
    skipped = reader.skipped  # lines that gave no row (malformed CSV, unusable NMEA), by reason
    n_skipped = sum(len(texts) for texts in skipped.values())
    counts.rows_read += rows + n_skipped
    for reason, texts in skipped.items():
        counts.add(reason, len(texts))
        if rejects and texts:
            rejects.write(_malformed_rows(texts, label, reason))
    counts.files.append(
        {
            "source": label,
            "rows": rows + n_skipped,
            "columns": reader.columns,
            "derived": [c for c in ("sog", "cog") if c not in reader.columns],
        }
    )
    if task is not None:
        progress.update(task, completed=reader.total)


def _vessel_stages(
    parts: VesselPartitions,
    counts: IngestCounts,
    settings: IngestSettings,
    points: StagedParquet,
    rejects: StagedParquet | None,
    labels: list[str],
    progress: Progress | None,
) -> list[pa.Table]:
    """Per-vessel cleaning, segmentation and clustering, one partition at a time; points are
    written as they come, track summaries returned (one row per track: small)."""
    task = progress.add_task("clean, segment, cluster", total=len(parts)) if progress else None
    tracks: list[pa.Table] = []
    next_track_id = 0
    stops = dwell_rules(settings.dwell_radius_m, settings.dwell_time_s, settings.min_sog_kn)
    for table in parts:
        table, codes = clean_vessels(table, settings)
        kept = np.flatnonzero(codes == 0)
        time_us = table.column("time").to_numpy().view(np.int64)
        mmsi = table.column("mmsi").to_numpy()
        lon, lat, sog = (table.column(c).to_numpy()[kept] for c in ("lon", "lat", "sog"))
        track, seg_codes, n_short = segment(
            mmsi[kept], time_us[kept], settings.stop_gap_s, settings.min_points, stops,
            lon, lat, sog,
        )  # fmt: skip
        codes[kept] = seg_codes
        counts.add_codes(codes)
        counts.short_segments += n_short
        if rejects:
            rejects.write(_reject_rows(table, codes, labels))
        in_track = track >= 0
        if in_track.any():
            rows = table.take(pa.array(kept[in_track]))
            out_points, out_tracks = build_tracks(rows, track[in_track], next_track_id)
            points.write(out_points)
            tracks.append(out_tracks)
            next_track_id += out_tracks.num_rows
            counts.kept_points += out_points.num_rows
            for name in out_tracks.column("cluster").to_pylist():
                counts.tracks[name] += 1
        if task is not None:
            progress.advance(task)
    return tracks


_REASON_NAMES = np.array([""] + [reason for _, reason, _ in REASONS.values()], dtype=object)


def _reject_rows(table: pa.Table, codes: np.ndarray, source: str | list[str]) -> pa.Table:
    """The rejected rows of a table, with their reason and source, in the rejects schema."""
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


def _malformed_rows(texts: list[str | None], source: str, reason: str) -> pa.Table:
    n = len(texts)
    columns = {name: pa.nulls(n, REJECTS_SCHEMA.field(name).type) for name in REJECTS_SCHEMA.names}
    columns["source"] = pa.array([source] * n, pa.string())
    columns["reason"] = pa.array([reason] * n, pa.string())
    columns["raw"] = pa.array(texts, pa.string())
    return pa.table(columns, schema=REJECTS_SCHEMA)
