"""`nearest`: the distance to the closest normal track, with no learning at all.

A track's score (`--score` anything but lane) is its mean great-circle DTW (metres along the
warping path, the same unit as DATI's scores) to the nearest training track that starts within
`near_km` of its start (all training tracks when none does). With `--score lane` it is, as for
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
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aisdati.detectors.base import Detector, Scores, ScoreSettings, tail_mean
from aisdati.dtw import matched_distances, nearest_mean_dtw_m
from aisdati.errors import UserError
from aisdati.geo import haversine_m, lane_distances
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.tracks.store import Track


class NearestDetector(Detector):
    method = "nearest"
    format = "aisdati-nearest/1"

    def __init__(self, name: str, card: dict[str, Any], tracks: list[np.ndarray], mmsi: np.ndarray):
        super().__init__(name, card)
        self.tracks = tracks
        self.mmsi = np.asarray(mmsi, np.int64)

    @classmethod
    def fit(
        cls,
        name: str,
        tracks: Sequence[Track],
        card: dict[str, Any],
        how: ScoreSettings | None = None,
    ):
        """Remember the tracks; calibrate on each one against the other vessels' tracks."""
        how = how or ScoreSettings()
        det = cls(name, card, [t.positions for t in tracks], np.array([t.mmsi for t in tracks]))
        queries = [t.positions for t in tracks]
        own = det.search(queries, how.near_km, exclude=det.mmsi)[0]
        lane = det.lane_scores(queries, how, exclude=det.mmsi)[0]
        card["calibration"] = {
            k: [round(float(s), 2) for s in v] for k, v in (("nearest", own), ("lane", lane))
        }
        card["calibrated_with"] = how.calibrated_with()
        return det

    def calibration_key(self, how: ScoreSettings) -> str:
        return "lane" if how.score == "lane" else "nearest"

    def _candidates(self, queries: list[np.ndarray], near_km: float, exclude: np.ndarray | None):
        """Per query, the training tracks it is compared with (see the module docstring).
        `exclude` (calibration) gives each query's vessel, to leave out; the queries are then
        the training tracks themselves, so with no other vessel only the query's own track is
        left out."""
        starts = np.array([q[0] for q in queries])
        own = np.array([t[0] for t in self.tracks])
        d = haversine_m(starts[:, None, 0], starts[:, None, 1], own[None, :, 0], own[None, :, 1])
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

    def search(self, queries: list[np.ndarray], near_km: float, exclude=None):
        return nearest_mean_dtw_m(queries, self.tracks, self._candidates(queries, near_km, exclude))

    def lane_scores(self, queries: list[np.ndarray], how: ScoreSettings, exclude=None):
        """Tail mean of each query's per-report distances to the lane of its candidate
        training tracks, and those distances."""
        cands = self._candidates(queries, how.near_km, exclude)
        profiles = [
            lane_distances(q, [self.tracks[j] for j in c], how.lane_course_km * 1000.0)
            for q, c in zip(queries, cands, strict=True)
        ]
        return np.array([tail_mean(d, how.tail) for d in profiles]), profiles

    def score(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str] = ()
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

    @classmethod
    def load(cls, stem: Path, card: dict[str, Any]) -> NearestDetector:
        path = stem.with_suffix(".npz")
        try:
            with np.load(path, allow_pickle=False) as z:
                flat, offsets, mmsi = z["positions"], z["offsets"], z["mmsi"]
        except (OSError, ValueError, KeyError) as exc:
            raise UserError(f"cannot load {path}: {str(exc).splitlines()[0]}") from None
        tracks = [flat[a:b] for a, b in itertools.pairwise(offsets)]
        return cls(stem.name, card, tracks, mmsi)
