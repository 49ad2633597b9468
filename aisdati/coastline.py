"""Offline coastline at any scale: land polygons for maps and a fast vectorised land test.

Source: the OpenStreetMap land polygons that the `roaring-landmask` wheel ships (a dependency
of aisdati; nothing is downloaded at run time). They resolve the coast to about 100-200 m
between vertices, enough for fjords and harbour channels (the Kitimat arm, the Hudson and the
East River, the Kill van Kull). OSM's coastline stops at the tidal limit, so the point test
(`on_land`) takes the lakes and rivers of `aisdati.inland_water` (Natural Earth 1:10m, shipped)
out of the land: the Great Lakes, the Mississippi and the Columbia are water to it. Maps
(`land`) draw the coastline's land alone. Attribution: © OpenStreetMap contributors, ODbL
(`source().attribution`); Natural Earth is public domain.

The first use on a machine converts the package's polygons (about 9 million vertices) into
flat arrays under the user cache folder (`$AISDATI_CACHE_DIR`, else `$XDG_CACHE_HOME/aisdati`,
else `~/.cache/aisdati`; about 90 MB, 10-20 s, 1 GB of memory while it runs); later processes
memory-map them and read only the polygons a box touches. Where that folder cannot be written
the arrays stay in memory for the process.

Fallback: when `roaring-landmask` cannot be imported (a platform without its wheel, an install
with `--no-deps`), the same API serves the Natural Earth 1:110m outline shipped in
`aisdati/data/` and warns once; maps then show only a rough coast, and `on_land` misses
harbours and small islands.

API: `land(bbox)` for drawing, `on_land(lon, lat)` for testing points, `source()` for what is
in use. Longitudes are in degrees east, [-180, 180]; a box is (lon_min, lat_min, lon_max,
lat_max) and must not cross the antimeridian.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import warnings
from dataclasses import dataclass
from functools import cache, lru_cache
from importlib.resources import files
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from aisdati.inland_water import water

log = logging.getLogger(__name__)

BBox = tuple[float, float, float, float]
"""(lon_min, lat_min, lon_max, lat_max) in degrees."""

TILE_DEG = 1.0
"""`on_land` clips the land to tiles of this size (degrees) and keeps the recent ones."""

BLOCK_DEG = 10.0
"""Tiles are cut from blocks of this size (a multiple of TILE_DEG)."""

CACHE_FORMAT = 1
_ARRAYS = ("coords", "rings", "polys", "bounds")


@dataclass(frozen=True)
class CoastlineSource:
    """Which land data is in use."""

    name: str  # "osm" (roaring-landmask) or "ne110m" (the fallback)
    description: str
    attribution: str


OSM = CoastlineSource(
    "osm",
    "OpenStreetMap land polygons shipped by roaring-landmask (~100-200 m vertex spacing)",
    "coastline © OpenStreetMap contributors (ODbL)",
)
NE110M = CoastlineSource(
    "ne110m",
    "Natural Earth 1:110m land, the Americas (fallback: roaring-landmask is not installed)",
    "coastline: Natural Earth 1:110m (public domain)",
)


@dataclass(frozen=True)
class _World:
    """All land polygons as flat arrays: `coords` [n, 2] lon/lat (float32, ~1 m), `rings`
    (offsets of each ring into coords), `polys` (offsets of each polygon's rings into rings;
    its first ring is the exterior), `bounds` [p, 4] per polygon."""

    coords: np.ndarray
    rings: np.ndarray
    polys: np.ndarray
    bounds: np.ndarray
    source: CoastlineSource


# ------------------------------------------------------------------------------- loading
def cache_dir() -> Path:
    """Folder of aisdati's cached files (the coastline arrays)."""
    if os.environ.get("AISDATI_CACHE_DIR"):
        return Path(os.environ["AISDATI_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "aisdati"


def _arrays_from_geometry(geom) -> dict[str, np.ndarray]:
    """Flat arrays of a (Multi)Polygon, one entry per polygon."""
    if isinstance(geom, Polygon):
        geom = MultiPolygon([geom])
    _, coords, (rings, polys, _multi) = shapely.to_ragged_array([geom])
    starts = rings[polys[:-1]]  # first coordinate of each polygon
    bounds = np.column_stack(
        [
            np.minimum.reduceat(coords[:, 0], starts),
            np.minimum.reduceat(coords[:, 1], starts),
            np.maximum.reduceat(coords[:, 0], starts),
            np.maximum.reduceat(coords[:, 1], starts),
        ]
    )
    return {
        "coords": coords.astype(np.float32),
        "rings": rings.astype(np.int64),
        "polys": polys.astype(np.int64),
        "bounds": bounds.astype(np.float32),
    }


def osm_arrays() -> dict[str, np.ndarray]:
    """The OSM land polygons of roaring-landmask as flat arrays (the slow conversion)."""
    from roaring_landmask import LandmaskProvider, Shapes

    return _arrays_from_geometry(shapely.from_wkb(Shapes.wkb(LandmaskProvider.Osm)))


def ne110m_arrays() -> dict[str, np.ndarray]:
    """The fallback Natural Earth 1:110m land shipped with aisdati, as flat arrays."""
    from shapely.geometry import shape

    doc = json.loads((files("aisdati") / "data" / "land_110m_americas.geojson").read_text())
    return _arrays_from_geometry(shape(doc["features"][0]["geometry"]))


def cached_osm_arrays(version: str) -> dict[str, np.ndarray]:
    """The OSM arrays, memory-mapped from the cache, built there first if missing."""
    folder = cache_dir() / f"land-osm-roaring-{version}-v{CACHE_FORMAT}"
    try:
        return {k: np.load(folder / f"{k}.npy", mmap_mode="r") for k in _ARRAYS}
    except (OSError, ValueError):
        pass
    log.info("building the coastline cache in %s (once per machine)", folder)
    arrays = osm_arrays()
    tmp = folder.with_name(f".{folder.name}.{os.getpid()}.tmp")
    try:
        tmp.mkdir(parents=True, exist_ok=True)
        for k, a in arrays.items():
            np.save(tmp / f"{k}.npy", a)
        if folder.exists():  # a broken cache: replace it
            shutil.rmtree(folder, ignore_errors=True)
        tmp.rename(folder)  # atomic; another process may have won the race
    except OSError as exc:
        log.warning("coastline cache not written (%s); keeping it in memory", exc)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return arrays


@cache
def _world() -> _World:
    try:
        from importlib.metadata import version

        import roaring_landmask  # noqa: F401

        arrays, src = cached_osm_arrays(version("roaring-landmask")), OSM
    except ImportError:
        warnings.warn(
            "roaring-landmask is not installed: maps and on_land use the coarse Natural Earth "
            "1:110m outline (pip install roaring-landmask for harbour-scale coastlines)",
            RuntimeWarning,
            stacklevel=3,
        )
        arrays, src = ne110m_arrays(), NE110M
    return _World(**arrays, source=src)


def clear_caches() -> None:
    """Forget the land loaded and cut so far: the next call loads it again (after the cache
    folder or the installed packages changed)."""
    for cached in (_world, _land, _block, _tile):
        cached.cache_clear()


def source() -> CoastlineSource:
    """The land data in use (loads it on first call)."""
    return _world().source


# ----------------------------------------------------------------------------- selecting
def _ranges(starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """np.concatenate([np.arange(s, e) for s, e in zip(starts, ends)]), vectorised."""
    lens = ends - starts
    if lens.sum() == 0:
        return np.zeros(0, dtype=np.int64)
    shift = starts - np.concatenate([[0], np.cumsum(lens)[:-1]])
    return np.repeat(shift, lens) + np.arange(lens.sum())


def _polygons_in(world: _World, bbox: BBox, min_extent: float = 0.0) -> np.ndarray:
    """The whole polygons whose bounds meet the box (and span at least min_extent degrees)."""
    x0, y0, x1, y1 = bbox
    b = world.bounds
    keep = (b[:, 0] <= x1) & (b[:, 2] >= x0) & (b[:, 1] <= y1) & (b[:, 3] >= y0)
    if min_extent > 0:
        keep &= np.maximum(b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]) >= min_extent
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return np.empty(0, dtype=object)
    ring_idx = _ranges(world.polys[idx], world.polys[idx + 1])
    c0, c1 = world.rings[ring_idx], world.rings[ring_idx + 1]
    coords = np.asarray(world.coords[_ranges(c0, c1)], dtype=np.float64)
    ring_off = np.concatenate([[0], np.cumsum(c1 - c0)])
    poly_off = np.concatenate([[0], np.cumsum(world.polys[idx + 1] - world.polys[idx])])
    return shapely.from_ragged_array(shapely.GeometryType.POLYGON, coords, (ring_off, poly_off))


def _only_polygons(geoms: np.ndarray) -> list[Polygon]:
    out: list[Polygon] = []
    for g in geoms:
        if isinstance(g, Polygon):
            if not g.is_empty:
                out.append(g)
        elif hasattr(g, "geoms"):  # Multi* or a collection from make_valid
            out.extend(_only_polygons(np.asarray(list(g.geoms), dtype=object)))
    return out


def _check_bbox(bbox: BBox) -> BBox:
    x0, y0, x1, y1 = (float(v) for v in bbox)
    if not (np.isfinite([x0, y0, x1, y1]).all() and x0 < x1 and y0 < y1):
        raise ValueError(f"a box is (lon_min, lat_min, lon_max, lat_max), got {bbox}")
    return max(x0, -180.0), max(y0, -90.0), min(x1, 180.0), min(y1, 90.0)


def _clip(polys: np.ndarray, bbox: BBox, tolerance: float = 0.0) -> list[Polygon]:
    """Valid polygons of `polys` cut by the box, simplified with `tolerance` if > 0."""
    clipped = shapely.clip_by_rect(polys, *bbox)
    if tolerance > 0:  # topology is repaired below, 20x faster than preserving it
        clipped = shapely.simplify(clipped, tolerance, preserve_topology=False)
    clipped = clipped[~shapely.is_empty(clipped)]
    bad = ~shapely.is_valid(clipped)
    if bad.any():  # a few OSM rings touch themselves
        clipped[bad] = shapely.make_valid(clipped[bad])
    return _only_polygons(clipped)


@lru_cache(maxsize=32)
def _land(bbox: BBox, tolerance: float) -> MultiPolygon:
    return MultiPolygon(_clip(_polygons_in(_world(), bbox, tolerance), bbox, tolerance))


def land(bbox: BBox, tolerance: float = 0.0) -> MultiPolygon:
    """The land inside a lon/lat box, clipped to it (cached per box).

    The members are the source's land polygons cut by the box (not dissolved: neighbours may
    touch). `tolerance` (degrees) simplifies the outline and drops islands smaller than it,
    for drawing a large box quickly: about the size of a pixel, e.g. span / 2000."""
    if tolerance < 0:
        raise ValueError("tolerance must be >= 0")
    return _land(_check_bbox(bbox), float(tolerance))


# --------------------------------------------------------------------------- point tests
@lru_cache(maxsize=32)
def _block(bx: int, by: int) -> tuple[np.ndarray, np.ndarray]:
    """Land of one BLOCK_DEG block (its polygons and their bounds), which tiles are cut from:
    cutting a continent once per block rather than once per tile. The caches hold a whole
    coast (the US day of tests/data touches 22 blocks and 320 tiles, ~200 MB): a live feed
    checks reports all along it in every chunk, and a cache smaller than that rebuilt its
    blocks and tiles for every chunk (0.5 ms a report instead of 2.4 us)."""
    x0, y0 = -180.0 + bx * BLOCK_DEG, -90.0 + by * BLOCK_DEG
    box = (x0, y0, x0 + BLOCK_DEG, y0 + BLOCK_DEG)
    polys = np.asarray(_clip(_polygons_in(_world(), box), box), dtype=object)
    return polys, shapely.bounds(polys).reshape(-1, 4)


@lru_cache(maxsize=1024)
def _tile(ix: int, iy: int, inland_water: bool) -> Polygon | MultiPolygon | bool:
    """Land of one tile, less its inland water (`aisdati.inland_water`) if asked: False (all
    water), True (all land) or a prepared geometry."""
    x0, y0 = -180.0 + ix * TILE_DEG, -90.0 + iy * TILE_DEG
    box = (x0, y0, x0 + TILE_DEG, y0 + TILE_DEG)
    per_block = round(BLOCK_DEG / TILE_DEG)
    polys, b = _block(ix // per_block, iy // per_block)
    near = (b[:, 0] <= box[2]) & (b[:, 2] >= box[0]) & (b[:, 1] <= box[3]) & (b[:, 3] >= box[1])
    dry = np.asarray(_clip(polys[near], box), dtype=object)
    if inland_water and dry.size:
        dry = shapely.difference(dry, water(box))
    geom = MultiPolygon(_only_polygons(dry))
    if geom.is_empty:
        return False
    if (
        geom.area >= TILE_DEG * TILE_DEG * (1 - 1e-12)
        and shapely.box(*box).difference(geom).is_empty
    ):
        return True
    shapely.prepare(geom)
    return geom


def on_land(
    lon: np.ndarray | float, lat: np.ndarray | float, inland_water: bool = True
) -> np.ndarray:
    """Whether each point is on land (True) or on water (False), vectorised: the sea, and with
    `inland_water` the lakes and rivers of `aisdati.inland_water` (False: the coastline alone).

    Longitudes wrap into [-180, 180); points exactly on the coastline count as land; NaN or
    infinite coordinates give False. Returns a bool array of the broadcast shape of lon, lat.
    A few hundred thousand to millions of points per second once the tiles that the points
    fall in are loaded (the first call in a new 1-degree tile clips it, ~10-100 ms)."""
    x, y = np.broadcast_arrays(np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64))
    shape = x.shape
    x = np.mod(x.ravel() + 180.0, 360.0) - 180.0
    y = y.ravel()
    out = np.zeros(x.size, dtype=bool)
    ok = np.flatnonzero(np.isfinite(x) & np.isfinite(y) & (np.abs(y) <= 90.0))
    if ok.size == 0:
        return out.reshape(shape)
    nx, ny = round(360 / TILE_DEG), round(180 / TILE_DEG)
    ix = np.clip(((x[ok] + 180.0) // TILE_DEG).astype(np.int64), 0, nx - 1)
    iy = np.clip(((y[ok] + 90.0) // TILE_DEG).astype(np.int64), 0, ny - 1)
    key = ix * ny + iy
    if key.min() == key.max():  # one tile: the usual case
        groups = [ok]
        keys = [int(key[0])]
    else:
        order = np.argsort(key, kind="stable")
        sk = key[order]
        cut = np.flatnonzero(np.diff(sk)) + 1
        groups = np.split(ok[order], cut)
        keys = [int(k) for k in sk[np.concatenate([[0], cut])]]
    for k, idx in zip(keys, groups, strict=True):
        tile = _tile(k // ny, k % ny, inland_water)
        if tile is True:
            out[idx] = True
        elif tile is not False:
            out[idx] = shapely.intersects_xy(tile, x[idx], y[idx])
    return out.reshape(shape)
