"""Region of interest (`aisdati.preprocess.roi`): the default Florida Straits polygon and
GeoJSON files, across the antimeridian, and polygons with NaN or latitudes off the Earth one line
(issue 13, items 4 and 11)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from aisdati.errors import UserError
from aisdati.preprocess.roi import florida_straits, in_roi, load_roi
from tests.helpers.cli import one_line_error
from tests.helpers.ingest import NY_HOUR, ingest, ingest_ny_hour


def test_default_polygon_covers_the_straits_and_excludes_the_rest():
    roi = load_roi("florida-straits")
    inside = {
        "off Key West": (-81.8, 24.3),
        "off Miami": (-79.9, 25.7),
        "Gulf entrance": (-82.9, 24.0),
    }
    outside = {
        "Florida Bay": (-80.8, 25.0),
        "Tampa": (-82.5, 27.9),
        "Nicholas Channel": (-79.8, 23.4),
        "Havana inland": (-82.36, 22.9),
        "Gulf of Mexico": (-85.0, 25.0),
        "north of Miami": (-80.0, 26.5),
    }
    for name, points in (("in", inside), ("out", outside)):
        lon, lat = np.array(list(points.values())).T
        mask = in_roi(roi, lon, lat)
        assert mask.all() if name == "in" else not mask.any(), points
    assert roi.is_valid and florida_straits().bounds[0] >= -84  # inside UTM zone 17


def test_none_disables_the_filter():
    assert load_roi("none") is None


def test_geojson_polygon_feature_collection(tmp_path):
    square = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]]}
    path = tmp_path / "roi.geojson"
    path.write_text(
        json.dumps(
            {"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": square}]}
        )
    )
    roi = load_roi(str(path))
    assert list(in_roi(roi, np.array([0.5, 2.0]), np.array([0.5, 0.5]))) == [True, False]


@pytest.mark.parametrize(
    "doc, message",
    [
        ({"type": "Point", "coordinates": [0, 0]}, "found Point"),
        ({"type": "LineString", "coordinates": [[0, 0], [1, 1]]}, "found LineString"),
        ({"type": "FeatureCollection", "features": []}, "no polygon"),
        ({"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}, "invalid"),
    ],
)
def test_roi_that_is_not_a_polygon_is_a_user_error(tmp_path, doc, message):
    path = tmp_path / "roi.geojson"
    path.write_text(json.dumps(doc))
    with pytest.raises(UserError, match=message):
        load_roi(str(path))


def test_roi_not_json(tmp_path):
    path = tmp_path / "roi.geojson"
    path.write_text("not json")
    with pytest.raises(UserError, match="not valid GeoJSON"):
        load_roi(str(path))


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every damaged copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


# -------------------------------------------------------------- 4, 11: ROI polygons
def _shifted_ny(data: Path, tmp_path: Path) -> tuple[Path, float]:
    """The NY hour moved in longitude to just west of the antimeridian, inside a region that
    crosses it (tracks that cross it themselves are refused: `test_hostile_inputs`)."""
    table = pd.read_csv(data / NY_HOUR)
    shift = 179.9 - float(table["LON"].max())
    table["LON"] = table["LON"] + shift
    assert table["LON"].between(170, 180).all()
    src = tmp_path / "antimeridian.csv"
    table.to_csv(src, index=False)
    return src, shift


def test_roi_across_the_antimeridian_is_not_its_complement(cli, data, tmp_path, baseline):
    src, _ = _shifted_ny(data, tmp_path)
    roi = tmp_path / "dateline.geojson"
    ring = [[170, 35], [-170, 35], [-170, 45], [170, 45], [170, 35]]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    result, report = ingest(cli, tmp_path / "out", src, extra=("--roi", roi, "--min-points", "20"))
    assert result.exit_code == 0, result.output
    assert report["rejected"]["outside_roi"] == 0  # every report lies within 10 deg of 180
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    assert "antimeridian" in result.stderr and "warning:" in result.stderr
    # the same area written with longitudes beyond 180 reads the same
    beyond = [[x % 360, y] for x, y in ring]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [beyond]}))
    result, again = ingest(cli, tmp_path / "out2", src, extra=("--roi", roi, "--min-points", "20"))
    assert result.exit_code == 0 and again["kept_points"] == baseline["kept_points"]


@pytest.mark.parametrize("bad", ["NaN", "Infinity"])
def test_roi_with_nan_coordinates_is_one_line(cli, data, tmp_path, bad):
    roi = tmp_path / "nan.geojson"
    ring = f"[[-75, 40], [{bad}, 40], [-73, 41], [-75, 40]]"
    roi.write_text('{"type": "Polygon", "coordinates": [' + ring + "]}")
    result, _ = ingest(cli, tmp_path / "out", data / NY_HOUR, extra=("--roi", roi))
    one_line_error(result, "NaN or infinite coordinates")


def test_roi_latitudes_off_the_earth_are_one_line(cli, data, tmp_path):
    roi = tmp_path / "far.geojson"
    ring = [[0, 0], [1, 95], [2, 0], [0, 0]]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    result, _ = ingest(cli, tmp_path / "out", data / NY_HOUR, extra=("--roi", roi))
    one_line_error(result, r"lat in \[-90, 90\]")
