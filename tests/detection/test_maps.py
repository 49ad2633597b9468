"""The maps of `aisdati detect` (`aisdati.detection.maps`, `aisdati.detection.webmap`) drawn
over the offline coastline."""

from __future__ import annotations

import io
import json

import matplotlib.image as mpimg
import numpy as np
import pandas as pd
import pytest

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

KITIMAT_BOX = (-129.5, 53.2, -128.6, 53.7)


def _rgb(hex_color: str) -> np.ndarray:
    return np.array([int(hex_color[i : i + 2], 16) for i in (1, 3, 5)]) / 255


def _share(img: np.ndarray, hex_color: str) -> float:
    """Fraction of the image's pixels within 2/255 of a colour."""
    return float((np.abs(img[..., :3] - _rgb(hex_color)).max(axis=-1) < 2.5 / 255).mean())


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


def test_evidence_marks_the_strongest_alert_from_when_to_when():
    """Issue 69, item 4: the figure says when: the strongest alert's stretch, its times, the
    evidence over the time of day."""
    track = _channel_tracks()[0]
    hours = np.arange(len(track)) / 6
    start = pd.Timestamp("2018-08-19 05:00", tz="UTC")
    events = pd.DataFrame(
        {
            "class": ["alert", "alert", "activity"],
            "track_id": [7, 7, 7],
            "kind": ["drift", "position-jump", "gap"],
            "start": pd.to_datetime(
                ["2018-08-19 05:30", "2018-08-19 06:20", "2018-08-19 07:00"], utc=True
            ),
            "end": pd.to_datetime(
                ["2018-08-19 05:40", "2018-08-19 08:07", "2018-08-19 09:00"], utc=True
            ),
            "strength": [1.2, 3.1, 9.0],
        }
    )
    alert = maps.strongest_alert(events, 7)
    assert alert is not None and alert.kind == "position-jump"
    assert alert.when == "2018-08-19 06:20 to 08:07 UTC"
    assert maps.strongest_alert(events, 8) is None
    times = (start + pd.to_timedelta(hours, unit="h")).round("s")
    assert maps.alert_points(times, alert) == (8, 19)  # 06:20 .. 08:00, every 10 min
    profile = np.linspace(0, 0.03, len(track)) * 66_000
    png = plot_track_evidence(
        track, None, profile, (25, 35), "t", hours=hours, start=start, alert=alert
    )
    assert png.startswith(b"\x89PNG")


def test_a_gap_is_a_link_labelled_with_its_duration():
    events = pd.DataFrame(
        {
            "kind": ["gap", "loitering", "gap"],
            "lons": [[-129.0, -128.5], [-129.0], [-129.2, -129.1]],
            "lats": [[53.0, 53.2], [53.0], [53.1, 53.3]],
            "duration_s": [6660.0, 100.0, 70_800.0],
        }
    )
    links = maps.gap_links(events)
    assert [label for _, label in links] == ["19.7 h", "111 min"]  # longest first
    assert links[1][0].tolist() == [[-129.0, 53.0], [-128.5, 53.2]]


def test_a_meeting_is_each_vessels_stretch_named_not_one_point():
    events = pd.DataFrame(
        {
            "kind": ["encounter", "loitering", "gnss-interference"],
            "class": ["activity", "activity", "alert"],
            "mmsi": [316001000, 316002000, 316003000],
            "others": ['[{"mmsi": 316004000, "name": null, "ship_type": null}]', None, None],
            "lons": [[-129.2, -129.19, np.nan, -129.201, -129.191], [-129.0], [-129.3, -129.2,
                     -129.25, -129.3]],
            "lats": [[53.5, 53.51, np.nan, 53.5, 53.511], [53.0], [53.4, 53.4, 53.45, 53.4]],
            "lon": [-129.195, -129.0, -129.25],
            "lat": [53.505, 53.0, 53.42],
        }
    )  # fmt: skip
    [(parts, label)] = maps.meetings(events)  # the area is an outline, not a meeting
    assert [p.tolist() for p in parts] == [[[-129.2, 53.5], [-129.19, 53.51]],
                                           [[-129.201, 53.5], [-129.191, 53.511]]]  # fmt: skip
    assert label == "encounter 316001000 / 316004000"
    assert maps.places(events, "activity").tolist() == [[-129.0, 53.0]]  # not the meeting's point
    assert len(maps.area_outlines(events)) == 1
    tracks = _channel_tracks()
    png = plot_detection_map(tracks, tracks, np.array([False, False]), np.zeros((2, 2)), [],
                             met=maps.meetings(events))  # fmt: skip
    img = mpimg.imread(io.BytesIO(png), format="png")
    assert _share(img, "#9467bd") > 0  # tab:purple: the two stretches
