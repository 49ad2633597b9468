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
