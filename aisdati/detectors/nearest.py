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
line run by one boat), against the vessel's other tracks (`aisdati.detectors.traffic`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from aisdati.ais.card import DataCard, ModelCard, TrainingReport
from aisdati.ais.source import fit_space
from aisdati.ais.training import TrainSettings, base_card
from aisdati.detectors.base import Detector
from aisdati.detectors.scoring import Scores, ScoreSettings
from aisdati.detectors.traffic import Traffic
from aisdati.dtw import matched_distances, nearest_mean_dtw_m
from aisdati.model.trainer import Callback
from aisdati.tracks.store import Track


class NearestDetector(Detector):
    method = "nearest"
    progress_unit = "models"

    def __init__(
        self,
        settings: TrainSettings | None = None,
        how: ScoreSettings | None = None,
        name: str | None = None,
    ):
        super().__init__(settings, how, name)
        self.training_tracks = Traffic([], np.empty(0, np.int64), False)
        """The training tracks."""

    @classmethod
    def episodes(cls, settings: TrainSettings) -> int:
        return 1  # it remembers its tracks in one pass

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
        self.training_tracks = Traffic.of(tracks, self.card.cluster)
        how, own = self.how, self.training_tracks.tracks
        dtw = self.search(own, how.near_km, exclude=self.training_tracks.mmsi)[0]
        self.card.calibration = {
            k: [round(float(s), 2) for s in v]
            for k, v in (("nearest", dtw), ("lane", self.training_tracks.calibration(how)))
        }
        self.card.calibrated_with = how.calibrated_with()
        self.card.training = TrainingReport(wall_seconds=time.perf_counter() - t0)
        return self

    def calibration_key(self, how: ScoreSettings) -> str:
        return "lane" if how.score == "lane" else "nearest"

    def search(
        self, queries: list[np.ndarray], near_km: float, exclude: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each query's mean DTW (m) to its nearest candidate training track, and which."""
        candidates = self.training_tracks.candidates(queries, near_km, exclude)
        return nearest_mean_dtw_m(queries, self.training_tracks.tracks, candidates)

    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        positions = [t.positions for t in tracks]
        dist, arg = self.search(positions, how.near_km)
        evidence = [self.training_tracks.tracks[a] for a in arg]
        parts = {"nearest": dist}
        if how.score == "lane" or "lane" in also:
            parts["lane"], profiles = self.training_tracks.lane_scores(positions, how)
        if how.score != "lane":
            profiles = [matched_distances(p, e) for p, e in zip(positions, evidence, strict=True)]
        return Scores(parts[self.calibration_key(how)], profiles, evidence, parts)

    # -------------------------------------------------------------------- files
    def save(self, stem: Path) -> None:
        # with the training tracks' corridor, as the policies save theirs
        self.write_model(stem, {".npz": self.training_tracks.to_bytes()})

    @classmethod
    def from_files(cls, stem: Path, card: ModelCard) -> NearestDetector:
        det = cls(name=stem.name)
        det.card = card
        det.training_tracks = Traffic.read(stem.with_suffix(".npz"), card)
        return det
