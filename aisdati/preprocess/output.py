"""The ingest outputs (their contracts are `aisdati.tracks.schema`'s) and how they reach the
disk: every file is written under a temporary name in the run's staging folder and renamed to
its name there once the run succeeded (`commit_all`); the staging folder then lands in --out as
one set (`aisdati.outdir.staged_outputs`). An interrupted or failed run never leaves a
half-written `points.parquet`, nor a new `points.parquet` beside an earlier run's tracks.

`points.parquet`, `reports.parquet` and `rejects.parquet` are Parquet datasets: folders of part
files (`part-00000.parquet`, ...), one per task that wrote rows, so that tasks on several workers
write them side by side (`StagedDataset`, `PartWriter`). Each part is renamed into its folder
once whole, and the folder, under a temporary name until the run succeeded, lands whole.

The route clusters reach the disk here as well (`write_routes`, `route_summary`):
`aisdati.preprocess.routes` finds them and knows nothing of how ingest stages its files, so the
dependency runs one way, from here to there."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import shapely

from aisdati.errors import UserError
from aisdati.geo import haversine_m
from aisdati.interrupts import raise_if_interrupted
from aisdati.outdir import DATASET_PART, temporary_path
from aisdati.preprocess.cluster import cluster_tracks
from aisdati.preprocess.routes import Routes, TrackShapes
from aisdati.tracks.schema import (
    GEO_METADATA,
    POINTS_SCHEMA,
    ROUTE_COLUMNS,
    ROUTES_SCHEMA,
    TRACKS_SCHEMA,
    UTC_US,
    VESSEL_COLUMNS,
    VESSEL_SCHEMA,
)


def build_tracks(
    points: pa.Table, track: np.ndarray, first_track_id: int
) -> tuple[pa.Table, pa.Table]:
    """The kept reports of one partition (sorted by MMSI and time, each with its 0-based track
    index in the partition; at least one report) as rows of points.parquet and tracks.parquet."""
    n_tracks = int(track.max()) + 1
    lon = points.column("lon").to_numpy()
    lat = points.column("lat").to_numpy()
    time_us = points.column("time").to_numpy().view(np.int64)
    cog = points.column("cog").to_numpy()
    track_id = track + first_track_id
    out_points = pa.table(
        [
            track_id,
            points.column("mmsi"),
            points.column("time"),
            lon,
            lat,
            points.column("sog").cast(pa.float32()),
            cog32(cog),
            points.column("heading"),
            points.column("status"),
        ],
        schema=POINTS_SCHEMA,
    )
    first = np.flatnonzero(np.r_[True, track[1:] != track[:-1]])
    last = np.r_[first[1:] - 1, len(track) - 1]
    same = track[1:] == track[:-1]
    steps = np.where(same, haversine_m(lon[:-1], lat[:-1], lon[1:], lat[1:]), 0.0)
    length_m = np.bincount(track[1:], weights=steps, minlength=n_tracks)
    lines = shapely.linestrings(np.column_stack([lon, lat]), indices=track)
    out_tracks = pa.table(
        [
            np.arange(n_tracks, dtype=np.int64) + first_track_id,
            points.column("mmsi").take(pa.array(first)),
            pa.array(time_us[first]).view(UTC_US),
            pa.array(time_us[last]).view(UTC_US),
            np.bincount(track, minlength=n_tracks).astype(np.int64),
            length_m / 1000.0,
            pa.array(cluster_tracks(track, cog, n_tracks), pa.string()),
            lon[first],
            lat[first],
            pa.nulls(n_tracks, pa.string()),  # route: set once all tracks are known
            pa.array(["cluster"] * n_tracks, pa.string()),
            *(pa.nulls(n_tracks, VESSEL_SCHEMA.field(f).type) for f in VESSEL_COLUMNS),  # later
            pa.array(shapely.to_wkb(lines), pa.binary()),
        ],
        schema=TRACKS_SCHEMA,
    )
    return out_points, out_tracks


def cog32(cog: np.ndarray) -> np.ndarray:
    """COG as float32, still in [0, 360): 359.99999 would round up to 360."""
    out = cog.astype(np.float32)
    out[out >= 360.0] = 0.0
    return out


ROUTE_FILES = ("routes.parquet", "routes.geojson", "routes.png")
"""The route clusters' files (`write_routes`), with `--clusters routes`."""
OUTPUT_NAMES = (
    "points.parquet",
    "tracks.parquet",
    "reports.parquet",
    "vessels.parquet",
    "identities.parquet",
    "ingest_report.json",
    "rejects.parquet",
    *ROUTE_FILES,
)
"""Every file ingest may write into its output folder: a run replaces them as one set and
removes those of an earlier run it does not write (no `--keep-rejects`, `--clusters direction`)."""
REPORT_NAME = "ingest_report.json"
"""The report of the set, written last."""
DATASET_NAMES = ("points.parquet", "reports.parquet", "rejects.parquet")
"""The outputs that are folders of part files (Parquet datasets), each landing whole."""


def commit_all(staged: list[StagedFile]) -> None:
    """Rename every staged file to its final name in the staging folder; if one rename fails,
    the temporaries left are removed and the failure is one `UserError`."""
    raise_if_interrupted()
    for i, f in enumerate(staged):
        try:
            f.commit()
        except OSError as exc:
            for rest in staged[i:]:
                rest.discard()
            raise UserError(f"cannot write {f.final}: {exc.strerror or exc}") from None


class StagedFile:
    """A file written under a temporary name next to its final one, renamed by `commit`."""

    def __init__(self, final: Path) -> None:
        self.final = final
        self.tmp = temporary_path(final)

    def commit(self) -> None:
        os.replace(self.tmp, self.final)

    def discard(self) -> None:
        self.tmp.unlink(missing_ok=True)


class StagedDataset(StagedFile):
    """A Parquet dataset: a folder that tasks fill with part files (`PartWriter`, any part
    numbers), its parts numbered 0, 1, ... in their order and the folder renamed by `commit`."""

    def __init__(self, final: Path, schema: pa.Schema) -> None:
        super().__init__(final)
        self.schema = schema
        self.tmp.mkdir()

    def commit(self) -> None:
        """Whatever is no part (what a task lost with its worker left) removed, the parts
        renumbered from 0, an empty part when there is none (readers need one for the schema),
        and the folder renamed."""
        parts = []
        for entry in self.tmp.iterdir():
            if DATASET_PART.match(entry.name):
                parts.append(entry)
            else:
                entry.unlink()
        parts.sort(key=lambda p: int(p.stem.removeprefix("part-")))
        for k, path in enumerate(parts):
            path.rename(self.tmp / part_name(k))
        if not parts:
            pq.write_table(self.schema.empty_table(), self.tmp / part_name(0), compression="zstd")
        os.replace(self.tmp, self.final)

    def discard(self) -> None:
        shutil.rmtree(self.tmp, ignore_errors=True)


def part_name(index: int) -> str:
    return f"part-{index:05d}.parquet"


class PartWriter:
    """Part `index` of the dataset folder `folder`, written batch by batch under a temporary
    name and renamed into place when its block ends well (no file at all when no row came; none
    when the block raised): a task run again replaces its part whole."""

    def __init__(self, folder: Path, index: int, schema: pa.Schema) -> None:
        self.final = folder / part_name(index)
        self.tmp = temporary_path(self.final)
        self.schema = schema
        self.writer: pq.ParquetWriter | None = None
        self.rows = 0

    def __enter__(self) -> PartWriter:
        return self

    def write(self, table: pa.Table) -> None:
        if table.num_rows:
            if self.writer is None:
                self.writer = pq.ParquetWriter(self.tmp, self.schema, compression="zstd")
            self.writer.write_table(table)
            self.rows += table.num_rows

    def __exit__(self, kind: type[BaseException] | None, *rest: Any) -> None:
        if self.writer is None:
            return
        self.writer.close()
        if kind is None:
            os.replace(self.tmp, self.final)
        else:
            self.tmp.unlink(missing_ok=True)


def write_tracks(final: Path, tables: Iterable[pa.Table]) -> StagedFile:
    """tracks.parquet as GeoParquet (the track geometry as a WKB LineString), one row group
    per table as they come: a national month's tracks need not be in memory at once."""
    staged = StagedFile(final)
    schema = TRACKS_SCHEMA.with_metadata({"geo": json.dumps(GEO_METADATA)})
    with pq.ParquetWriter(staged.tmp, schema, compression="zstd") as writer:
        writer.write_table(schema.empty_table())  # the schema, were there no tables
        for table in tables:
            writer.write_table(table.cast(schema))
    return staged


def write_table(final: Path, table: pa.Table) -> StagedFile:
    """A small table (vessels.parquet) as one Parquet file, staged."""
    staged = StagedFile(final)
    pq.write_table(table, staged.tmp, compression="zstd")
    return staged


def write_json(final: Path, doc: dict[str, Any]) -> StagedFile:
    staged = StagedFile(final)
    staged.tmp.write_text(json.dumps(doc, indent=2, default=str) + "\n", encoding="utf-8")
    return staged


# -------------------------------------------------------------------------- route outputs
def with_routes(tracks: pa.Table, labels: np.ndarray) -> pa.Table:
    """tracks.parquet's rows with their `route` column filled in (None: no route)."""
    col = tracks.schema.get_field_index("route")
    return tracks.set_column(col, "route", pa.array(list(labels), pa.string()))


def routes_arrow(routes: Routes) -> pa.Table:
    """routes.parquet: one row per route, the medoid track as a WKB LineString."""
    table = routes.table
    columns = [pa.array(table[c].tolist(), ROUTES_SCHEMA.field(c).type) for c in ROUTE_COLUMNS]
    wkb = [shapely.to_wkb(shapely.linestrings(xy)) for xy in routes.medoids]
    columns.append(pa.array(wkb, pa.binary()))
    return pa.Table.from_arrays(columns, schema=ROUTES_SCHEMA)


def routes_geojson(routes: Routes) -> dict[str, Any]:
    """routes.geojson: a FeatureCollection of the medoid LineStrings with the route's facts."""
    features = []
    for row, xy in zip(routes.table.to_dict("records"), routes.medoids, strict=True):
        props = {k: (round(v, 6) if isinstance(v, float) else v) for k, v in row.items()}
        props = {k: (int(v) if isinstance(v, np.integer) else v) for k, v in props.items()}
        coords = np.round(xy, 6).tolist()
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": coords},
                "properties": props,
            }
        )
    return {"type": "FeatureCollection", "features": features}


def write_routes(
    out_dir: Path, routes: Routes, shapes: TrackShapes, title: str
) -> list[StagedFile]:
    """routes.parquet, routes.geojson and routes.png (each track drawn as its resampled
    shape), staged (renamed when the run commits)."""
    from aisdati.preprocess.figures import plot_routes

    parquet = StagedFile(out_dir / "routes.parquet")
    table = routes_arrow(routes).replace_schema_metadata({"geo": json.dumps(GEO_METADATA)})
    pq.write_table(table, parquet.tmp, compression="zstd")
    geojson = StagedFile(out_dir / "routes.geojson")
    geojson.tmp.write_text(json.dumps(routes_geojson(routes)) + "\n", encoding="utf-8")
    png = StagedFile(out_dir / "routes.png")
    png.tmp = png.tmp.with_name(png.tmp.name + ".png")  # matplotlib picks the format by suffix
    lines = list(shapes.resampled)
    plot_routes(lines, routes.labels, routes.table, routes.medoids, png.tmp, title)
    return [parquet, geojson, png]


def route_summary(routes: Routes) -> dict[str, Any]:
    """For ingest_report.json and `--json`: the routes table and how many tracks have none."""
    rows = [
        {k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.items()}
        for r in routes.table.to_dict("records")
    ]
    rows = [{k: (int(v) if isinstance(v, np.integer) else v) for k, v in r.items()} for r in rows]
    return {
        "routes": rows,
        "routed_tracks": int(sum(r["n_tracks"] for r in rows)),
        "unrouted_tracks": int(sum(label is None for label in routes.labels)),
    }
