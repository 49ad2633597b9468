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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

from aisdati.errors import UserError
from aisdati.geo import EARTH_RADIUS_M
from aisdati.model.readers import ArraySpec, read_npz

M_PER_DEG = np.pi * EARTH_RADIUS_M / 180.0
TURNS_DEG = (*(a for k in range(15, 180, 15) for a in (k, -k)), 180)
"""Courses tried, in this order, when a step would leave the corridor. Up to 90° was not
enough: Kitimat track 97 starts at the tip of an inlet open only to the east-south-east, its
policy heads north-west like its route, and its rollouts never left the start (131 km)."""


@dataclass
class Corridor:
    mask: np.ndarray
    """[rows (lat), cols (lon)] True where a position is allowed."""
    origin: np.ndarray
    """(lon, lat) of the grid's lower-left corner."""
    step: np.ndarray
    """(dlon, dlat) cell size in degrees."""
    _gap: np.ndarray | None = field(default=None, repr=False, compare=False)

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
        lat = self.origin[1] + self.step[1] * self.mask.shape[0] / 2
        cell = self.step * M_PER_DEG * np.array([np.cos(np.radians(lat)), 1.0])
        if self._gap is None:
            self._gap = distance_transform_edt(~self.mask, sampling=(cell[1], cell[0]))
        raw = np.floor((np.asarray(points, np.float64) - self.origin) / self.step)
        finite = np.all(np.isfinite(raw), axis=-1)
        raw = np.where(finite[..., None], raw, 0.0)
        rows, cols = self.mask.shape
        ij = np.clip(raw, 0, [cols - 1, rows - 1]).astype(int)
        off = (raw - ij) * cell
        beyond = np.hypot(off[..., 0], off[..., 1])
        return np.where(finite, self._gap[ij[..., 1], ij[..., 0]] + beyond, np.inf)

    def allowed(self, points: np.ndarray) -> np.ndarray:
        """Whether each point lies in an allowed cell (no gap to the corridor)."""
        return self.gap_m(points) == 0.0

    def slide(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        """Where each agent ends up: the proposed point if it takes the agent no farther from
        the corridor (`gap_m`; inside, that is staying inside), else the smallest turn of the
        same step that does, else where it is. Rows of [N, 2] arrays."""
        limit = self.gap_m(position)
        finite = np.all(np.isfinite(proposed), axis=1)
        fits = finite & (self.gap_m(proposed) <= limit)
        out = np.where(fits[:, None], proposed, position)
        todo = ~fits & finite
        if not todo.any():
            return out
        coslat = np.cos(np.radians(position[todo, 1]))
        d = (proposed[todo] - position[todo]) * np.column_stack([coslat, np.ones_like(coslat)])
        found = np.zeros(todo.sum(), dtype=bool)
        result = position[todo].copy()
        for turn in TURNS_DEG:
            a = np.radians(turn)  # clockwise turn of a course (x east, y north)
            rx = d[:, 0] * np.cos(a) + d[:, 1] * np.sin(a)
            ry = -d[:, 0] * np.sin(a) + d[:, 1] * np.cos(a)
            cand = position[todo] + np.column_stack([rx / coslat, ry])
            ok = ~found & (self.gap_m(cand) <= limit[todo])
            result[ok] = cand[ok]
            found |= ok
            if found.all():
                break
        out[todo] = result
        return out

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


CORRIDOR_ARRAYS = {
    "mask": ArraySpec("biu", 2),
    "origin": ArraySpec("f", 1, width=2),
    "step": ArraySpec("f", 1, width=2),
}
"""What a corridor file holds (`Corridor.to_bytes`): at most `ArraySpec.max_items` cells, a
region 2,300 km square at the default 200 m."""
