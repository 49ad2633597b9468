"""The offline coastline (aisdati.coastline) and the maps drawn over it (aisdati.detection.maps)."""

from __future__ import annotations

import io
import json
import sys
import time

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest
from shapely.geometry import MultiPolygon, box

from aisdati import coastline
from aisdati.detection import maps
from aisdati.detection.maps import map_subset, plot_detection_map, plot_track_evidence
from aisdati.detection.webmap import (
    LAYER_BEST_ROLLOUTS,
    LAYER_COAST,
    LAYER_FLAGGED,
    LAYER_MEDOIDS,
    LAYER_ROLLOUTS,
    LAYER_STRETCHES,
    LAYER_TRACKS,
    html_detection_map,
)
from aisdati.plots import LAND_COLOR, WATER_COLOR

# Checked on a drawn map: the middle of Douglas Channel (about 4 km wide here, 2 km from either
# shore) and a point 5 km inland on the land east of it, in the Kitimat sample's area.
DOUGLAS_CHANNEL = (-129.205, 53.55)
INLAND_KITIMAT = (-128.75, 53.3)
KITIMAT_BOX = (-129.5, 53.2, -128.6, 53.7)


def _rgb(hex_color: str) -> np.ndarray:
    return np.array([int(hex_color[i : i + 2], 16) for i in (1, 3, 5)]) / 255


def _share(img: np.ndarray, hex_color: str) -> float:
    """Fraction of the image's pixels within 2/255 of a colour."""
    return float((np.abs(img[..., :3] - _rgb(hex_color)).max(axis=-1) < 2.5 / 255).mean())


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


# ---------------------------------------------------------------------------------- maps
def _channel_tracks() -> list[np.ndarray]:
    """Two made-up tracks down Douglas Channel."""
    lat = np.linspace(53.62, 53.42, 40)
    return [np.column_stack([np.full_like(lat, -129.205 + d), lat]) for d in (-0.004, 0.004)]


def test_png_map_draws_land_at_fjord_scale():
    tracks = _channel_tracks()
    rollouts = [t + np.array([0.01, 0.0]) for t in tracks]
    lo, hi = np.array(KITIMAT_BOX[:2]), np.array(KITIMAT_BOX[2:])
    png = plot_detection_map(
        tracks,
        rollouts,
        np.array([True, False]),
        np.array([tracks[0][20], tracks[1][20]]),
        [(lo, hi)],
        title="Douglas Channel",
    )
    img = mpimg.imread(io.BytesIO(png), format="png")
    assert _share(img, LAND_COLOR) > 0.15  # the old 1:110m outline drew no land here
    assert _share(img, WATER_COLOR) > 0.05


def test_track_evidence_figure():
    track = _channel_tracks()[0]
    rollout = track + np.linspace(0, 0.03, len(track))[:, None] * [1.0, 0.0]
    profile = np.linspace(0, 0.03, len(track)) * 66_000
    png = plot_track_evidence(track, rollout, profile, (25, 35), "track 7: drifts east")
    img = mpimg.imread(io.BytesIO(png), format="png")
    assert img.shape[1] > img.shape[0] and _share(img, LAND_COLOR) > 0.05
    hours = np.arange(len(track)) / 6
    png = plot_track_evidence(track, None, profile, None, "no rollout", hours=hours)
    assert png.startswith(b"\x89PNG")
    with pytest.raises(ValueError, match="one value per track point"):
        plot_track_evidence(track, rollout, profile[:-1], None, "bad")


def test_html_map_layers(tmp_path):
    tracks = _channel_tracks()
    props = [
        {"track_id": i, "score": 0.5, "max_dev_lon": t[5, 0], "max_dev_lat": t[5, 1]}
        for i, t in enumerate(tracks)
    ]
    regions = [(np.array(KITIMAT_BOX[:2]), np.array(KITIMAT_BOX[2:]))]
    flagged = np.array([True, False])
    old = tmp_path / "old.html"
    html_detection_map(tracks, tracks, props, flagged, regions, old)  # the existing call
    assert LAYER_FLAGGED in old.read_text() and LAYER_MEDOIDS not in old.read_text()
    path = tmp_path / "map.html"
    html_detection_map(
        tracks,
        tracks,
        props,
        flagged,
        regions,
        path,
        best_rollouts=[tracks[1], None],
        stretches=[tracks[0][10:20], ("injected turn", tracks[1][5:9])],
        medoids=[("up", tracks[0]), ("down", tracks[1][::-1])],
        title="Kitimat <test>",
    )
    page = path.read_text()
    for name in (
        LAYER_TRACKS,
        LAYER_FLAGGED,
        LAYER_ROLLOUTS,
        LAYER_BEST_ROLLOUTS,
        LAYER_STRETCHES,
        LAYER_MEDOIDS,
        LAYER_COAST,
    ):
        assert name in page
    assert "injected turn" in page and "Kitimat &lt;test&gt;" in page
    assert "L.control.layers" in page


def test_maps_draw_every_flagged_track_and_at_most_the_cap_of_the_others():
    flagged = np.zeros(12_003, dtype=bool)
    flagged[[5, 6_000, 12_002]] = True
    drawn = map_subset(flagged, 1_000)
    assert set(np.flatnonzero(flagged)) <= set(drawn.tolist())
    others = drawn[~flagged[drawn]]
    assert 900 <= len(others) <= 1_000 and np.all(np.diff(drawn) > 0)
    assert others[0] == 0 and others[-1] > 11_000  # evenly over the whole set
    np.testing.assert_array_equal(map_subset(flagged[:500], 1_000), np.arange(500))


def test_a_detection_over_the_cap_says_how_many_tracks_its_maps_draw(cli, kitimat, tmp_path):
    """Kitimat's tracks judged by `nearest` route models, the maps' cap set to 2: map.html holds
    every flagged track and 2 of the others, and its title says so."""
    models = tmp_path / "models"
    trained = cli("train", "--cluster", "routes", "--method", "nearest", "--data", kitimat,
                  "--out", models)  # fmt: skip
    assert trained.exit_code == 0, trained.output
    out = tmp_path / "report"
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(maps, "MAP_UNFLAGGED_TRACKS", 2)
        result = cli(
            "detect", "--data", kitimat, "--models", models, "--method", "nearest",
            "--cluster", "all", "--top-percent", "10", "--out", out,
        )  # fmt: skip
    assert result.exit_code == 0, result.output
    scores = pd.read_parquet(out / "scores.parquet")
    others = int((~scores["flagged"]).sum())
    assert others > 2
    page = (out / "map.html").read_text()
    assert f"2 of {others:,} others drawn" in page
    payload = page.split('id="aisdati-data">', 1)[1].split("</script>", 1)[0]
    layers = json.loads(payload.replace("<\\/", "</"))["layers"]
    assert len(layers["tracks"]["features"]) == 2
    assert len(layers["flagged"]["features"]) == int(scores["flagged"].sum())
    assert (out / "map.png").stat().st_size > 0
