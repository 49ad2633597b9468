"""What every figure of aisdati shares: matplotlib's Agg backend (no display needed), saving
whole files, grids of panels, and lon/lat maps over the offline coastline (`aisdati.coastline`).

The figures themselves live with what they show: `aisdati.detection.maps` (detect),
`aisdati.evaluation.figures` (evaluate), `aisdati.preprocess.figures` (ingest's routes.png)."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from aisdati.outdir import atomic_write_bytes


def drawn(fig: plt.Figure, fmt: str = "png") -> bytes:
    """The figure drawn in memory in format `fmt`, then closed: the bytes of a figure file,
    which a worker process can hand back to the process that writes the outputs."""
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format=fmt, dpi=120, bbox_inches="tight")
    finally:
        plt.close(fig)
    return buf.getvalue()


def save(fig: plt.Figure, path: Path) -> None:
    """Draw the figure in memory (in the format its suffix names), then write it whole under
    aisdati's one temporary name (`atomic_write_bytes`): a figure on disk is always complete,
    and a failed drawing leaves nothing."""
    atomic_write_bytes(path, drawn(fig, path.suffix.lstrip(".")))


def plain_text() -> contextlib.AbstractContextManager:
    """Figure texts made in this block are drawn as they are: `$` is a dollar sign, not the
    start of mathtext. Titles, labels and legends hold user strings (file, route and model
    names), and `$\\q$` in one would otherwise break the figure."""
    return plt.rc_context({"text.parse_math": False})


def grid(n: int) -> tuple[plt.Figure, np.ndarray]:
    """A figure of `n` panels, two per row (the unused last one hidden), and its axes, flat."""
    cols = min(n, 2)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


LAND_COLOR = "#e8e4d8"
COAST_COLOR = "#b8b09a"
WATER_COLOR = "#eef4f8"


def draw_land(ax: plt.Axes) -> None:
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
        # add_artist, not add_patch: the limits are set already, and add_patch's update of the
        # data limits walks the coastline's segments in Python (0.1 s a map, half a figure)
        ax.add_artist(PathPatch(path, fc=LAND_COLOR, ec=COAST_COLOR, lw=0.5, zorder=0))
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


def set_map_limits(ax: plt.Axes, lo: np.ndarray, hi: np.ndarray) -> None:
    """Lon/lat limits, the longitude axis stretched by 1/cos(latitude) so shapes are true."""
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect(1.0 / np.cos(np.radians((lo[1] + hi[1]) / 2)))
    ax.ticklabel_format(useOffset=False)
    ax.xaxis.set_major_locator(plt.MaxNLocator(5))
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
