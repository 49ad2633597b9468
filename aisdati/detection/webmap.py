"""The detection map as one self-contained HTML page that works without a network.

Analysts open `map.html` on ships, in operations centres and on secure networks, where a page
that loads its scripts from CDNs and its base map from a tile server is blank. So the page holds
everything it needs: Leaflet 1.9.4 (BSD-2-Clause, vendored in `aisdati/data/leaflet/`) and its
styles inline, its icons as data URIs, the coastline from `aisdati.coastline` (the offline OSM
land polygons) as a land layer, and the tracks as GeoJSON. Nothing is requested from anywhere
unless the user switches the base layer to OpenStreetMap tiles (listed, never on by default).

Layers (each toggled in the layer control): the coastline, the test tracks coloured by score,
the flagged tracks (red, with a popup per track and a marker where each deviates most), the
nearest rollout of each flagged track, and the optional best rollouts, highlighted stretches,
route medoids and model regions.
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Sequence
from functools import cache
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import shape

LAYER_COAST = "coastline (offline)"
LAYER_TRACKS = "test tracks"
LAYER_FLAGGED = "flagged tracks"
LAYER_ROLLOUTS = "nearest rollouts (flagged)"
LAYER_BEST_ROLLOUTS = "best rollouts (all tracks)"
LAYER_STRETCHES = "stretches"
LAYER_EVENTS = "events"
LAYER_MEDOIDS = "route medoids"
LAYER_REGIONS = "model regions"
BASE_OFFLINE = "no tiles (offline)"
BASE_TILES = "OpenStreetMap tiles (online)"

LAND_COLOR = "#e8e4d8"
COAST_COLOR = "#b8b09a"
WATER_COLOR = "#eef4f8"
SCORE_CMAP = "viridis"
"""Colour ramp of the unflagged tracks' scores (low = dark blue, high = yellow)."""

TILE_URL = "https://tile.openstreetmap.org/{z}/{x}/{y}.png"
COAST_ATTRIBUTION = "land: &copy; OpenStreetMap contributors (ODbL)"


@cache
def _asset(name: str) -> bytes:
    """A file of the package's `data/` folder (Leaflet under `leaflet/`, the page script)."""
    return (files("aisdati") / "data").joinpath(*name.split("/")).read_bytes()


def _leaflet_css() -> str:
    """Leaflet's stylesheet with its image references turned into data URIs."""

    def inline(match: re.Match[str]) -> str:
        png = base64.b64encode(_asset("leaflet/" + match.group(1))).decode()
        return f"url(data:image/png;base64,{png})"

    return re.sub(r"url\(images/([\w.-]+\.png)\)", inline, _asset("leaflet/leaflet.css").decode())


def _latlon(xy: np.ndarray) -> list[list[float]]:
    """[n, 2] lon/lat -> GeoJSON coordinates ([lon, lat], rounded to ~1 m)."""
    return np.round(np.asarray(xy, dtype=float), 5).tolist()


def _json_safe(props: dict[str, Any]) -> dict[str, Any]:
    """Properties as JSON can carry them: NaN and infinities become null, numpy scalars plain."""
    out = {}
    for key, value in props.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, float) and not np.isfinite(value):
            value = None
        out[key] = value
    return out


def _line(xy: np.ndarray, **props: Any) -> dict[str, Any]:
    return {
        "type": "Feature",
        "geometry": {"type": "LineString", "coordinates": _latlon(xy)},
        "properties": _json_safe(props),
    }


def _collection(features: list[dict[str, Any]]) -> dict[str, Any]:
    return {"type": "FeatureCollection", "features": features}


def _labelled(items: Sequence, prefix: str) -> list[tuple[str, np.ndarray]]:
    """[(label, [n, 2])] from items that are either arrays or (label, array) pairs."""
    out = []
    for i, item in enumerate(items):
        if isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str):
            out.append((item[0], np.asarray(item[1], dtype=float)))
        else:
            out.append((f"{prefix} {i}", np.asarray(item, dtype=float)))
    return out


def score_scale(scores: np.ndarray) -> tuple[float, float]:
    """The score range the colours span: the 5th to 95th percentile (so one extreme score does
    not wash the others out)."""
    s = np.asarray(scores, dtype=float)
    finite = s[np.isfinite(s)]
    if not len(finite):
        return 0.0, 1.0
    lo, hi = np.percentile(finite, [5, 95])
    return float(lo), float(hi)


def score_colours(scores: np.ndarray, scale: tuple[float, float]) -> list[str]:
    """Hex colours of scores on `SCORE_CMAP` over `scale` (grey where a score is missing)."""
    from matplotlib import colormaps
    from matplotlib.colors import to_hex

    lo, hi = scale
    t = np.clip((np.asarray(scores, dtype=float) - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)
    cmap = colormaps[SCORE_CMAP]
    return [to_hex(cmap(x)) if np.isfinite(x) else "#888888" for x in t]


def legend(scale: tuple[float, float]) -> dict[str, Any]:
    """The colour bar of the unflagged tracks: five stops and the scores at its ends."""
    from matplotlib import colormaps
    from matplotlib.colors import to_hex

    cmap = colormaps[SCORE_CMAP]
    return {"stops": [to_hex(cmap(x)) for x in np.linspace(0, 1, 5)], "range": list(scale)}


def land_geojson(lo: np.ndarray, hi: np.ndarray) -> dict[str, Any]:
    """The offline land polygons of the box [lo, hi] (lon/lat), simplified to about a pixel of
    a full-page map, as a GeoJSON geometry."""
    from shapely.geometry import mapping

    from aisdati.coastline import land

    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-3))
    bbox = (
        max(float(lo[0]) - span, -180.0),
        max(float(lo[1]) - span, -90.0),
        min(float(hi[0]) + span, 180.0),
        min(float(hi[1]) + span, 90.0),
    )
    geom = land(bbox, tolerance=span / 2000)
    doc = mapping(geom)
    return json.loads(json.dumps(doc, default=lambda v: list(v)))


def _extent(groups: Sequence[Sequence[np.ndarray]]) -> tuple[np.ndarray, np.ndarray] | None:
    pts = [np.asarray(xy, float).reshape(-1, 2) for group in groups for xy in group]
    pts = [p[np.isfinite(p).all(axis=1)] for p in pts]
    pts = [p for p in pts if len(p)]
    if not pts:
        return None
    allpts = np.concatenate(pts)
    return allpts.min(axis=0), allpts.max(axis=0)


def _scores(props: Sequence[dict]) -> np.ndarray:
    return np.array([p.get("score", np.nan) for p in props], dtype=float)


def _track_layers(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray | None],
    props: Sequence[dict],
    flagged: np.ndarray,
) -> dict[str, Any]:
    """The tracks (coloured by score), flagged tracks, their rollouts and deviation points."""
    colours = score_colours(_scores(props), score_scale(_scores(props)))
    normal, red, blue, marks = [], [], [], []
    for xy, roll, p, f, colour in zip(tracks, rollouts, props, flagged, colours, strict=True):
        if not len(xy):
            continue
        if not f:
            normal.append(_line(xy, colour=colour, **p))
            continue
        red.append(_line(xy, colour="#d62728", **p))
        if roll is not None and len(roll):
            blue.append(_line(roll, track_id=p.get("track_id")))
        if {"max_dev_lat", "max_dev_lon"} <= p.keys() and np.isfinite(
            [p["max_dev_lat"], p["max_dev_lon"]]
        ).all():
            point = {"type": "Point", "coordinates": [p["max_dev_lon"], p["max_dev_lat"]]}
            marks.append({"type": "Feature", "geometry": point, "properties": _json_safe(p)})
    return {
        "tracks": _collection(normal),
        "flagged": _collection(red),
        "rollouts": _collection(blue),
        "deviations": _collection(marks),
    }


def map_data(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray | None],
    props: Sequence[dict],
    flagged: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    best_rollouts: Sequence[np.ndarray | None] | None = None,
    stretches: Sequence[np.ndarray | tuple[str, np.ndarray]] | None = None,
    medoids: Sequence[tuple[str, np.ndarray]] | None = None,
    events: dict[str, Any] | None = None,
    title: str = "",
) -> dict[str, Any]:
    """Everything the page draws, as plain JSON (the page's script only styles it); `events`:
    the events' GeoJSON (`aisdati.events.table.events_geojson`), a popup each."""
    flagged = np.asarray(flagged, dtype=bool)
    stretch_lines = _labelled(stretches or [], "stretch")
    medoid_lines = _labelled(medoids or [], "route")
    corners = [np.stack([lo, hi]) for lo, hi in regions]
    places = [shapely.get_coordinates(shape(f["geometry"])) for f in _features(events)]
    lines = [xy for _, xy in (*stretch_lines, *medoid_lines)]
    extent = _extent([tracks, lines + places, corners])
    optional = _optional_layers(
        best_rollouts,
        None if stretches is None else stretch_lines,
        None if medoids is None else medoid_lines,
    )
    optional["events"] = events
    return {
        "title": title,
        "layers": _track_layers(tracks, rollouts, props, flagged),
        "optional": optional,
        "regions": [_latlon_box(lo, hi) for lo, hi in regions],
        **_framing(extent),
        "names": _layer_names(optional),  # only the layers the page has
        "legend": legend(score_scale(_scores(props))),
        "style": {"land": LAND_COLOR, "coast": COAST_COLOR, "water": WATER_COLOR},
        "tile_url": TILE_URL,
        "coast_attribution": COAST_ATTRIBUTION,
    }


def _features(collection: dict[str, Any] | None) -> list[dict[str, Any]]:
    return collection["features"] if collection else []


def _optional_layers(
    best_rollouts: Sequence[np.ndarray | None] | None,
    stretch_lines: list[tuple[str, np.ndarray]] | None,
    medoid_lines: list[tuple[str, np.ndarray]] | None,
) -> dict[str, dict[str, Any] | None]:
    """The layers a map may have: the best rollouts, the stretches and the route medoids, each
    a collection of its non-empty lines, or None where the caller gave none."""
    best = None
    if best_rollouts is not None:
        best = _collection(
            [
                _line(r, label=f"rollout {i}")
                for i, r in enumerate(best_rollouts)
                if r is not None and len(r)
            ]
        )
    return {
        "best": best,
        "stretches": _labelled_lines(stretch_lines),
        "medoids": _labelled_lines(medoid_lines),
    }


def _labelled_lines(lines: list[tuple[str, np.ndarray]] | None) -> dict[str, Any] | None:
    """A collection of the non-empty (label, line) pairs, each line with its label; None for
    None."""
    if lines is None:
        return None
    return _collection([_line(xy, label=label) for label, xy in lines if len(xy)])


def _latlon_box(lo: np.ndarray, hi: np.ndarray) -> list[list[float]]:
    """A lon/lat box [lo, hi] as Leaflet's bounds: [[south, west], [north, east]]."""
    return [[float(lo[1]), float(lo[0])], [float(hi[1]), float(hi[0])]]


def _framing(extent: tuple[np.ndarray, np.ndarray] | None) -> dict[str, Any]:
    """The page's `bounds` (what it shows first) and `land` (the coastline layer) for the box
    of everything drawn; both None where nothing is."""
    if extent is None:
        return {"bounds": None, "land": None}
    lo, hi = extent
    return {"bounds": _latlon_box(lo, hi), "land": land_geojson(lo, hi)}


def _layer_names(optional: dict[str, dict[str, Any] | None]) -> dict[str, str]:
    """The layer control's names of the layers every page has and of the `optional` ones it
    has (not None)."""
    names = {
        "coast": LAYER_COAST,
        "tracks": LAYER_TRACKS,
        "flagged": LAYER_FLAGGED,
        "rollouts": LAYER_ROLLOUTS,
        "regions": LAYER_REGIONS,
        "offline": BASE_OFFLINE,
        "tiles": BASE_TILES,
    }
    extra = {
        "best": LAYER_BEST_ROLLOUTS,
        "stretches": LAYER_STRETCHES,
        "medoids": LAYER_MEDOIDS,
        "events": LAYER_EVENTS,
    }
    names.update({k: v for k, v in extra.items() if optional.get(k) is not None})
    return names


PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>{leaflet_css}</style>
<style>
html, body, #map {{ height: 100%; margin: 0; }}
.aisdati-title {{ position: absolute; top: 8px; left: 54px; z-index: 1000; background: white;
  padding: 2px 8px; font: 14px sans-serif; opacity: 0.9; border-radius: 3px; }}
.aisdati-legend {{ background: white; padding: 4px 8px; font: 12px sans-serif; width: 190px;
  border-radius: 3px; opacity: 0.9; }}
.aisdati-bar {{ height: 10px; margin: 2px 0; }}
.aisdati-swatch {{ display: inline-block; width: 18px; height: 4px; vertical-align: middle; }}
.aisdati-line {{ display: inline-block; width: 18px; height: 0; vertical-align: middle; }}
.aisdati-dot {{ display: inline-block; width: 8px; height: 8px; border: 2px solid black;
  border-radius: 50%; margin: 0 4px; vertical-align: middle; }}
.aisdati-gap {{ background: white; border: 1px solid #3182bd; color: #3182bd; font: 11px sans-serif;
  padding: 0 3px; box-shadow: none; }}
.leaflet-popup-content td {{ padding: 0 6px 0 0; font: 12px sans-serif; }}
</style>
</head><body>
<div id="map"></div>
<div class="aisdati-title">{title}</div>
<script>{leaflet_js}</script>
<script type="application/json" id="aisdati-data">{data}</script>
<script>{script}</script>
</body></html>
"""


def render_page(data: dict[str, Any]) -> str:
    """The HTML page of `map_data`'s result; `</` in the data is escaped so no string in it can
    close the script element."""
    payload = json.dumps(data, allow_nan=False, default=float).replace("</", "<\\/")
    return PAGE.format(
        title=html.escape(data.get("title") or "aisdati detection map"),
        leaflet_css=_leaflet_css(),
        leaflet_js=_asset("leaflet/leaflet.js").decode(),
        data=payload,
        script=_asset("webmap.js").decode(),
    )


def html_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray | None],
    props: Sequence[dict],
    flagged: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    path: Path,
    **optional: Any,
) -> None:
    """Write the self-contained detection page to `path` (atomically, under outdir's one
    temporary-name scheme, so a reader never sees half a page). `optional`: best_rollouts,
    stretches, medoids, title (see `map_data`)."""
    from aisdati.outdir import atomic_write_bytes

    page = render_page(map_data(tracks, rollouts, props, flagged, regions, **optional))
    atomic_write_bytes(path, page.encode("utf-8"))
