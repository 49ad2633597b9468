"""Every figure of aisdati, drawn with matplotlib's Agg backend (no display needed)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from aisdati.model.families import Family


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


LAND_MIN_SPAN_DEG = 2.0
"""The 1:110m land outline is drawn only on maps spanning at least this many degrees; on smaller
ones (a harbour) it would put land across shipping lanes."""


def land_geometry():
    """Offline land basemap: Natural Earth 1:110m, the Americas (see aisdati/data/README.md)."""
    import json
    from importlib.resources import files

    from shapely.geometry import shape

    doc = json.loads((files("aisdati") / "data" / "land_110m_americas.geojson").read_text())
    return shape(doc["features"][0]["geometry"])


def _draw_land(ax: plt.Axes) -> None:
    from shapely.geometry import MultiPolygon, Polygon

    land = land_geometry()
    polys = land.geoms if isinstance(land, MultiPolygon) else [land]
    for poly in polys:
        if isinstance(poly, Polygon):
            x, y = poly.exterior.xy
            ax.fill(x, y, color="#e8e4d8", ec="#b8b09a", lw=0.6, zorder=0)


def plot_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray],
    flagged: np.ndarray,
    max_dev: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    path: Path,
    title: str = "",
) -> None:
    """Test tracks grey, flagged tracks red with their nearest rollout blue and a cross where they
    deviate most, the models' regions dashed, over an offline land basemap (lon/lat, the
    longitude axis stretched by 1/cos(latitude) so that shapes are true)."""
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
    ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    ax.set_aspect(1.0 / np.cos(np.radians((lo[1] + hi[1]) / 2)))
    if max(hi - lo) >= LAND_MIN_SPAN_DEG:
        _draw_land(ax)
    else:
        ax.text(
            0.01,
            0.01,
            "harbour scale: the offline 1:110m land outline is too coarse to draw",
            transform=ax.transAxes,
            fontsize=7,
            color="0.4",
        )
    ax.set_facecolor("#eef4f8")
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    handles = [
        plt.Line2D([], [], color="0.55", lw=1, label="test track"),
        plt.Line2D([], [], color="tab:red", lw=1.4, label="flagged track"),
        plt.Line2D([], [], color="tab:blue", lw=1, label="nearest rollout"),
        plt.Line2D([], [], color="k", marker="x", ls="", label="largest deviation"),
        plt.Line2D([], [], color="k", ls="--", lw=0.8, label="model region"),
    ]
    ax.legend(handles=handles, fontsize=8, loc="best")
    ax.set_title(title or "DATI anomalies")
    _save(fig, path)


def html_detection_map(
    tracks: Sequence[np.ndarray],
    rollouts: Sequence[np.ndarray],
    props: Sequence[dict],
    flagged: np.ndarray,
    regions: Sequence[tuple[np.ndarray, np.ndarray]],
    path: Path,
) -> None:
    """The detection map as a zoomable folium (Leaflet) page: OpenStreetMap tiles (fetched by the
    browser when online), test tracks grey, flagged red with a popup of their scores, nearest
    rollouts blue, a marker where each flagged track deviates most, the models' regions."""
    import folium

    allpts = np.concatenate(list(tracks))
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    fmap = folium.Map(tiles="OpenStreetMap", control_scale=True)
    fmap.fit_bounds([[lo[1], lo[0]], [hi[1], hi[0]]])
    normal = folium.FeatureGroup("test tracks", show=True)
    red = folium.FeatureGroup("flagged tracks", show=True)
    blue = folium.FeatureGroup("nearest rollouts (flagged)", show=True)
    for xy, roll, p, f in zip(tracks, rollouts, props, flagged, strict=True):
        latlon = np.round(xy[:, ::-1], 5).tolist()
        text = "<br>".join(f"{k}: {v}" for k, v in p.items())
        if not f:
            folium.PolyLine(latlon, color="#888888", weight=1.5, opacity=0.6, tooltip=text).add_to(
                normal
            )
            continue
        folium.PolyLine(latlon, color="#d62728", weight=3, tooltip=text, popup=text).add_to(red)
        folium.PolyLine(np.round(roll[:, ::-1], 5).tolist(), color="#1f77b4", weight=2).add_to(blue)
        folium.CircleMarker(
            [p["max_dev_lat"], p["max_dev_lon"]],
            radius=6,
            color="black",
            fill=True,
            tooltip=f"track {p['track_id']}: largest deviation {p['max_dev_m']:,.0f} m",
        ).add_to(red)
    for lo_r, hi_r in regions:
        folium.Rectangle(
            [[lo_r[1], lo_r[0]], [hi_r[1], hi_r[0]]], color="black", weight=1, dash_array="5"
        ).add_to(fmap)
    for group in (normal, blue, red):
        group.add_to(fmap)
    folium.LayerControl().add_to(fmap)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    fmap.save(str(tmp))
    tmp.replace(path)


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
    ax.set_facecolor("#eef4f8")
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    head = f"{len(names)} routes in {len(lines):,} tracks" + (f" of {title}" if title else "")
    ax.set_title(
        f"{head}\nthe largest in colour, their medoid track thick (dot: entry, arrows: direction)",
        fontsize=10,
    )
    _save(fig, path)
