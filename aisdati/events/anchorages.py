"""Ports and anchorages: where many vessels stop, learned from the traffic itself as Global
Fishing Watch builds its anchorages (a grid of cells about 0.5 km on a side; a cell where
enough distinct vessels were stopped is an anchorage point), or given as GeoJSON by the user.

They say where a vessel is *not at sea*: a port visit is a stay near one
(`aisdati.events.port_visits`), an encounter is at least 10 km from every one
(`aisdati.events.encounters`). `detect` learns them from every report of its ingest output
(or reads `--ports`) and writes them to anchorages.geojson, which `--ports` reads back."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow.dataset as ds
from scipy.spatial import cKDTree
from shapely import contains_xy
from shapely.geometry import shape
from shapely.geometry.base import BaseGeometry

from aisdati.errors import UserError
from aisdati.events.reports import M_PER_DEG
from aisdati.events.settings import EventSettings
from aisdati.geo import EARTH_RADIUS_M, arc_m, unit_vectors
from aisdati.tracks.reports import REPORTS, has_reports

FILL_M = 250.0
"""A given polygon becomes points this far apart over its area and outline (a report inside
it is then within this of a point)."""


@dataclass(frozen=True)
class Anchorages:
    """Anchorage points (lon/lat degrees), how many distinct vessels stopped at each (0 where
    given) and the port each belongs to (a name where given, else None)."""

    lon: np.ndarray
    lat: np.ndarray
    vessels: np.ndarray
    port: tuple[str | None, ...]
    source: str
    """Where they come from: "learned from N reports" or the file given."""
    stoppers: tuple[frozenset[int], ...] = ()
    """The vessels stopped at each learned point (none where given)."""

    def __len__(self) -> int:
        return len(self.lon)

    @cached_property
    def _tree(self) -> cKDTree | None:
        if not len(self):
            return None
        return cKDTree(unit_vectors(np.column_stack([self.lon, self.lat])))

    def subset(self, keep: np.ndarray) -> Anchorages:
        """The points `keep` (a mask) selects."""
        pick = np.flatnonzero(keep)
        stoppers = tuple(self.stoppers[i] for i in pick) if self.stoppers else ()
        port = tuple(self.port[i] for i in pick)
        return Anchorages(
            self.lon[pick], self.lat[pick], self.vessels[pick], port, self.source, stoppers
        )

    def fragile(self, spare: int, min_vessels: int) -> np.ndarray:
        """[n] which learned points would stop being anchorages without `spare` of the vessels
        stopped at them (given points never)."""
        learned = self.vessels > 0
        return learned & (self.vessels < min_vessels + spare)

    def within(self, lon: float, lat: float, metres: float) -> list[int]:
        """The points within `metres` of a position."""
        if self._tree is None:
            return []
        chord = 2 * np.sin(metres / (2 * EARTH_RADIUS_M))
        return list(self._tree.query_ball_point(unit_vectors(np.array([lon, lat])), chord))

    def nearest(self, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each position's distance (m) to the nearest anchorage point and that point's index
        (inf and -1 where there is none)."""
        lon, lat = np.asarray(lon, np.float64), np.asarray(lat, np.float64)
        if self._tree is None or not lon.size:
            return np.full(lon.shape, np.inf), np.full(lon.shape, -1)
        chord, index = self._tree.query(unit_vectors(np.stack([lon, lat], axis=-1)))
        return arc_m(chord), index

    def geojson(self) -> dict[str, Any]:
        """A FeatureCollection of the points (what `read_ports` reads back)."""
        features = [
            {
                "type": "Feature",
                "geometry": {"type": "Point", "coordinates": [float(x), float(y)]},
                "properties": {"vessels_stopped": int(n), "port": p},
            }
            for x, y, n, p in zip(self.lon, self.lat, self.vessels, self.port, strict=True)
        ]
        return {"type": "FeatureCollection", "source": self.source, "features": features}


def learn(
    mmsi: np.ndarray, lon: np.ndarray, lat: np.ndarray, s: EventSettings = EventSettings()
) -> Anchorages:
    """The anchorage points of stopped reports (`mmsi`, `lon`, `lat` of reports under
    `stopped_kn`): the centre of each cell of `anchorage_cell_m` where at least
    `anchorage_min_vessels` distinct vessels were stopped. Rows of cells are `anchorage_cell_m`
    of latitude, and each row's cells that many metres of longitude at its latitude (an
    equal-area grid, as S2's level-14 cells nearly are)."""
    lat_step = s.anchorage_cell_m / M_PER_DEG
    row = np.floor(np.asarray(lat, np.float64) / lat_step)
    row_lat = np.clip((row + 0.5) * lat_step, -89.0, 89.0)
    lon_step = lat_step / np.cos(np.radians(row_lat))
    col = np.floor(np.asarray(lon, np.float64) / lon_step)
    cells = pd.DataFrame({"mmsi": mmsi, "row": row, "col": col, "lon_step": lon_step})
    per = cells.groupby(["row", "col"]).agg(
        vessels=("mmsi", "nunique"), lon_step=("lon_step", "first"), who=("mmsi", frozenset)
    )
    per = per[per["vessels"] >= s.anchorage_min_vessels].reset_index()
    return Anchorages(
        ((per["col"] + 0.5) * per["lon_step"]).to_numpy(np.float64),
        ((per["row"] + 0.5) * lat_step).to_numpy(np.float64),
        per["vessels"].to_numpy(np.int64),
        (None,) * len(per),
        f"learned from {len(cells):,} stopped reports",
        tuple(frozenset(int(m) for m in w) for w in per["who"]),
    )


def learned_from(reports: pd.DataFrame, s: EventSettings = EventSettings()) -> Anchorages:
    """`learn` over a table of reports (reports.parquet's columns)."""
    stopped = reports[reports["sog"] < s.stopped_kn]
    return learn(*(stopped[c].to_numpy() for c in ("mmsi", "lon", "lat")), s=s)


def of_area(data_dir: Path, s: EventSettings = EventSettings()) -> Anchorages:
    """The anchorages of an ingest output: learned from every stopped report of its
    reports.parquet (only those are read); none where the output predates reports.parquet
    (points.parquet keeps no slow report)."""
    if not has_reports(data_dir):
        return Anchorages(np.empty(0), np.empty(0), np.empty(0, np.int64), (), "none learned")
    table = ds.dataset(data_dir / REPORTS, format="parquet").to_table(
        columns=["mmsi", "lon", "lat", "sog"], filter=ds.field("sog") < s.stopped_kn
    )
    return learned_from(table.to_pandas(), s)


def area_ports(data_dir: Path, given: Path | None = None) -> Anchorages:
    """An ingest output's ports and anchorages: those `given` as GeoJSON (`read_ports`), else
    learned from its traffic (`of_area`)."""
    return read_ports(given) if given is not None else of_area(data_dir)


def read_ports(path: Path) -> Anchorages:
    """Ports and anchorages given as GeoJSON (a FeatureCollection, a Feature or a geometry):
    Points are anchorage points, Polygons and MultiPolygons port areas (filled with points
    `FILL_M` apart); a feature's `name` or `port` property names its port. One line on a file
    that is not that."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise UserError(f"--ports {path}: cannot read it as JSON ({exc})") from None
    features = doc.get("features") if isinstance(doc, dict) else None
    if features is None:
        features = [doc if doc.get("type") == "Feature" else {"geometry": doc}]
    lon, lat, names = [], [], []
    for i, f in enumerate(features):
        try:
            geometry = shape(f["geometry"])
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise UserError(f"--ports {path}: feature {i} has no readable geometry ({exc})") from (
                None
            )
        if geometry.geom_type not in ("Point", "MultiPoint", "Polygon", "MultiPolygon"):
            raise UserError(
                f"--ports {path}: feature {i} is a {geometry.geom_type}; ports are Points or "
                "Polygons"
            )
        props = f.get("properties") or {}
        xy = _points_of(geometry)
        lon += xy[:, 0].tolist()
        lat += xy[:, 1].tolist()
        names += [props.get("name") or props.get("port")] * len(xy)
    if not lon:
        raise UserError(f"--ports {path}: no port or anchorage in it")
    if not (np.all(np.abs(lat) <= 90) and np.all(np.abs(lon) <= 180)):
        raise UserError(f"--ports {path}: coordinates must be lon/lat degrees (WGS84)")
    n = len(lon)
    return Anchorages(np.array(lon), np.array(lat), np.zeros(n, np.int64), tuple(names), str(path))


def _points_of(geometry: BaseGeometry) -> np.ndarray:
    """[n, 2] lon/lat: a point's own; a polygon's outline and interior every `FILL_M`."""
    if geometry.geom_type in ("Point", "MultiPoint"):
        return np.array([(p.x, p.y) for p in getattr(geometry, "geoms", [geometry])])
    x0, y0, x1, y1 = geometry.bounds
    lat_step = FILL_M / M_PER_DEG
    lon_step = lat_step / max(np.cos(np.radians((y0 + y1) / 2)), 0.05)
    xs = np.arange(x0, x1 + lon_step, lon_step)
    ys = np.arange(y0, y1 + lat_step, lat_step)
    xs, ys = (g.ravel() for g in np.meshgrid(xs, ys))
    inside = contains_xy(geometry, xs, ys)
    outline = geometry.boundary.segmentize(lat_step)
    edge = [xy for ring in getattr(outline, "geoms", [outline]) for xy in ring.coords]
    return np.vstack([np.column_stack([xs[inside], ys[inside]]), np.array(edge).reshape(-1, 2)])
