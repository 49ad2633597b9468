"""The figure of `aisdati ingest`: routes.png, the route clusters over the coastline."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from aisdati.plots import WATER_COLOR, draw_land, plain_text, save

ROUTE_LEGEND_MAX = 15
"""Routes drawn in their own colour with their medoid in routes.png (the largest); the tracks of
the others are drawn in one colour, as "other routes"."""
OTHER_ROUTES_COLOUR = "#7f9fbf"

THIN_LINES_MAX = 25_000
"""Thin track lines routes.png draws at most: beyond, every k-th track of each group (said in
the title). Drawing them all cost 5 s and about 1 GB at 100,000-270,000 tracks, for a picture
that looks the same; the counts in the legend are always of all tracks."""

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


def _extent(lines: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The lon/lat box of the lines, from each line's extremes: no copy of every point."""
    if not lines:
        return np.zeros(2), np.zeros(2)
    lo = np.min([xy.min(axis=0) for xy in lines], axis=0)
    return lo, np.max([xy.max(axis=0) for xy in lines], axis=0)


@plain_text()  # the title names the input files, the legend the routes: drawn as they are
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
    lo, hi = _extent(framed)
    coslat = float(np.cos(np.radians((lo[1] + hi[1]) / 2)))
    stride = _draw_tracks(ax, lines, labels, shown, colour)
    shift = ROUTE_OFFSET * max((hi[0] - lo[0]) * coslat, hi[1] - lo[1], 1e-3)
    handles = _draw_medoids(ax, names, routes, medoids, colour, (shift, coslat))
    handles += _other_handles(routes, labels)
    _frame(ax, lo, hi, coslat)
    ax.legend(handles=handles, fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    head = f"{len(names)} routes in {len(lines):,} tracks" + (f" of {title}" if title else "")
    if stride > 1:
        head += f" (thin lines: 1 in {stride} tracks)"
    ax.set_title(
        f"{head}\nthe largest in colour, their medoid track thick (dot: entry, arrows: direction)",
        fontsize=10,
    )
    save(fig, path)


def _draw_tracks(
    ax: plt.Axes,
    lines: Sequence[np.ndarray],
    labels: Sequence[str | None],
    shown: set[str],
    colour: dict[str, Any],
) -> int:
    """Every track as a thin line: those of the `shown` routes in their route's colour, those of
    the other routes in one colour, those without a route grey; every k-th track of each group
    when there are more than `THIN_LINES_MAX`. Returns k."""
    by_label: dict[str | None, list[np.ndarray]] = {}
    for xy, label in zip(lines, labels, strict=True):
        by_label.setdefault(label if label is None or label in shown else "", []).append(xy)
    # each group of thin lines is one artist: fast for tens of thousands of tracks
    stride = -(-len(lines) // THIN_LINES_MAX) if lines else 1
    styles = {None: ("0.72", 0.4, 0.6, 1.0), "": (OTHER_ROUTES_COLOUR, 0.4, 0.4, 1.5)}
    for label, group in by_label.items():
        c, lw, alpha, z = styles.get(label, (colour.get(label), 0.5, 0.3, 2.0))
        drawn = group[::stride]
        ax.add_collection(LineCollection(drawn, colors=[c], linewidths=lw, alpha=alpha, zorder=z))
    return stride


def _draw_medoids(
    ax: plt.Axes,
    names: list[str],
    routes,
    medoids: Sequence[np.ndarray],
    colour: dict[str, Any],
    offset: tuple[float, float],
) -> list[plt.Line2D]:
    """The medoid tracks of the `ROUTE_LEGEND_MAX` largest routes (`names`, largest first), each
    moved to the right of its direction (`offset`: `_keep_right`'s shift and cos(latitude)), the
    largest on top; their legend entries."""
    handles = []
    for i, (name, xy) in enumerate(zip(names[:ROUTE_LEGEND_MAX], medoids, strict=False)):
        c = colour[name]
        z = 3 + (len(names) - i) / (len(names) + 1)  # the largest routes on top
        _draw_medoid(ax, _keep_right(xy, *offset), c, z)
        n = int(routes["n_tracks"].iloc[i])
        handles.append(plt.Line2D([], [], color=c, lw=2.2, label=f"{name} ({n} tracks)"))
    return handles


def _draw_medoid(ax: plt.Axes, med: np.ndarray, c: Any, z: float) -> None:
    """One medoid track: a thick line in colour `c` edged in black, a dot at its entry and an
    arrow halfway and at its end, all at depth `z`."""
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


def _other_handles(routes, labels: Sequence[str | None]) -> list[plt.Line2D]:
    """The legend entries of the routes beyond `ROUTE_LEGEND_MAX` (when there are any) and of
    the tracks without a route, with their numbers of tracks."""
    handles = []
    if len(routes) > ROUTE_LEGEND_MAX:
        rest = int(routes["n_tracks"].iloc[ROUTE_LEGEND_MAX:].sum())
        label = f"{len(routes) - ROUTE_LEGEND_MAX} other routes ({rest} tracks)"
        handles.append(plt.Line2D([], [], color=OTHER_ROUTES_COLOUR, lw=1, label=label))
    n_unrouted = sum(label is None for label in labels)
    handles.append(plt.Line2D([], [], color="0.72", lw=1, label=f"no route ({n_unrouted} tracks)"))
    return handles


def _frame(ax: plt.Axes, lo: np.ndarray, hi: np.ndarray, coslat: float) -> None:
    """The map's box (lon/lat [lo, hi] and a margin), its aspect, the land and the axes' labels."""
    pad = np.maximum((hi - lo) * 0.06, 0.005)
    ax.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
    ax.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
    ax.set_aspect(1.0 / coslat)
    draw_land(ax)
    ax.set_facecolor(WATER_COLOR)
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
