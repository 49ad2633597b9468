"""The live page's coastline: the offline land of the box the page shows, drawn as detect's
`map.html` draws it (`aisdati.detection.webmap.land_geojson`, its colours and attribution).
The page asks again as the operator pans and zooms, so the coast is as fine as the zoom."""

from __future__ import annotations

import json
import math
from functools import lru_cache

import numpy as np

from aisdati.detection.webmap import (
    COAST_ATTRIBUTION,
    COAST_COLOR,
    LAND_COLOR,
    WATER_COLOR,
    land_geojson,
)

STYLE = {"land": LAND_COLOR, "coast": COAST_COLOR, "water": WATER_COLOR}


def snapped(bbox: str) -> tuple[float, float, float, float] | None:
    """`west,south,east,north` (the page's view) widened to a grid of a quarter of its span
    and kept within the map's world, so that views close to each other share one land; None
    for anything else."""
    try:
        west, south, east, north = (float(v) for v in bbox.split(","))
    except ValueError:
        return None
    if not all(map(math.isfinite, (west, south, east, north))) or west >= east or south >= north:
        return None
    step = 2.0 ** math.ceil(math.log2(max(east - west, north - south) / 4))
    box = (
        max(math.floor(west / step) * step, -180.0),
        max(math.floor(south / step) * step, -85.0),
        min(math.ceil(east / step) * step, 180.0),
        min(math.ceil(north / step) * step, 85.0),
    )
    return box if box[0] < box[2] and box[1] < box[3] else None


@lru_cache(maxsize=64)
def land_json(box: tuple[float, float, float, float]) -> bytes:
    """The land of `box` (and as much again around it) with the style to draw it, as JSON."""
    west, south, east, north = box
    land = land_geojson(np.array([west, south]), np.array([east, north]))
    return json.dumps(
        {"land": land, "box": box, "style": STYLE, "attribution": COAST_ATTRIBUTION}
    ).encode()
