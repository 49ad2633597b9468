"""The offline coastline (`aisdati.coastline`): the land test at fjord and harbour scale, its
speed, the clipped land polygons and their cache."""

from __future__ import annotations

import sys
import time

import numpy as np
import pytest
from shapely.geometry import MultiPolygon, box

from aisdati import coastline

# Checked on a drawn map: the middle of Douglas Channel (about 4 km wide here, 2 km from either
# shore) and a point 5 km inland on the land east of it, in the Kitimat sample's area.
DOUGLAS_CHANNEL = (-129.205, 53.55)
INLAND_KITIMAT = (-128.75, 53.3)
KITIMAT_BOX = (-129.5, 53.2, -128.6, 53.7)


# ----------------------------------------------------------------------------- coastline
def test_source_is_osm_from_roaring_landmask():
    src = coastline.source()
    assert src.name == "osm"
    assert "OpenStreetMap" in src.attribution


def test_on_land_at_fjord_scale():
    lon, lat = zip(DOUGLAS_CHANNEL, INLAND_KITIMAT, strict=True)
    assert coastline.on_land(np.array(lon), np.array(lat)).tolist() == [False, True]


def test_on_land_at_harbour_scale():
    # The Hudson off Midtown (GSHHG and 1 km rasters fill it in), the East River, Central Park.
    got = coastline.on_land([-74.01, -73.966, -73.97], [40.75, 40.75, 40.78])
    assert got.tolist() == [False, False, True]


def test_on_land_shapes_wrapping_and_nan():
    lon = np.array([[DOUGLAS_CHANNEL[0], INLAND_KITIMAT[0]], [np.nan, -40.0]])
    lat = np.array([[DOUGLAS_CHANNEL[1], INLAND_KITIMAT[1]], [53.0, 30.0]])
    got = coastline.on_land(lon, lat)
    assert got.dtype == bool and got.shape == (2, 2)
    assert got.tolist() == [[False, True], [False, False]]  # NaN and the mid-Atlantic: sea
    assert coastline.on_land(lon + 360, lat).tolist() == got.tolist()
    assert coastline.on_land(*INLAND_KITIMAT).shape == ()
    assert coastline.on_land(np.zeros(0), np.zeros(0)).shape == (0,)


def test_on_land_is_fast():
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = KITIMAT_BOX
    lon, lat = rng.uniform(x0, x1, 100_000), rng.uniform(y0, y1, 100_000)
    coastline.on_land(lon, lat)  # cuts the tiles
    t = time.perf_counter()
    land = coastline.on_land(lon, lat)
    # ~1e6 points/s measured on the 2-core development machine; 1e5/s is the promise.
    assert time.perf_counter() - t < 1.0
    assert 0.3 < land.mean() < 0.9


def test_land_is_clipped_and_cached():
    geom = coastline.land(KITIMAT_BOX)
    assert isinstance(geom, MultiPolygon) and not geom.is_empty
    assert box(*KITIMAT_BOX).buffer(1e-9).contains(geom)
    assert coastline.land(KITIMAT_BOX) is geom
    simple = coastline.land(KITIMAT_BOX, tolerance=0.005)
    assert len(simple.geoms) < len(geom.geoms)
    assert coastline.land((-40.0, 30.0, -39.0, 31.0)).is_empty  # mid-Atlantic
    with pytest.raises(ValueError):
        coastline.land((1.0, 0.0, 0.0, 1.0))


@pytest.fixture
def fresh_coastline():
    coastline.clear_caches()
    yield
    coastline.clear_caches()


def test_fallback_without_roaring_landmask(monkeypatch, fresh_coastline):
    monkeypatch.setitem(sys.modules, "roaring_landmask", None)  # import raises ImportError
    with pytest.warns(RuntimeWarning, match="roaring-landmask is not installed"):
        src = coastline.source()
    assert src.name == "ne110m"
    assert coastline.on_land([-100.0, -40.0], [40.0, 30.0]).tolist() == [True, False]
    assert not coastline.land((-101.0, 39.0, -99.0, 41.0)).is_empty


def test_cache_is_written_then_memory_mapped(monkeypatch, tmp_path, fresh_coastline):
    monkeypatch.setenv("AISDATI_CACHE_DIR", str(tmp_path))
    built = []

    def fake_osm():  # the small 1:110m outline instead of the 9-million-vertex OSM land
        built.append(1)
        return coastline.ne110m_arrays()

    monkeypatch.setattr(coastline, "osm_arrays", fake_osm)
    first = coastline.cached_osm_arrays("test")
    (folder,) = tmp_path.iterdir()
    assert sorted(p.name for p in folder.iterdir()) == [f"{k}.npy" for k in sorted(first)]
    again = coastline.cached_osm_arrays("test")
    assert built == [1] and isinstance(again["coords"], np.memmap)
    np.testing.assert_array_equal(again["coords"], first["coords"])
    (folder / "coords.npy").write_bytes(b"broken")
    coastline.cached_osm_arrays("test")
    assert built == [1, 1] and np.load(folder / "coords.npy").shape == first["coords"].shape
