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
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon, shape

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


def load_roi(spec: str | Path | None) -> Polygon | MultiPolygon | None:
    """Resolve `--roi`: 'florida-straits' (default), 'none' (no spatial filter) or a GeoJSON file
    holding a Polygon or MultiPolygon (bare geometry, Feature, or FeatureCollection)."""
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
    geom = _geometry_of(doc, path)
    if geom.is_empty or not geom.is_valid:
        raise UserError(f"--roi {path}: the polygon is empty or invalid (self-intersecting?)")
    return geom


def _geometry_of(doc: object, path: Path) -> Polygon | MultiPolygon:
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
        try:
            polygons.append(shape(g))
        except (ValueError, TypeError, IndexError, AttributeError) as exc:
            raise UserError(f"--roi {path}: malformed {kind} coordinates ({exc})") from None
    if not polygons:
        raise UserError(f"--roi {path}: the FeatureCollection holds no polygon")
    return polygons[0] if len(polygons) == 1 else shapely.union_all(polygons)


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
