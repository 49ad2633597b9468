"""Region of interest: the paper's default Florida Straits polygon, GeoJSON polygons, and a fast
vectorised point-in-polygon test.

The default is derived from section 6 and Fig. 4 of the paper: traffic "between the surroundings
of Miami (north east) and the entrance to the gulf of Mexico (south west)" in UTM zone 17
(84-78 deg W), leaving out "trajectories going to or coming from the eastern Greater Antilles as
well as on the north of the Florida Keys". The paper's rollouts start on "the vertical boundary at
the entrance to the gulf of Mexico" and "the horizontal boundary near Miami", so the polygon has
a meridian as its west edge and a parallel as its north edge. Its vertices (lon, lat, WGS84):

* west edge, the Gulf entrance: the meridian 83.0 W (just west of the Dry Tortugas), from the
  Cuban coast at 22.95 N up to 24.75 N;
* north-west edge: along the reef line on the south side of the Florida Keys (Dry Tortugas, Key
  West, Marathon, Key Largo), so the waters north of the Keys (Florida Bay, the Gulf coast of
  Florida) are outside;
* north edge, near Miami: the parallel 25.9 N from the coast (80.10 W) to Bimini (79.25 W);
* east edge: the western rim of the Great Bahama Bank down to 25.0 N, then a cut to the Cuban
  coast west of Cay Sal Bank, which leaves out the Santaren and Nicholas Channels, the routes to
  and from the eastern Greater Antilles;
* south edge: the north coast of Cuba (Cardenas, Havana, Mariel).

It is an approximation of a boundary the paper shows only as a figure; pass your own polygon with
`--roi file.geojson` when it matters.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import shapely
import shapely.affinity
import shapely.errors
from shapely.geometry import MultiPolygon, Polygon, box, shape

from aisdati.errors import UserError

FLORIDA_STRAITS: tuple[tuple[float, float], ...] = (
    (-83.00, 22.95),
    (-83.00, 24.75),
    (-82.20, 24.50),
    (-81.80, 24.45),
    (-81.00, 24.60),
    (-80.60, 24.85),
    (-80.30, 25.20),
    (-80.15, 25.50),
    (-80.10, 25.90),
    (-79.25, 25.90),
    (-79.30, 25.00),
    (-80.20, 24.25),
    (-80.70, 23.20),
    (-81.50, 23.10),
    (-82.40, 23.15),
)
"""Vertices of the default region of interest (lon, lat), see the module docstring."""

DEFAULT_ROI = "florida-straits"


def florida_straits() -> Polygon:
    """The paper's region of interest as a shapely polygon."""
    return Polygon(FLORIDA_STRAITS)


def load_roi(
    spec: str | Path | None, warn: Callable[[str], None] | None = None
) -> Polygon | MultiPolygon | None:
    """Resolve `--roi`: 'florida-straits' (default), 'none' (no spatial filter) or a GeoJSON file
    holding a Polygon or MultiPolygon (bare geometry, Feature, or FeatureCollection).

    Coordinates must be finite, latitudes in [-90, 90] and longitudes in [-360, 360]. A ring with
    an edge spanning more than 180 degrees of longitude crosses the antimeridian (each edge takes
    the shorter way round, as most tools draw them): it is unwrapped and split at 180, so that
    170..-170 is the 20 degrees around the antimeridian, not the 340 degrees outside it; so are
    longitudes beyond 180 (170..190). `warn` receives a note when that happens."""
    if spec is None or str(spec).lower() == "none":
        return None
    if str(spec).lower() == DEFAULT_ROI:
        return florida_straits()
    path = Path(spec)
    if not path.is_file():
        raise UserError(
            f"--roi {spec}: no such file (use 'none', '{DEFAULT_ROI}' or a GeoJSON file)"
        )
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserError(f"--roi {path}: not valid GeoJSON ({exc})") from None
    notes: list[str] = []
    try:
        geom = _geometry_of(doc, path, notes)
        valid = not geom.is_empty and geom.is_valid
    except shapely.errors.GEOSException as exc:
        raise UserError(f"--roi {path}: not a usable polygon ({exc})") from None
    if not valid:
        raise UserError(f"--roi {path}: the polygon is empty or invalid (self-intersecting?)")
    if notes and warn is not None:
        warn(f"--roi {path}: {notes[0]}")
    return geom


def _geometry_of(doc: object, path: Path, notes: list[str]) -> Polygon | MultiPolygon:
    """Union of the polygons in a GeoJSON document; anything that is not a polygon is an error."""
    if not isinstance(doc, dict):
        raise UserError(f"--roi {path}: expected a GeoJSON object")
    if doc.get("type") == "FeatureCollection":
        features = doc.get("features") or []
        geometries = [f.get("geometry") if isinstance(f, dict) else None for f in features]
    elif doc.get("type") == "Feature":
        geometries = [doc.get("geometry")]
    else:
        geometries = [doc]
    polygons = []
    for g in geometries:
        kind = g.get("type") if isinstance(g, dict) else None
        if kind not in ("Polygon", "MultiPolygon"):
            raise UserError(
                f"--roi {path}: needs a Polygon or MultiPolygon, found {kind or 'no geometry'}"
            )
        if not all(math.isfinite(v) for v in _numbers(g.get("coordinates"))):
            raise UserError(f"--roi {path}: the polygon has NaN or infinite coordinates")
        try:
            geom = shape(g)
        except (ValueError, TypeError, IndexError, AttributeError) as exc:
            raise UserError(f"--roi {path}: malformed {kind} coordinates ({exc})") from None
        _check_coordinates(geom, path)
        polygons.extend(_wrapped(p, notes) for p in getattr(geom, "geoms", [geom]))
    if not polygons:
        raise UserError(f"--roi {path}: the FeatureCollection holds no polygon")
    return polygons[0] if len(polygons) == 1 else shapely.union_all(polygons)


def _numbers(node: object) -> list[float]:
    """The numbers in nested GeoJSON coordinate lists (anything else is left to `shape`)."""
    if isinstance(node, (int, float)) and not isinstance(node, bool):
        return [float(node)]
    if isinstance(node, (list, tuple)):
        return [v for item in node for v in _numbers(item)]
    return []


def _check_coordinates(geom: Polygon | MultiPolygon, path: Path) -> None:
    """Finite coordinates, on the Earth: NaN would reach GEOS (a crash, not a message)."""
    xy = shapely.get_coordinates(geom)
    if not np.isfinite(xy).all():
        raise UserError(f"--roi {path}: the polygon has NaN or infinite coordinates")
    if xy.size and (np.abs(xy[:, 1]).max() > 90 or np.abs(xy[:, 0]).max() > 360):
        raise UserError(
            f"--roi {path}: coordinates must be (lon, lat) with lat in [-90, 90] and lon in "
            f"[-360, 360]; found lon {xy[:, 0].min():g}..{xy[:, 0].max():g}, "
            f"lat {xy[:, 1].min():g}..{xy[:, 1].max():g}"
        )


def _unwrap(lon: np.ndarray) -> np.ndarray:
    """Longitudes made continuous: each step taken the shorter way round (|step| <= 180)."""
    steps = np.diff(lon)
    steps = (steps + 180.0) % 360.0 - 180.0
    return np.r_[lon[:1], lon[0] + np.cumsum(steps)]


def _wrapped(polygon: Polygon, notes: list[str]) -> Polygon | MultiPolygon:
    """`polygon` in [-180, 180] longitudes: rings that cross the antimeridian unwrapped, then the
    parts beyond +-180 moved back by 360 degrees (so the result may be a MultiPolygon)."""
    rings = [np.asarray(polygon.exterior.coords)] + [
        np.asarray(r.coords) for r in polygon.interiors
    ]
    crosses = any((np.abs(np.diff(r[:, 0])) > 180).any() for r in rings)
    if crosses:
        shell = rings[0].copy()
        shell[:, 0] = _unwrap(shell[:, 0])
        holes = []
        for ring in rings[1:]:
            ring = ring.copy()
            ring[:, 0] = _unwrap(ring[:, 0])
            ring[:, 0] += 360.0 * np.round((shell[:, 0].mean() - ring[:, 0].mean()) / 360.0)
            holes.append(ring)
        polygon = Polygon(shell, holes)
    x0, _, x1, _ = polygon.bounds
    if x0 >= -180 and x1 <= 180:
        return polygon
    pieces = []
    for k in (-2, -1, 0, 1, 2):
        part = polygon.intersection(box(360.0 * k - 180, -90, 360.0 * k + 180, 90))
        if not part.is_empty:
            pieces.append(shapely.affinity.translate(part, xoff=-360.0 * k))
    merged = shapely.union_all(pieces)
    west, east = (x0 + 180) % 360 - 180, (x1 + 180) % 360 - 180
    how = (
        "an edge spans more than 180 degrees of longitude, so edges were taken the shorter way "
        "round; to mean the other side, add vertices so that no edge spans more than 180"
        if crosses
        else "longitudes beyond 180"
    )
    notes.append(
        f"the polygon crosses the antimeridian: read as the area from {west:g} eastwards across "
        f"180 to {east:g}, split there ({how})"
    )
    polys = [g for g in getattr(merged, "geoms", [merged]) if isinstance(g, Polygon)]
    return polys[0] if len(polys) == 1 else MultiPolygon(polys)


def in_roi(roi: Polygon | MultiPolygon, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Mask of the points inside (or on the boundary of) `roi`. A bounding-box test first, so the
    exact test only runs on the few points near the area; NaN positions are outside."""
    x0, y0, x1, y1 = roi.bounds
    with np.errstate(invalid="ignore"):
        near = (lon >= x0) & (lon <= x1) & (lat >= y0) & (lat <= y1)
    mask = np.zeros(lon.shape, dtype=bool)
    idx = np.flatnonzero(near)
    if idx.size:
        shapely.prepare(roi)
        mask[idx] = shapely.intersects_xy(roi, lon[idx], lat[idx])
    return mask
