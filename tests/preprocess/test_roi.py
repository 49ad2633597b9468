"""Region of interest: the default Florida Straits polygon and GeoJSON files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aisdati.errors import UserError
from aisdati.preprocess.roi import florida_straits, in_roi, load_roi


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
