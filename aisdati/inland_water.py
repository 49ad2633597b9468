"""Inland water the coastline does not know: the lakes and rivers that the land test
(`aisdati.coastline.on_land`) counts as water.

Why: OpenStreetMap's land polygons end at the coastline, so the Great Lakes and every river
above its tidal limit (the Mississippi, the Columbia, the Ohio, the Lake Washington Ship Canal)
are land to them, and a vessel sailing there would be reported ashore.

Source: Natural Earth 1:10m (public domain; `aisdati/data/inland_water.npz`, built by
`scripts/inland_water.py`): every lake and reservoir polygon (`ne_10m_lakes` and its North
American and European supplements) and every river and lake centre line that is not
intermittent (`ne_10m_rivers_lake_centerlines`, `ne_10m_rivers_north_america`,
`ne_10m_rivers_europe`). A river is water within `RIVER_HALF_WIDTH_M` of its centre line.

What it misses: channels, bayous, canals and marinas Natural Earth does not draw at 1:10m (the
Houston Ship Channel, the Intracoastal Waterway, the Kiel Canal); the `seen` water of a model's
training traffic (`aisdati.tracks.ashore`) covers those where a model is used. What it costs: a
position within about `RIVER_HALF_WIDTH_M` plus the ashore margin of any mapped river, navigable
or not, is not ashore.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from importlib.resources import files

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from aisdati.geo import EARTH_RADIUS_M

RIVER_HALF_WIDTH_M = 1000.0
"""Half the width of water around a river's centre line: half of a navigable river's width
(the lower Mississippi and the Columbia are 0.5-2 km wide) plus Natural Earth 1:10m's placing
of its lines (up to about 1 km off the bank at New Orleans); narrower rivers are given the
same, wider ones are not. With the ashore margin a river's reports within about 1.4 km of
its line are not ashore."""

M_PER_DEG = EARTH_RADIUS_M * math.pi / 180.0
POLYGON = int(shapely.GeometryType.POLYGON)
BBox = tuple[float, float, float, float]


@dataclass(frozen=True)
class _Layer:
    lakes: np.ndarray  # Polygons
    rivers: np.ndarray  # LineStrings
    lake_tree: shapely.STRtree
    river_tree: shapely.STRtree


@cache
def _layer() -> _Layer:
    with np.load(str(files("aisdati") / "data" / "inland_water.npz")) as z:
        lakes = shapely.from_ragged_array(
            shapely.GeometryType.POLYGON,
            z["lake_xy"].astype(np.float64),
            (z["lake_rings"], z["lake_polys"]),
        )
        rivers = shapely.from_ragged_array(
            shapely.GeometryType.LINESTRING,
            z["river_xy"].astype(np.float64),
            (z["river_parts"],),
        )
    return _Layer(lakes, rivers, shapely.STRtree(lakes), shapely.STRtree(rivers))


def water(bbox: BBox) -> shapely.MultiPolygon:
    """The inland water inside a lon/lat box (lon_min, lat_min, lon_max, lat_max), clipped to
    it: lakes, and rivers widened to `RIVER_HALF_WIDTH_M` on either side. Meant for boxes of a
    degree or so (the rivers are widened in a flat frame at the box's middle latitude)."""
    x0, y0, x1, y1 = bbox
    layer = _layer()
    lakes = layer.lakes[layer.lake_tree.query(shapely.box(*bbox))]
    half_deg = RIVER_HALF_WIDTH_M / M_PER_DEG
    cos_lat = max(math.cos(math.radians(max(abs(y0), abs(y1)))), 0.01)
    wide = (x0 - half_deg / cos_lat, y0 - half_deg, x1 + half_deg / cos_lat, y1 + half_deg)
    near = layer.rivers[layer.river_tree.query(shapely.box(*wide))]
    parts = list(shapely.clip_by_rect(shapely.make_valid(lakes), *bbox))
    if len(near):
        parts.append(shapely.clip_by_rect(_widened(near, wide, half_deg), *bbox))
    if not parts:
        return shapely.MultiPolygon()
    pieces = shapely.get_parts(shapely.union_all(parts))  # clipping may leave edges: areas only
    return shapely.MultiPolygon(list(pieces[shapely.get_type_id(pieces) == POLYGON]))


def _widened(lines: np.ndarray, wide: BBox, half_deg: float) -> BaseGeometry:
    """The lines (cut to the box `wide`) widened by `half_deg` degrees of latitude on either
    side, in a frame whose longitudes are shrunk by the cosine of the box's middle latitude."""
    mid_x, mid_y = (wide[0] + wide[2]) / 2, (wide[1] + wide[3]) / 2
    k = math.cos(math.radians(mid_y))
    cut = shapely.clip_by_rect(lines, *wide)
    flat = shapely.transform(cut, lambda xy: np.column_stack([(xy[:, 0] - mid_x) * k, xy[:, 1]]))
    band = shapely.union_all(shapely.buffer(flat, half_deg, quad_segs=4))
    return shapely.transform(band, lambda xy: np.column_stack([xy[:, 0] / k + mid_x, xy[:, 1]]))
