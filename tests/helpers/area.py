"""A model of a whole area on Kitimat, July trains and August is judged: the split, the few
rollouts the mechanism tests score with, and nearest models saved for `detect`."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from aisdati.ais.training import TrainSettings
from aisdati.detectors import ScoreSettings
from aisdati.detectors.nearest import NearestDetector
from aisdati.tracks.store import Track

AUGUST = pd.Timestamp("2018-08-01", tz="UTC")
HOW = ScoreSettings(rollouts=2, lane_rollouts=4)
"""Few rollouts: the tests check what judges a track and how, not how well."""


def save_nearest(tracks: list[Track], cluster: str, models: Path) -> None:
    det = NearestDetector(TrainSettings(cluster=cluster), HOW).fit(tracks)
    det.save(models / det.name)
