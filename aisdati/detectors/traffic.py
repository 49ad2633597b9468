"""The training tracks themselves, kept by a model: the lane that remembered traffic covers.

`nearest` judges by them alone; a policy's `steptraffic` score adds them to the one-step score
(`aisdati.detectors.policy`). A track's traffic distance is, for each of its reports, the
course-weighed distance to the nearest point of the candidate training tracks
(`aisdati.geo.lane_distances`), and the mean of the largest `ScoreSettings.tail` of those. The
candidates of a model of a whole area (`--cluster all`) are every training track; of a route's,
those starting within `near_km` of the track's start (all where none does). Calibration is
leave-one-vessel-out: each training track against the other vessels' tracks, or, where one vessel
sailed every training track (a ferry line run by one boat), against the vessel's other tracks.
"""

from __future__ import annotations

import io
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aisdati.ais.card import MAX_POINTS, MAX_TRACKS, ModelCard
from aisdati.detectors.scoring import ScoreSettings, tail_mean
from aisdati.errors import UserError
from aisdati.geo import haversine_m, lane_distances
from aisdati.model.readers import ArraySpec, read_npz
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track

TRACK_ARRAYS = {
    "positions": ArraySpec("f", 2, width=2, max_items=2 * MAX_POINTS),
    "offsets": ArraySpec("iu", 1, max_items=MAX_TRACKS + 1),
    "mmsi": ArraySpec("iu", 1, max_items=MAX_TRACKS),
}
"""What `Traffic.to_bytes` writes: every training report's (lon, lat), where each track's
reports start (and the end), each track's vessel."""


@dataclass
class Traffic:
    """The training tracks' positions and vessels (see the module docstring)."""

    tracks: list[np.ndarray]
    mmsi: np.ndarray
    whole_area: bool
    """Every training track is a candidate (a model of a whole area), not only those starting
    near the track's start."""

    @classmethod
    def of(cls, tracks: Sequence[Track], cluster: str) -> Traffic:
        mmsi = np.array([t.mmsi for t in tracks], np.int64)
        return cls([t.positions for t in tracks], mmsi, cluster == AREA)

    def candidates(
        self, queries: Sequence[np.ndarray], near_km: float, exclude: np.ndarray | None = None
    ) -> list[np.ndarray]:
        """Per query, the training tracks it is compared with. `exclude` (calibration) gives
        each query's vessel, to leave out; the queries are then the training tracks themselves,
        so with no other vessel only the query's own track is left out."""
        starts = np.array([q[0] for q in queries])
        own = np.array([t[0] for t in self.tracks])
        d = haversine_m(starts[:, None, 0], starts[:, None, 1], own[None, :, 0], own[None, :, 1])
        if self.whole_area:
            d = np.zeros_like(d)
        out = []
        for k in range(len(starts)):
            ok = np.ones(len(self.tracks), dtype=bool)
            if exclude is not None:
                ok &= self.mmsi != exclude[k]
                if not ok.any():
                    ok = np.arange(len(self.tracks)) != k
            near = np.nonzero(ok & (d[k] <= near_km * 1000.0))[0]
            out.append(near if len(near) else np.nonzero(ok)[0])
        return out

    def lane_scores(
        self, queries: Sequence[np.ndarray], how: ScoreSettings, exclude: np.ndarray | None = None
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """Tail mean of each query's per-report distances to the lane of its candidate
        training tracks, and those distances."""
        cands = self.candidates(queries, how.near_km, exclude)
        profiles = [
            lane_distances(q, [self.tracks[j] for j in c], how.lane_course_km * 1000.0)
            for q, c in zip(queries, cands, strict=True)
        ]
        return np.array([tail_mean(d, how.tail) for d in profiles]), profiles

    def calibration(self, how: ScoreSettings) -> np.ndarray:
        """The training tracks' own lane scores, leave-one-vessel-out."""
        return self.lane_scores(self.tracks, how, exclude=self.mmsi)[0]

    def to_bytes(self) -> bytes:
        flat = np.concatenate(self.tracks)
        offsets = np.concatenate([[0], np.cumsum([len(t) for t in self.tracks])])
        buf = io.BytesIO()
        np.savez_compressed(buf, positions=flat, offsets=offsets, mmsi=self.mmsi)
        return buf.getvalue()

    @classmethod
    def read(cls, path: Path, card: ModelCard) -> Traffic:
        """The training tracks saved at `path`, checked against the card: the offsets cut the
        positions into the card's tracks (the DTW kernels read them unchecked)."""
        z = read_npz(path, TRACK_ARRAYS)
        flat, mmsi = z["positions"].astype(np.float64), z["mmsi"].astype(np.int64)
        offsets = z["offsets"].astype(np.int64)  # a descending uint64 would wrap in np.diff
        n, points = len(card.data.track_ids), card.data.points
        problem = None
        if len(offsets) != n + 1 or len(mmsi) != n:
            problem = f"it holds {len(offsets) - 1} tracks and {len(mmsi)} vessels, the card {n}"
        elif len(flat) != points:
            problem = f"it holds {len(flat)} positions, the card says {points}"
        elif offsets[0] != 0 or offsets[-1] != points or np.any(np.diff(offsets) < 1):
            problem = f"the offsets must rise from 0 to {points}, by at least 1 per track"
        elif np.any(np.abs(flat) > [180.0, 90.0]):
            problem = "positions must be (lon, lat) in degrees"
        if problem is not None:
            raise UserError(f"cannot load {path}: {problem}")
        tracks = [flat[a:b] for a, b in itertools.pairwise(offsets)]
        return cls(tracks, mmsi, card.cluster == AREA)
