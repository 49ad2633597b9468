"""The navigable corridor of a group of tracks: where a generated track may go.

The paper keeps the agent inside a region of interest drawn around the traffic, sticking at its
edge. A lon/lat box around winding channels contains the land between them, so rollouts that
stick only at the box cut across islands and leave the lanes. The corridor is the union of the
training tracks buffered by `buffer_km`, minus land where a coastline is available, rasterised
on a grid of `cell_m` cells so that a lookup costs O(1). A move that would leave it *slides*:
the same step length is tried with the course turned by 15°, 30°, ... up to 180° either way (the
smaller turn first), so a rollout follows a channel's bend instead of stopping dead, and an
agent at the closed end of a channel (a berth, the tip of an inlet) turns round instead of
staying there for good; when no turn fits, the agent stays where it is (the paper's sticking).
The same rule holds an agent outside the corridor (a track that starts off the lanes) to moves
that take it no farther from the corridor (`gap_m`), turned like the others, so it finds its way
in; refused every move that does not enter at once, it was held at its start for good."""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

from aisdati.errors import UserError
from aisdati.geo import EARTH_RADIUS_M
from aisdati.model.readers import ArraySpec, read_npz

M_PER_DEG = np.pi * EARTH_RADIUS_M / 180.0
TURNS_DEG = (*(a for k in range(15, 180, 15) for a in (k, -k)), 180)
"""Courses tried, in this order, when a step would leave the corridor. Up to 90° was not
enough: Kitimat track 97 starts at the tip of an inlet open only to the east-south-east, its
policy heads north-west like its route, and its rollouts never left the start (131 km)."""
_TURN_COS = np.array([np.cos(np.radians(turn)) for turn in TURNS_DEG])
_TURN_SIN = np.array([np.sin(np.radians(turn)) for turn in TURNS_DEG])


@dataclass
class Corridor:
    mask: np.ndarray
    """[rows (lat), cols (lon)] True where a position is allowed."""
    origin: np.ndarray
    """(lon, lat) of the grid's lower-left corner."""
    step: np.ndarray
    """(dlon, dlat) cell size in degrees."""
    _lookup: tuple[np.ndarray, ...] | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_tracks(
        cls,
        tracks: Sequence[np.ndarray],
        buffer_km: float = 2.0,
        cell_m: float = 200.0,
        on_land: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    ) -> Corridor:
        pts = np.concatenate(list(tracks))
        lat0 = float(np.mean(pts[:, 1]))
        step = np.array([cell_m / (M_PER_DEG * np.cos(np.radians(lat0))), cell_m / M_PER_DEG])
        margin = (buffer_km * 1000.0 / cell_m + 2) * step
        origin = pts.min(axis=0) - margin
        shape = np.ceil((pts.max(axis=0) + margin - origin) / step).astype(int)[::-1]
        visited = np.zeros(shape, dtype=bool)
        for t in tracks:  # densify each segment to half a cell so no cell is skipped
            seg = np.diff(t, axis=0)
            n = np.maximum(np.ceil(np.abs(seg / step).max(axis=1) * 2).astype(int), 1)
            frac = np.concatenate([np.arange(k) / k for k in n])
            base = np.repeat(t[:-1], n, axis=0) + np.repeat(seg, n, axis=0) * frac[:, None]
            ij = np.floor((np.vstack([base, t[-1:]]) - origin) / step).astype(int)
            visited[ij[:, 1], ij[:, 0]] = True
        mask = distance_transform_edt(~visited) * cell_m <= buffer_km * 1000.0
        if on_land is not None:
            rows, cols = np.nonzero(mask)
            centres = origin + (np.column_stack([cols, rows]) + 0.5) * step
            land = on_land(centres[:, 0], centres[:, 1])
            mask[rows[land], cols[land]] = False
            mask[visited] = True  # where ships sailed is water, whatever the coastline says
        return cls(mask, origin, step)

    def gap_m(self, points: np.ndarray) -> np.ndarray:
        """Distance (m, to the cell) from each point to the nearest allowed cell: 0 inside;
        off the grid, the distance to the grid's nearest cell plus that cell's; inf for a
        non-finite point. The grid's distance map is computed once, on first use."""
        points = np.asarray(points, np.float64)
        flat = np.ascontiguousarray(points.reshape(-1, 2))
        out = np.empty(len(flat))
        _gaps(flat, *self._grid(), out)
        return out.reshape(points.shape[:-1])

    def allowed(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies in an allowed cell (no gap to the corridor)."""
        return self.gap_m(points) == 0.0

    def slide(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        """Where each agent ends up: the proposed point if it takes the agent no farther from
        the corridor (`gap_m`; inside, that is staying inside), else the smallest turn of the
        same step that does, else where it is. Rows of [N, 2] arrays. Compiled, agent by agent:
        a rollout calls it at every step, and as numpy passes over the agents still turning it
        was half of scoring's time."""
        position = np.ascontiguousarray(position, np.float64)
        proposed = np.ascontiguousarray(proposed, np.float64)
        coslat = np.cos(np.radians(position[:, 1]))
        out = np.empty_like(position)
        _slide(position, proposed, coslat, _TURN_COS, _TURN_SIN, *self._grid(), out)
        return out

    def _grid(self) -> tuple[np.ndarray, ...]:
        """What the compiled lookups read, made on first use and kept (a rollout looks up at
        every step): the distance map (m), the grid's origin and cell (degrees) and the cell's
        size in metres (east, north)."""
        if self._lookup is None:
            lat = self.origin[1] + self.step[1] * self.mask.shape[0] / 2
            cell = self.step * M_PER_DEG * np.array([np.cos(np.radians(lat)), 1.0])
            gap = distance_transform_edt(~self.mask, sampling=(cell[1], cell[0]))
            origin, step = (np.asarray(x, np.float64) for x in (self.origin, self.step))
            self._lookup = (gap, origin, step, cell)
        return self._lookup

    def to_bytes(self) -> bytes:
        buf = io.BytesIO()
        np.savez_compressed(buf, mask=self.mask, origin=self.origin, step=self.step)
        return buf.getvalue()

    @classmethod
    def from_file(cls, path: Path) -> Corridor:
        """What `to_bytes` wrote; a damaged or foreign file is a one-line `UserError`."""
        z = read_npz(path, CORRIDOR_ARRAYS)
        mask, origin, step = z["mask"].astype(bool), z["origin"], z["step"]
        if 0 in mask.shape:
            raise UserError(f"cannot load {path}: its grid ('mask') is empty")
        if not np.all(step > 0):
            raise UserError(f"cannot load {path}: the cell size ('step') must be > 0, got {step}")
        return cls(mask, origin, step)


@njit(cache=True)
def _gap_one(x, y, gap, origin, step, cell):  # pragma: no cover - compiled
    """`Corridor.gap_m` of one point."""
    rx = np.floor((x - origin[0]) / step[0])
    ry = np.floor((y - origin[1]) / step[1])
    if not (math.isfinite(rx) and math.isfinite(ry)):
        return math.inf
    rows, cols = gap.shape
    ix = min(max(rx, 0.0), cols - 1.0)
    iy = min(max(ry, 0.0), rows - 1.0)
    beyond = math.hypot((rx - ix) * cell[0], (ry - iy) * cell[1])
    return gap[int(iy), int(ix)] + beyond


@njit(cache=True)
def _gaps(points, gap, origin, step, cell, out):  # pragma: no cover - compiled
    for k in range(len(points)):
        out[k] = _gap_one(points[k, 0], points[k, 1], gap, origin, step, cell)


@njit(cache=True)
def _slide(  # pragma: no cover - compiled
    position, proposed, coslat, cos_t, sin_t, gap, origin, step, cell, out
):
    """`Corridor.slide`, agent by agent."""
    for k in range(len(position)):
        px, py, qx, qy = position[k, 0], position[k, 1], proposed[k, 0], proposed[k, 1]
        out[k, 0], out[k, 1] = px, py
        if not (math.isfinite(qx) and math.isfinite(qy)):
            continue
        limit = _gap_one(px, py, gap, origin, step, cell)
        if _gap_one(qx, qy, gap, origin, step, cell) <= limit:
            out[k, 0], out[k, 1] = qx, qy
            continue
        dx, dy = (qx - px) * coslat[k], qy - py
        for t in range(len(cos_t)):  # clockwise turns of the course (x east, y north)
            cx = px + (dx * cos_t[t] + dy * sin_t[t]) / coslat[k]
            cy = py + (-dx * sin_t[t] + dy * cos_t[t])
            if _gap_one(cx, cy, gap, origin, step, cell) <= limit:
                out[k, 0], out[k, 1] = cx, cy
                break


CORRIDOR_ARRAYS = {
    "mask": ArraySpec("biu", 2),
    "origin": ArraySpec("f", 1, width=2),
    "step": ArraySpec("f", 1, width=2),
}
"""What a corridor file holds (`Corridor.to_bytes`): at most `ArraySpec.max_items` cells, a
region 2,300 km square at the default 200 m."""
