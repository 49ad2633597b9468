"""Build aisdati/data/inland_water.npz, the lakes and rivers the land test knows
(`aisdati.inland_water`), from Natural Earth's 1:10m physical layers (public domain), GeoJSON:

    python scripts/inland_water.py NE_GEOJSON_DIR aisdati/data/inland_water.npz

NE_GEOJSON_DIR holds ne_10m_lakes.json, ne_10m_lakes_north_america.json,
ne_10m_lakes_europe.json, ne_10m_rivers_lake_centerlines.json,
ne_10m_rivers_north_america.json and ne_10m_rivers_europe.json (Natural Earth 4.x, e.g. the
GeoJSON copies of github.com/martynafford/natural-earth-geojson, `10m/physical/*.7z`).

Kept: every lake and reservoir polygon, and every river and lake centre line that is not
intermittent (a dry wash carries no vessel). Outlines are simplified by `TOLERANCE_DEG` (well
under Natural Earth 1:10m's own accuracy) and stored as float32 (about 1 m).
"""

from __future__ import annotations

import sys
from pathlib import Path

import geopandas as gpd
import numpy as np
import pandas as pd
import shapely

LAKES = ("ne_10m_lakes", "ne_10m_lakes_north_america", "ne_10m_lakes_europe")
RIVERS = ("ne_10m_rivers_lake_centerlines", "ne_10m_rivers_north_america", "ne_10m_rivers_europe")
TOLERANCE_DEG = 0.0005
"""About 50 m: Natural Earth 1:10m places its lines to a few hundred metres."""


def read(folder: Path, names: tuple[str, ...]) -> gpd.GeoDataFrame:
    return pd.concat([gpd.read_file(folder / f"{n}.json") for n in names], ignore_index=True)


def parts(geoms: np.ndarray) -> np.ndarray:
    """Single parts of (multi) geometries, empty ones dropped."""
    single = shapely.get_parts(geoms)
    return single[~shapely.is_empty(single)]


def main(folder: Path, out: Path) -> None:
    lakes = read(folder, LAKES)
    polys = parts(shapely.make_valid(shapely.simplify(lakes.geometry.values, TOLERANCE_DEG)))
    polys = polys[shapely.get_type_id(polys) == shapely.GeometryType.POLYGON]
    rivers = read(folder, RIVERS)
    rivers = rivers[~rivers["featurecla"].str.contains("Intermittent")]
    lines = parts(shapely.simplify(rivers.geometry.values, TOLERANCE_DEG))
    _, lake_xy, (lake_rings, lake_polys) = shapely.to_ragged_array(polys)
    _, river_xy, (river_parts,) = shapely.to_ragged_array(lines)
    np.savez_compressed(
        out,
        lake_xy=lake_xy.astype(np.float32),
        lake_rings=lake_rings.astype(np.int64),
        lake_polys=lake_polys.astype(np.int64),
        river_xy=river_xy.astype(np.float32),
        river_parts=river_parts.astype(np.int64),
    )
    size = out.stat().st_size / 1e6
    vertices = len(lake_xy) + len(river_xy)
    print(
        f"{out}: {len(polys):,} lakes, {len(lines):,} river lines, {vertices:,} vertices, "
        f"{size:.1f} MB"
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
