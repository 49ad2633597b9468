"""Reading the tracks that `aisdati ingest` wrote (data/processed) for training and detection.

A `Track` holds one track's positions (lon, lat degrees) and the real time steps between its
reports in hours, which is what the AIS environment and the detector work with, and what the
vessel reported of its motion (SOG, COG) where points.parquet has it.

Tracks are selected by name (`select_cluster`): the paper's direction clusters `up`, `down` and
`other` (the `cluster` column), a route cluster `route-<n>` (the `route` column, see
`aisdati.preprocess.routes`), or `unrouted` (the tracks that fit no route). tracks.parquet files
written before route clusters existed have no `route` column: every track is then unrouted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aisdati.errors import UserError
from aisdati.tracks.schema import AREA, CLUSTERS, ROUTE_PREFIX, TRACK_COLUMNS, UNROUTED

MIN_ROUTE_TRACKS = 5
"""Fewest tracks a route needs to be trained on (ingest's default --route-min-tracks, so every
route of a default ingest qualifies)."""


@dataclass(frozen=True)
class Track:
    track_id: int
    mmsi: int
    start: pd.Timestamp
    positions: np.ndarray
    """[n, 2] (lon, lat) in degrees."""
    dts: np.ndarray
    """[n - 1] hours between consecutive reports."""
    cluster: str
    route: str | None = None
    """`route-<n>`, or None when the track fits no route."""
    sog: np.ndarray | None = None
    """[n] reported speed over ground (knots), NaN where not given; None: not read."""
    cog: np.ndarray | None = None
    """[n] reported course over ground (degrees), NaN where not given; None: not read."""

    @property
    def steps(self) -> int:
        return len(self.positions) - 1


def _paths(data_dir: Path) -> tuple[Path, Path]:
    """points.parquet (a folder of part files, as ingest writes it, or one file, as evaluate's
    data and earlier versions of ingest wrote it) and tracks.parquet."""
    points, tracks = data_dir / "points.parquet", data_dir / "tracks.parquet"
    for f, found in ((points, points.is_file() or points.is_dir()), (tracks, tracks.is_file())):
        if not found:
            raise UserError(f"{f} not found: run `aisdati ingest --out {data_dir}` first")
    return points, tracks


def read_track_table(data_dir: Path) -> pd.DataFrame:
    """tracks.parquet without its geometry column (`route` all None in files that predate it)."""
    _, tracks = _paths(data_dir)
    try:
        names = set(pq.read_schema(tracks).names)
        columns = [c for c in TRACK_COLUMNS if c in names or c != "route"]
        table = pq.read_table(tracks, columns=columns).to_pandas()
    except Exception as exc:  # pyarrow raises several types for damaged or foreign files
        raise UserError(f"cannot read {tracks}: {str(exc).splitlines()[0]}") from None
    if "route" not in table.columns:
        table["route"] = None
    table["route"] = table["route"].astype(object).where(table["route"].notna(), None)
    return table


def _route_number(name: str) -> int:
    return int(name[len(ROUTE_PREFIX) :])


ROUTES_LISTED = 12
"""Routes named in an error message (the largest: their numbers come first)."""


def cluster_counts(table: pd.DataFrame) -> str:
    """What a track table holds, by name: 'up: 9, down: 5, other: 144; route-1: 47, ...,
    unrouted: 58' (routes in number order, the first `ROUTES_LISTED`)."""
    clusters = table["cluster"].value_counts()
    parts = [f"{c}: {int(clusters[c])}" for c in CLUSTERS if c in clusters]
    text = ", ".join(parts) or "no tracks at all"
    routes = table["route"].value_counts() if "route" in table else pd.Series(dtype=int)
    if len(routes):
        names = sorted(routes.index, key=_route_number)
        unrouted = int(table["route"].isna().sum())
        text += "; " + ", ".join(f"{r}: {int(routes[r])}" for r in names[:ROUTES_LISTED])
        if len(names) > ROUTES_LISTED:
            text += f", ... ({len(names)} routes)"
        text += f", {UNROUTED}: {unrouted}"
    return text


def is_track_set(name: str) -> bool:
    """Whether `name` has the form of a cluster, route or `unrouted` (not whether it exists)."""
    if name in CLUSTERS or name in (UNROUTED, AREA):
        return True
    rest = name[len(ROUTE_PREFIX) :]
    return name.startswith(ROUTE_PREFIX) and rest.isdigit() and not rest.startswith("0")


def select_cluster(
    table: pd.DataFrame, cluster: str, data_dir: Path, needed: int | None = None
) -> pd.DataFrame:
    """The tracks of a cluster (`up`, `down`, `other`), a route (`route-<n>`), `unrouted`, or
    every track of the area (`all`).
    Unknown names, empty selections and routes with fewer than `needed` tracks (default:
    `MIN_ROUTE_TRACKS` for a route, 1 otherwise) raise a one-line `UserError` that lists what
    the table holds."""
    if "route" not in table.columns:
        table = table.assign(route=None)
    if not is_track_set(cluster):
        raise UserError(
            f"unknown cluster {cluster!r}; choose from {', '.join(CLUSTERS)}, route-<n>, "
            f"{UNROUTED} or {AREA} ({data_dir} has {cluster_counts(table)})"
        )
    if cluster == AREA:
        chosen = table
    elif cluster in CLUSTERS:
        chosen = table[table["cluster"] == cluster]
    elif cluster == UNROUTED:
        chosen = table[table["route"].isna()]
    else:
        chosen = table[table["route"] == cluster]
    if chosen.empty:
        kind = "route" if cluster.startswith(ROUTE_PREFIX) else "cluster"
        if kind == "route" and not table["route"].notna().any():
            hint = " (no route clusters: ingest again with --clusters routes, the default)"
        else:
            hint = ""
        raise UserError(
            f"no tracks in {kind} {cluster!r} in {data_dir} ({cluster_counts(table)}){hint}"
        )
    if needed is None:
        needed = MIN_ROUTE_TRACKS if cluster.startswith(ROUTE_PREFIX) else 1
    require_tracks(chosen, cluster, needed)
    return chosen


def routes_with(data_dir: Path, command: str, needed: int = MIN_ROUTE_TRACKS) -> list[str]:
    """The routes of an ingest output with at least `needed` tracks, in route order; none is a
    one-line `UserError` that says how to get some (`command`: what else the user can run on
    one cluster, "train" or "evaluate")."""
    table = read_track_table(data_dir)
    counts = table["route"].dropna().value_counts() if "route" in table.columns else {}
    chosen = sorted((str(r) for r, n in counts.items() if n >= needed), key=_route_number)
    if not chosen:
        raise UserError(
            f"no route in {data_dir} has {needed} tracks or more: ingest with --clusters "
            f"routes (the default), or {command} one cluster"
        )
    return chosen


def require_tracks(table: pd.DataFrame, name: str, needed: int) -> None:
    """One-line `UserError` unless `table` (the tracks selected as `name`) holds at least
    `needed` tracks."""
    if len(table) < needed:
        raise UserError(
            f"{name} has {len(table)} track{'s' if len(table) != 1 else ''}; at least {needed} "
            f"are needed to train on it (pick a larger route or cluster, or ingest more data)"
        )


def load_tracks(data_dir: Path, track_ids: Sequence[int]) -> list[Track]:
    """The given tracks' points, in the order of `track_ids`. One sort of all the points (by
    track, then time; points of one time keep their order in the file) instead of pandas work per
    track, which took a millisecond a track: 2 s for a thousand, minutes for a month of a coast."""
    points_path, _ = _paths(data_dir)
    ids = [int(i) for i in track_ids]
    table = read_track_table(data_dir)[["track_id", "mmsi", "start", "cluster", "route"]]
    asked = table[table["track_id"].isin(ids)]
    rows = {int(r.track_id): r for r in asked.itertuples(index=False)}
    try:
        motion = [c for c in MOTION if c in pq.ParquetDataset(points_path).schema.names]
        points = pq.read_table(
            points_path,
            columns=["track_id", "time", "lon", "lat", *motion],
            filters=[("track_id", "in", ids)],
        )
    except Exception as exc:
        raise UserError(f"cannot read {points_path}: {str(exc).splitlines()[0]}") from None
    time = points.column("time")
    if not pa.types.is_timestamp(time.type):
        raise UserError(f"{points_path}: its time column is {time.type}, not a timestamp")
    per_second = _TICKS_PER_SECOND[time.type.unit]
    ticks = time.cast(pa.int64()).to_numpy()
    track = points.column("track_id").to_numpy()
    order = np.lexsort((ticks, track))
    track, ticks = track[order], ticks[order]
    lonlat = np.stack([_floats(points, c)[order] for c in ("lon", "lat")], axis=1)
    reported = {c: _floats(points, c)[order] for c in motion}
    first = np.flatnonzero(np.r_[True, track[1:] != track[:-1]])
    ends = np.r_[first[1:], len(track)]
    where = {
        t: (lo, hi)
        for t, lo, hi in zip(track[first].tolist(), first.tolist(), ends.tolist(), strict=True)
    }
    out = []
    for tid in ids:
        lo, hi = where.get(tid, (0, 0))
        if hi - lo < 2:
            raise UserError(f"track {tid} has fewer than 2 points in {points_path}")
        seconds = (ticks[lo:hi] - ticks[lo]) / per_second
        row = rows[tid]
        out.append(
            Track(
                tid,
                int(row.mmsi),
                row.start,
                lonlat[lo:hi],
                np.diff(seconds) / 3600.0,
                str(row.cluster),
                None if row.route is None else str(row.route),
                *(reported[c][lo:hi] if c in reported else None for c in MOTION),
            )
        )
    return out


MOTION = ("sog", "cog")
"""What a `Track` reads of the reported motion, where points.parquet has it."""


def _floats(points: pa.Table, name: str) -> np.ndarray:
    """A column as float64, NaN where null."""
    return pc.fill_null(points.column(name).cast(pa.float64()), np.nan).to_numpy()


_TICKS_PER_SECOND = {"s": 1, "ms": 1_000, "us": 1_000_000, "ns": 1_000_000_000}
"""Ticks of each Arrow timestamp unit in one second."""
