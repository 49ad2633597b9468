"""Reading the tracks that `aisdati ingest` wrote (data/processed) for training and detection.

A `Track` holds one track's positions (lon, lat degrees) and the real time steps between its
reports in hours, which is what the AIS environment and the detector work with.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from aisdati.errors import UserError

CLUSTERS = ("up", "down", "other")
TRACK_COLUMNS = ["track_id", "mmsi", "start", "end", "n_points", "length_km", "cluster"]


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

    @property
    def steps(self) -> int:
        return len(self.positions) - 1


def _paths(data_dir: Path) -> tuple[Path, Path]:
    points, tracks = data_dir / "points.parquet", data_dir / "tracks.parquet"
    for f in (points, tracks):
        if not f.is_file():
            raise UserError(f"{f} not found: run `aisdati ingest --out {data_dir}` first")
    return points, tracks


def read_track_table(data_dir: Path) -> pd.DataFrame:
    """tracks.parquet without its geometry column."""
    _, tracks = _paths(data_dir)
    try:
        table = pq.read_table(tracks, columns=TRACK_COLUMNS).to_pandas()
    except Exception as exc:  # pyarrow raises several types for damaged or foreign files
        raise UserError(f"cannot read {tracks}: {str(exc).splitlines()[0]}") from None
    return table


def select_cluster(table: pd.DataFrame, cluster: str, data_dir: Path) -> pd.DataFrame:
    if cluster not in CLUSTERS:
        raise UserError(f"unknown cluster {cluster!r}; choose from {', '.join(CLUSTERS)}")
    chosen = table[table["cluster"] == cluster]
    if chosen.empty:
        counts = table["cluster"].value_counts().to_dict()
        have = ", ".join(f"{k}: {v}" for k, v in counts.items()) or "no tracks at all"
        raise UserError(f"no tracks in cluster {cluster!r} in {data_dir} ({have})")
    return chosen


def load_tracks(data_dir: Path, track_ids: Sequence[int]) -> list[Track]:
    """The given tracks' points, in the order of `track_ids`."""
    points_path, _ = _paths(data_dir)
    table = read_track_table(data_dir).set_index("track_id")
    ids = [int(i) for i in track_ids]
    try:
        points = pq.read_table(
            points_path,
            columns=["track_id", "time", "lon", "lat"],
            filters=[("track_id", "in", ids)],
        ).to_pandas()
    except Exception as exc:
        raise UserError(f"cannot read {points_path}: {str(exc).splitlines()[0]}") from None
    out = []
    groups = dict(tuple(points.groupby("track_id", sort=False)))
    for tid in ids:
        g = groups.get(tid)
        if g is None or len(g) < 2:
            raise UserError(f"track {tid} has fewer than 2 points in {points_path}")
        g = g.sort_values("time")
        seconds = (g["time"] - g["time"].iloc[0]).dt.total_seconds().to_numpy()
        row = table.loc[tid]
        out.append(
            Track(
                tid,
                int(row["mmsi"]),
                row["start"],
                g[["lon", "lat"]].to_numpy(np.float64),
                np.diff(seconds) / 3600.0,
                str(row["cluster"]),
            )
        )
    return out
