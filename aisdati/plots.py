"""Every figure of aisdati, drawn with matplotlib's Agg backend (no display needed)."""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from aisdati.selftest.families import Family


def _save(fig: plt.Figure, path: Path) -> None:
    """Save through a temporary name so that a figure on disk is always complete."""
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)
    tmp.replace(path)


def _grid(n: int) -> tuple[plt.Figure, np.ndarray]:
    cols = min(n, 2)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def plot_families(families: Sequence[Family], path: Path, members: int = 9) -> None:
    """Each family with its boundary members highlighted (the paper's Fig. 1)."""
    fig, axes = _grid(len(families))
    for ax, fam in zip(axes, families, strict=False):
        for alpha in np.linspace(*fam.alpha_range, members):
            ref = fam.reference(alpha)
            ax.plot(ref[:, 0], ref[:, 1], color="0.75", lw=0.8)
        for alpha, color in zip(fam.boundary_alphas(), ("tab:blue", "tab:green"), strict=True):
            ref = fam.reference(alpha)
            ax.plot(ref[:, 0], ref[:, 1], color=color, lw=2, label=f"α = {alpha:.3g}")
            ax.plot(*ref[0], "o", color=color)
        ax.set_title(f"{fam.name}  (DTW diameter {fam.diameter:.3g})")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")
    fig.suptitle("Synthetic families: boundary members define the DTW diameter")
    _save(fig, path)


def plot_best_rollouts(
    panels: Sequence[tuple[str, np.ndarray, dict[str, np.ndarray], dict[str, float]]], path: Path
) -> None:
    """Per family, the reference and each method's best rollout from its first point (Fig. 2).

    A panel is (title, reference [n, 2], {method: rollout [n, 2]}, {method: score})."""
    fig, axes = _grid(len(panels))
    for ax, (title, ref, rollouts, scores) in zip(axes, panels, strict=False):
        ax.plot(ref[:, 0], ref[:, 1], color="black", lw=2.2, label="reference")
        ax.plot(*ref[0], "ko")
        for method, path_xy in rollouts.items():
            ax.plot(path_xy[:, 0], path_xy[:, 1], lw=1.4, label=f"{method} ({scores[method]:.3f})")
        ax.set_title(title)
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")
    fig.suptitle("Best rollout per family (normalised smoothed DTW in brackets)")
    _save(fig, path)



def _lonlat_aspect(ax: plt.Axes, points: np.ndarray) -> None:
    """True shapes on a lon/lat plot: stretch longitude by 1/cos(mean latitude)."""
    ax.set_aspect(1.0 / np.cos(np.radians(float(np.mean(points[:, 1])))), adjustable="datalim")


def plot_roc_pr(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path) -> None:
    """ROC and precision-recall curves, one line per detector and score (labels 1 = injected)."""
    from sklearn.metrics import precision_recall_curve, roc_curve

    fig, (roc, pr) = plt.subplots(1, 2, figsize=(11, 4.6))
    for name, (y, score) in curves.items():
        if y.min() == y.max():
            continue
        fpr, tpr, _ = roc_curve(y, score)
        prec, rec, _ = precision_recall_curve(y, score)
        roc.plot(fpr, tpr, lw=1.5, label=name)
        pr.plot(rec, prec, lw=1.5, label=name)
    roc.plot([0, 1], [0, 1], color="0.6", ls=":", lw=1)
    roc.set(xlabel="false positive rate", ylabel="true positive rate", title="ROC")
    pr.set(xlabel="recall", ylabel="precision", title="precision-recall", ylim=(0, 1.02))
    roc.legend(fontsize=8, loc="lower right")
    fig.suptitle("Detection of injected anomalies (held-out tracks)")
    _save(fig, path)


def plot_injected_examples(
    panels: Sequence[tuple[str, np.ndarray, np.ndarray, tuple[int, int], np.ndarray | None]],
    path: Path,
) -> None:
    """Per anomaly kind, the top-scored altered track: (title, source track, altered track,
    altered stretch [start, end), what the detector compared it with or None)."""
    fig, axes = _grid(len(panels))
    for ax, (title, source, track, (i, j), evidence) in zip(axes, panels, strict=False):
        ax.plot(source[:, 0], source[:, 1], color="0.7", lw=2.5, label="original track")
        if evidence is not None:
            ax.plot(evidence[:, 0], evidence[:, 1], color="tab:blue", lw=1, label="compared with")
        ax.plot(track[:, 0], track[:, 1], color="black", lw=1, label="altered track")
        ax.plot(track[i:j, 0], track[i:j, 1], color="tab:red", lw=2, label="altered stretch")
        ax.plot(*track[0], "o", color="black", ms=4)
        _lonlat_aspect(ax, track)
        ax.set_title(title, fontsize=9)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle("Top-scored injected anomaly of each kind")
    _save(fig, path)


LAND_COLOR = "#e8e4d8"
COAST_COLOR = "#b8b09a"
WATER_COLOR = "#eef4f8"


def _draw_land(ax: plt.Axes) -> None:
    """Fill the land inside the axes' current limits (coastline.land, cut to the view with a
    margin and simplified to about a pixel), under everything else, and credit the source."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as MplPath
    from shapely.geometry.polygon import orient

    from aisdati import coastline

    (x0, x1), (y0, y1) = sorted(ax.get_xlim()), sorted(ax.get_ylim())
    mx, my = (x1 - x0) * 0.05, (y1 - y0) * 0.05
    bbox = (x0 - mx, y0 - my, x1 + mx, y1 + my)
    geom = coastline.land(bbox, tolerance=min(x1 - x0, y1 - y0) / 1500)
    verts, codes = [], []
    for poly in geom.geoms:
        if poly.interiors:  # holes wind the other way, so that the nonzero rule leaves them open
            poly = orient(poly, 1.0)
        for ring in (poly.exterior, *poly.interiors):
            xy = np.asarray(ring.coords)
            verts.append(xy)
            codes += [MplPath.MOVETO] + [MplPath.LINETO] * (len(xy) - 2) + [MplPath.CLOSEPOLY]
    ax.set_facecolor(WATER_COLOR)
    if verts:
        path = MplPath(np.concatenate(verts), codes)
        ax.add_patch(PathPatch(path, fc=LAND_COLOR, ec=COAST_COLOR, lw=0.5, zorder=0))
    ax.text(
        0.995,
        0.005,
        coastline.source().attribution,
        transform=ax.transAxes,
        ha="right",
        va="bottom",
        fontsize=6,
        color="0.3",
        zorder=10,
        bbox={"fc": "white", "alpha": 0.6, "lw": 0, "pad": 1},
    )


def _set_map_limits(ax: plt.Axes, lo: np.ndarray, hi: np.ndarray) -> None:
    """Lon/lat limits, the longitude axis stretched by 1/cos(latitude) so shapes are true."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect(1.0 / np.cos(np.radians((lo[1] + hi[1]) / 2)))
    ax.ticklabel_format(useOffset=False)
    ax.xaxis.set_major_locator(plt.MaxNLocator(5))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")


def plot_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray],
    flagged: np.ndarray,
    max_dev: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    path: Path,
    title: str = "",
    evidence_label: str = "nearest rollout",
) -> None:
    """Test tracks grey, flagged tracks red with their nearest rollout blue and a cross where they
    deviate most, the models' regions dashed, over the offline coastline (aisdati.coastline, cut
    to the map's box at any scale; lon/lat, the longitude axis stretched by 1/cos(latitude) so
    that shapes are true)."""
    fig, ax = plt.subplots(figsize=(9, 7.5))
    for xy, f in zip(tracks, flagged, strict=True):
        if not f:
            ax.plot(xy[:, 0], xy[:, 1], color="0.55", lw=0.6, alpha=0.7, zorder=1)
    for xy, roll, f in zip(tracks, rollouts, flagged, strict=True):
        if f:
            ax.plot(roll[:, 0], roll[:, 1], color="tab:blue", lw=1.0, zorder=2)
            ax.plot(xy[:, 0], xy[:, 1], color="tab:red", lw=1.4, zorder=3)
            ax.plot(*xy[0], "o", color="tab:red", ms=3, zorder=3)
    if flagged.any():
        ax.plot(max_dev[flagged, 0], max_dev[flagged, 1], "kx", ms=7, mew=1.6, zorder=4)
    for lo, hi in regions:
        ax.plot(
            [lo[0], hi[0], hi[0], lo[0], lo[0]],
            [lo[1], lo[1], hi[1], hi[1], lo[1]],
            "k--",
            lw=0.8,
            zorder=1,
        )
    allpts = np.concatenate([*tracks, *[np.stack([lo, hi]) for lo, hi in regions]])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = np.maximum((hi - lo) * 0.04, 0.01)
    _set_map_limits(ax, lo - pad, hi + pad)
    _draw_land(ax)
    handles = [
        plt.Line2D([], [], color="0.55", lw=1, label="test track"),
        plt.Line2D([], [], color="tab:red", lw=1.4, label="flagged track"),
        plt.Line2D([], [], color="tab:blue", lw=1, label=evidence_label),
        plt.Line2D([], [], color="k", marker="x", ls="", label="largest deviation"),
        plt.Line2D([], [], color="k", ls="--", lw=0.8, label="model region"),
    ]
    ax.legend(handles=handles, fontsize=8, loc="best")
    ax.set_title(title or "DATI anomalies")
    _save(fig, path)


LAYER_TRACKS = "test tracks"
LAYER_FLAGGED = "flagged tracks"
LAYER_ROLLOUTS = "nearest rollouts (flagged)"
LAYER_BEST_ROLLOUTS = "best rollouts (all tracks)"
LAYER_STRETCHES = "stretches"
LAYER_MEDOIDS = "route medoids"
LAYER_REGIONS = "model regions"
"""Names of the layers of `html_detection_map`, as its layer control lists them."""


def _latlon(xy: np.ndarray) -> list[list[float]]:
    return np.round(np.asarray(xy, dtype=float)[:, ::-1], 5).tolist()


def _labelled(items: Sequence, prefix: str) -> list[tuple[str, np.ndarray]]:
    """[(label, [n, 2])] from items that are either arrays or (label, array) pairs."""
    out = []
    for i, item in enumerate(items):
        if isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str):
            out.append((item[0], np.asarray(item[1], dtype=float)))
        else:
            out.append((f"{prefix} {i}", np.asarray(item, dtype=float)))
    return out


def html_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray],
    props: Sequence[dict],
    flagged: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    path: Path,
    *,
    best_rollouts: Sequence[np.ndarray | None] | None = None,
    stretches: Sequence[np.ndarray | tuple[str, np.ndarray]] | None = None,
    medoids: Sequence[tuple[str, np.ndarray]] | None = None,
    title: str = "",
) -> None:
    """The detection map as a zoomable folium (Leaflet) page over OpenStreetMap tiles (fetched
    by the browser when online), one layer per kind of line, each toggled in a layer control:

    - `LAYER_TRACKS`: the test tracks that are not flagged, grey, with their scores on hover;
    - `LAYER_FLAGGED`: the flagged tracks, red, with a popup of their scores (`props`) and a
      marker where each deviates most (when props has max_dev_lat / max_dev_lon);
    - `LAYER_ROLLOUTS`: the nearest rollout (`rollouts`, one per track) of each flagged track;
    - `LAYER_BEST_ROLLOUTS` (optional, hidden at first): `best_rollouts`, one [m, 2] lon/lat
      line or None per track, for every track (light blue);
    - `LAYER_STRETCHES` (optional): `stretches`, highlighted pieces of tracks (e.g. injected or
      most-deviating segments), each a [k, 2] lon/lat array or a (label, array) pair (orange);
    - `LAYER_MEDOIDS` (optional): `medoids`, (route name, [n, 2] lon/lat) lines (purple, dashed);
    - `LAYER_REGIONS`: the models' regions (lo, hi corners), dashed rectangles.
    """
    import folium
    from branca.element import Element

    flagged = np.asarray(flagged, dtype=bool)
    stretch_lines = _labelled(stretches or [], "stretch")
    medoid_lines = _labelled(medoids or [], "route")
    extent = [np.asarray(xy, dtype=float) for xy in tracks]
    extent += [xy for _, xy in (*stretch_lines, *medoid_lines)]
    extent += [np.stack([lo, hi]) for lo, hi in regions]
    extent = [xy for xy in extent if len(xy)]
    fmap = folium.Map(tiles="OpenStreetMap", control_scale=True)
    if extent:
        allpts = np.concatenate(extent)
        lo, hi = np.nanmin(allpts, axis=0), np.nanmax(allpts, axis=0)
        fmap.fit_bounds([[lo[1], lo[0]], [hi[1], hi[0]]])
    if title:
        fmap.get_root().html.add_child(
            Element(
                '<div style="position:fixed;top:8px;left:60px;z-index:1000;background:white;'
                f'padding:2px 8px;font:14px sans-serif;opacity:0.85">{html.escape(title)}</div>'
            )
        )
    normal = folium.FeatureGroup(LAYER_TRACKS, show=True)
    red = folium.FeatureGroup(LAYER_FLAGGED, show=True)
    blue = folium.FeatureGroup(LAYER_ROLLOUTS, show=True)
    for xy, roll, p, f in zip(tracks, rollouts, props, flagged, strict=True):
        text = "<br>".join(f"{html.escape(str(k))}: {html.escape(str(v))}" for k, v in p.items())
        if not f:
            folium.PolyLine(
                _latlon(xy), color="#888888", weight=1.5, opacity=0.6, tooltip=text
            ).add_to(normal)
            continue
        folium.PolyLine(_latlon(xy), color="#d62728", weight=3, tooltip=text, popup=text).add_to(
            red
        )
        if roll is not None and len(roll):
            folium.PolyLine(_latlon(roll), color="#1f77b4", weight=2).add_to(blue)
        if {"max_dev_lat", "max_dev_lon"} <= p.keys():
            dev = p.get("max_dev_m")
            folium.CircleMarker(
                [p["max_dev_lat"], p["max_dev_lon"]],
                radius=6,
                color="black",
                fill=True,
                tooltip=f"track {p.get('track_id', '?')}: largest deviation"
                + (f" {dev:,.0f} m" if isinstance(dev, int | float) else ""),
            ).add_to(red)
    groups = [normal, blue, red]
    if best_rollouts is not None:
        best = folium.FeatureGroup(LAYER_BEST_ROLLOUTS, show=False)
        for i, roll in enumerate(best_rollouts):
            if roll is not None and len(roll):
                folium.PolyLine(
                    _latlon(roll), color="#6baed6", weight=1.5, opacity=0.7, tooltip=f"rollout {i}"
                ).add_to(best)
        groups.insert(1, best)
    if stretches is not None:
        orange = folium.FeatureGroup(LAYER_STRETCHES, show=True)
        for label, xy in stretch_lines:
            if len(xy):
                folium.PolyLine(
                    _latlon(xy), color="#ff7f0e", weight=6, opacity=0.8, tooltip=label
                ).add_to(orange)
        groups.append(orange)
    if medoids is not None:
        purple = folium.FeatureGroup(LAYER_MEDOIDS, show=True)
        for name, xy in medoid_lines:
            if len(xy):
                folium.PolyLine(
                    _latlon(xy), color="#7b3294", weight=3, dash_array="8 6", tooltip=name
                ).add_to(purple)
                folium.CircleMarker(
                    _latlon(xy[:1])[0], radius=4, color="#7b3294", fill=True, tooltip=name
                ).add_to(purple)
        groups.insert(0, purple)
    boxes = folium.FeatureGroup(LAYER_REGIONS, show=True)
    for lo_r, hi_r in regions:
        folium.Rectangle(
            [[lo_r[1], lo_r[0]], [hi_r[1], hi_r[0]]], color="black", weight=1, dash_array="5"
        ).add_to(boxes)
    for group in (boxes, *groups):
        group.add_to(fmap)
    folium.LayerControl(collapsed=False).add_to(fmap)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fmap.save(str(tmp))
    tmp.replace(path)


def _widen(lo: np.ndarray, hi: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Grow a lon/lat box about its centre to a width / height ratio (in true distance)."""
    coslat = np.cos(np.radians((lo[1] + hi[1]) / 2))
    w, h = (hi[0] - lo[0]) * coslat, hi[1] - lo[1]
    w, h = max(w, h * ratio), max(h, w / ratio)
    mid = (lo + hi) / 2
    half = np.array([w / coslat, h]) / 2
    return mid - half, mid + half


def plot_track_evidence(
    track: np.ndarray,
    rollout: np.ndarray | None,
    profile: np.ndarray,
    stretch: tuple[int, int] | None,
    title: str,
    path: Path,
    *,
    hours: np.ndarray | None = None,
    profile_label: str = "deviation from the rollout (m)",
    pad_frac: float = 0.15,
    pad_deg: float = 0.01,
    context: Sequence[np.ndarray] = (),
    evidence_label: str = "rollout",
) -> None:
    """Why one track stands out, in two panels.

    Left, a map: the coastline (at the map's scale), other tracks for context (`context`, light
    grey), the track (black, a green dot at its start), its rollout (blue dashed, when given),
    the stretch `track[i0:i1]` in red and a cross at the point of largest `profile`. The box is
    the track's and rollout's, padded by `pad_frac` of its span and at least `pad_deg` degrees.
    Right: `profile` ([n] metres, one value per track point: e.g. distance to the matched
    rollout point, a teacher-forced step error) against the point index, or against `hours`
    ([n] hours since the start) when given, with the stretch shaded.

    `stretch` is a Python slice (i0, i1): points i0..i1-1. Saved through a temporary name."""
    track = np.asarray(track, dtype=float)
    profile = np.asarray(profile, dtype=float)
    n = len(track)
    if track.ndim != 2 or track.shape[1] != 2 or n == 0:
        raise ValueError(f"track must be [n, 2] lon/lat, got shape {track.shape}")
    if profile.shape != (n,):
        raise ValueError(f"profile must have one value per track point ({n}), got {profile.shape}")
    x = np.arange(n) if hours is None else np.asarray(hours, dtype=float)
    if x.shape != (n,):
        raise ValueError(f"hours must have one value per track point ({n}), got {x.shape}")
    if stretch is not None:
        i0, i1 = max(0, int(stretch[0])), min(n, int(stretch[1]))
        stretch = (i0, i1) if i1 > i0 else None
    peak = int(np.nanargmax(profile)) if np.isfinite(profile).any() else None

    fig, (ax, axp) = plt.subplots(1, 2, figsize=(13, 5.6), gridspec_kw={"width_ratios": [1.15, 1]})
    pts = [track] + ([np.asarray(rollout, dtype=float)] if rollout is not None else [])
    allpts = np.concatenate(pts)
    allpts = allpts[np.isfinite(allpts).all(axis=1)]
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = np.maximum((hi - lo) * pad_frac, pad_deg)
    lo, hi = _widen(lo - pad, hi + pad, ratio=1.25)
    for xy in context:
        ax.plot(xy[:, 0], xy[:, 1], color="0.7", lw=0.6, alpha=0.8, zorder=1)
    if rollout is not None:
        ax.plot(
            rollout[:, 0], rollout[:, 1], "--", color="tab:blue", lw=1.3, zorder=2,
            label=evidence_label,
        )
    ax.plot(track[:, 0], track[:, 1], color="black", lw=1.4, zorder=3, label="track")
    ax.plot(*track[0], "o", color="tab:green", ms=7, mec="black", zorder=5, label="start")
    if stretch is not None:
        seg = track[stretch[0] : max(stretch[1], stretch[0] + 2)]
        ax.plot(seg[:, 0], seg[:, 1], color="tab:red", lw=3, zorder=4, label="stretch")
    if peak is not None:
        ax.plot(
            *track[peak],
            "x",
            color="tab:red",
            ms=10,
            mew=2.2,
            zorder=6,
            label=f"max {profile[peak]:,.0f} m",
        )
    _set_map_limits(ax, lo, hi)
    _draw_land(ax)
    ax.legend(fontsize=8, loc="best")

    axp.plot(x, profile, color="black", lw=1.2)
    if stretch is not None:
        axp.axvspan(
            x[stretch[0]],
            x[stretch[1] - 1],
            color="tab:red",
            alpha=0.18,
            label=f"stretch [{stretch[0]}, {stretch[1]})",
        )
    if peak is not None:
        axp.plot(x[peak], profile[peak], "x", color="tab:red", ms=10, mew=2.2)
    axp.set_xlabel("point index" if hours is None else "hours since the start")
    axp.set_ylabel(profile_label)
    span = float(x[-1] - x[0]) or 1.0
    axp.set_xlim(x[0] - 0.015 * span, x[-1] + 0.015 * span)
    axp.set_ylim(bottom=min(0.0, float(np.nanmin(profile))) if peak is not None else 0.0)
    axp.grid(alpha=0.3)
    if stretch is not None:
        axp.legend(fontsize=8, loc="best")
    fig.suptitle(title)
    _save(fig, path)


ROUTE_LEGEND_MAX = 15
"""Routes drawn in their own colour with their medoid in routes.png (the largest); the tracks of
the others are drawn in one colour, as "other routes"."""
OTHER_ROUTES_COLOUR = "#7f9fbf"

ROUTE_OFFSET = 0.004
"""routes.png draws each medoid this fraction of the map's span to the right of its direction of
travel, so that the two directions of a lane show side by side."""


def _route_colours(n: int) -> list:
    cmaps = [plt.get_cmap(name) for name in ("tab10", "Dark2", "Set1")]
    palette = [c for cmap in cmaps for c in cmap.colors]
    return [palette[i % len(palette)] for i in range(n)]


def _keep_right(xy: np.ndarray, shift: float, coslat: float) -> np.ndarray:
    """A lon/lat line moved `shift` (degrees of latitude) to the right of its direction."""
    if len(xy) < 2:
        return xy
    scaled = np.column_stack([xy[:, 0] * coslat, xy[:, 1]])
    tangent = np.gradient(scaled, axis=0)
    norm = np.hypot(tangent[:, 0], tangent[:, 1])
    norm[norm == 0] = 1.0
    right = np.column_stack([tangent[:, 1], -tangent[:, 0]]) / norm[:, None]
    moved = scaled + shift * right
    return np.column_stack([moved[:, 0] / coslat, moved[:, 1]])


def plot_routes(
    lines: Sequence[np.ndarray],
    labels: Sequence[str | None],
    routes,
    medoids: Sequence[np.ndarray],
    path: Path,
    title: str = "",
) -> None:
    """routes.png (`title`: what the tracks are, e.g. the input file; `routes`: the routes table,
    a pandas DataFrame with `route` and `n_tracks`, largest first; `medoids`: each route's medoid
    track): tracks without a route thin and grey;
    for the `ROUTE_LEGEND_MAX` largest routes, their tracks thin in the route's colour and its
    medoid track thick, drawn a little to the right of its direction of travel, with a dot at the
    entry and arrows along it, named in the legend with their size; the other routes' tracks in
    one colour. The map frames those largest routes (tracks reaching beyond are cut); lon/lat,
    the longitude stretched by 1/cos(latitude) so that shapes are true."""
    fig, ax = plt.subplots(figsize=(11, 9))
    names = list(routes["route"]) if len(routes) else []
    colour = dict(zip(names, _route_colours(len(names)), strict=True))
    shown = set(names[:ROUTE_LEGEND_MAX])
    framed = [xy for xy, label in zip(lines, labels, strict=True) if label in shown] or list(lines)
    allpts = np.concatenate(framed) if framed else np.zeros((1, 2))
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    coslat = float(np.cos(np.radians((lo[1] + hi[1]) / 2)))
    shift = ROUTE_OFFSET * max((hi[0] - lo[0]) * coslat, hi[1] - lo[1], 1e-3)
    from matplotlib.collections import LineCollection

    by_label: dict[str | None, list[np.ndarray]] = {}
    for xy, label in zip(lines, labels, strict=True):
        by_label.setdefault(label if label is None or label in shown else "", []).append(xy)
    # each group of thin lines is one artist: fast for tens of thousands of tracks
    styles = {None: ("0.72", 0.4, 0.6, 1.0), "": (OTHER_ROUTES_COLOUR, 0.4, 0.4, 1.5)}
    for label, group in by_label.items():
        c, lw, alpha, z = styles.get(label, (colour.get(label), 0.5, 0.3, 2.0))
        ax.add_collection(LineCollection(group, colors=[c], linewidths=lw, alpha=alpha, zorder=z))
    handles = []
    for i, (name, xy) in enumerate(zip(names[:ROUTE_LEGEND_MAX], medoids, strict=False)):
        c = colour[name]
        z = 3 + (len(names) - i) / (len(names) + 1)  # the largest routes on top
        med = _keep_right(xy, shift, coslat)
        ax.plot(med[:, 0], med[:, 1], color="k", lw=3.0, zorder=z)
        ax.plot(med[:, 0], med[:, 1], color=c, lw=2.0, zorder=z)
        ax.plot(*med[0], "o", color=c, mec="k", ms=5, zorder=z)
        for at in (len(med) // 2, len(med) - 1):
            if at >= 1:
                ax.annotate(
                    "",
                    xy=med[at],
                    xytext=med[at - 1],
                    arrowprops={"arrowstyle": "-|>", "color": c, "lw": 1.5, "mutation_scale": 14},
                    zorder=z,
                )
        n = int(routes["n_tracks"].iloc[i])
        handles.append(plt.Line2D([], [], color=c, lw=2.2, label=f"{name} ({n} tracks)"))
    if len(names) > ROUTE_LEGEND_MAX:
        rest = int(routes["n_tracks"].iloc[ROUTE_LEGEND_MAX:].sum())
        label = f"{len(names) - ROUTE_LEGEND_MAX} other routes ({rest} tracks)"
        handles.append(plt.Line2D([], [], color=OTHER_ROUTES_COLOUR, lw=1, label=label))
    n_unrouted = sum(label is None for label in labels)
    handles.append(plt.Line2D([], [], color="0.72", lw=1, label=f"no route ({n_unrouted} tracks)"))
    pad = np.maximum((hi - lo) * 0.06, 0.005)
    ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    ax.set_aspect(1.0 / coslat)
    _draw_land(ax)
    ax.set_facecolor(WATER_COLOR)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    head = f"{len(names)} routes in {len(lines):,} tracks" + (f" of {title}" if title else "")
    ax.set_title(
        f"{head}\nthe largest in colour, their medoid track thick (dot: entry, arrows: direction)",
        fontsize=10,
    )
    _save(fig, path)
