"""`nearest`: the distance to the closest normal track, with no learning at all.

A track's score (`--score` anything but lane) is its mean great-circle DTW (metres along the
warping path, the same unit as DATI's scores) to the nearest training track that starts within
`near_km` of its start (all training tracks when none does; a model of a whole area, `--cluster
all`, compares with every training track: the baseline an analyst tries first). With `--score
lane` it is, as for
the policies, the mean of the largest 10 % of each report's distance to the nearest point of
those training tracks: the lane that remembered traffic covers. It is the bar every learnt
detector has to clear: if imitating the traffic does not beat remembering it, the imitation adds
nothing to detection. The DTW search is exact (see `aisdati.dtw.nearest_mean_dtw_m` for the
pruning). Its calibration scores are leave-one-vessel-out: each training track against the
training tracks of other vessels, or, where one vessel sailed every training track (a ferry
line run by one boat), against the vessel's other tracks.
"""

from __future__ import annotations

import io
import itertools
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from aisdati.ais.card import MAX_POINTS, MAX_TRACKS, DataCard, ModelCard, TrainingReport
from aisdati.ais.source import fit_space
from aisdati.ais.training import TrainSettings, base_card
from aisdati.detectors.base import Detector
from aisdati.detectors.scoring import Scores, ScoreSettings, tail_mean
from aisdati.dtw import matched_distances, nearest_mean_dtw_m
from aisdati.errors import UserError
from aisdati.geo import haversine_m, lane_distances
from aisdati.model.readers import ArraySpec, read_npz
from aisdati.model.trainer import Callback
from aisdati.outdir import atomic_write_bytes
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track


class NearestDetector(Detector):
    method = "nearest"

    def __init__(
        self,
        settings: TrainSettings | None = None,
        how: ScoreSettings | None = None,
        name: str | None = None,
    ):
        super().__init__(settings, how, name)
        self.tracks: list[np.ndarray] = []
        """The training tracks' positions."""
        self.mmsi = np.empty(0, np.int64)
        """Their vessels."""

    def fit(
        self,
        tracks: Sequence[Track],
        data: DataCard | None = None,
        on_step: Callback | None = None,
    ) -> NearestDetector:
        """Remember the tracks; calibrate on each one against the other vessels' tracks."""
        t0 = time.perf_counter()
        space = fit_space(tracks, replace(self.settings.lane, members=1, crossfit=False))
        self.card = base_card("nearest", self.settings, space, self.describe(tracks, data))
        self.corridor = space.corridor
        self.tracks = [t.positions for t in tracks]
        self.mmsi = np.array([t.mmsi for t in tracks], np.int64)
        how = self.how
        own = self.search(self.tracks, how.near_km, exclude=self.mmsi)[0]
        lane = self.lane_scores(self.tracks, how, exclude=self.mmsi)[0]
        self.card.calibration = {
            k: [round(float(s), 2) for s in v] for k, v in (("nearest", own), ("lane", lane))
        }
        self.card.calibrated_with = how.calibrated_with()
        self.card.training = TrainingReport(wall_seconds=time.perf_counter() - t0)
        return self

    def calibration_key(self, how: ScoreSettings) -> str:
        return "lane" if how.score == "lane" else "nearest"

    def _candidates(
        self, queries: list[np.ndarray], near_km: float, exclude: np.ndarray | None
    ) -> list[np.ndarray]:
        """Per query, the training tracks it is compared with (see the module docstring).
        `exclude` (calibration) gives each query's vessel, to leave out; the queries are then
        the training tracks themselves, so with no other vessel only the query's own track is
        left out."""
        starts = np.array([q[0] for q in queries])
        own = np.array([t[0] for t in self.tracks])
        d = haversine_m(starts[:, None, 0], starts[:, None, 1], own[None, :, 0], own[None, :, 1])
        if self.card.cluster == AREA:
            d = np.zeros_like(d)  # every training track is a candidate
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

    def search(
        self, queries: list[np.ndarray], near_km: float, exclude: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each query's mean DTW (m) to its nearest candidate training track, and which."""
        return nearest_mean_dtw_m(queries, self.tracks, self._candidates(queries, near_km, exclude))

    def lane_scores(
        self, queries: list[np.ndarray], how: ScoreSettings, exclude: np.ndarray | None = None
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """Tail mean of each query's per-report distances to the lane of its candidate
        training tracks, and those distances."""
        cands = self._candidates(queries, how.near_km, exclude)
        profiles = [
            lane_distances(q, [self.tracks[j] for j in c], how.lane_course_km * 1000.0)
            for q, c in zip(queries, cands, strict=True)
        ]
        return np.array([tail_mean(d, how.tail) for d in profiles]), profiles

    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        positions = [t.positions for t in tracks]
        dist, arg = self.search(positions, how.near_km)
        evidence = [self.tracks[a] for a in arg]
        parts = {"nearest": dist}
        if how.score == "lane" or "lane" in also:
            parts["lane"], profiles = self.lane_scores(positions, how)
        if how.score != "lane":
            profiles = [matched_distances(p, e) for p, e in zip(positions, evidence, strict=True)]
        return Scores(parts[self.calibration_key(how)], profiles, evidence, parts)

    # -------------------------------------------------------------------- files
    def save(self, stem: Path) -> None:
        flat = np.concatenate(self.tracks)
        offsets = np.concatenate([[0], np.cumsum([len(t) for t in self.tracks])])
        buf = io.BytesIO()
        np.savez_compressed(buf, positions=flat, offsets=offsets, mmsi=self.mmsi)
        atomic_write_bytes(stem.with_suffix(".npz"), buf.getvalue())
        self.save_card(stem)
        self.save_corridor(stem)  # the training tracks' corridor, as the policies save theirs

    @classmethod
    def from_files(cls, stem: Path, card: ModelCard) -> NearestDetector:
        det = cls(name=stem.name)
        det.card = card
        det.tracks, det.mmsi = read_tracks(stem.with_suffix(".npz"), card)
        return det


TRACK_ARRAYS = {
    "positions": ArraySpec("f", 2, width=2, max_items=2 * MAX_POINTS),
    "offsets": ArraySpec("iu", 1, max_items=MAX_TRACKS + 1),
    "mmsi": ArraySpec("iu", 1, max_items=MAX_TRACKS),
}
"""What `NearestDetector.save` writes: every training report's (lon, lat), where each track's
reports start (and the end), each track's vessel."""


def read_tracks(path: Path, card: ModelCard) -> tuple[list[np.ndarray], np.ndarray]:
    """The training tracks and their vessels saved at `path`, checked against the card: the
    offsets cut the positions into the card's tracks (the DTW kernels read them unchecked)."""
    z = read_npz(path, TRACK_ARRAYS)
    flat, mmsi = z["positions"].astype(np.float64), z["mmsi"].astype(np.int64)
    offsets = z["offsets"].astype(np.int64)  # a descending uint64 would wrap round in np.diff
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
    return [flat[a:b] for a, b in itertools.pairwise(offsets)], mmsi
