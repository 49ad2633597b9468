"""Detectors behind one PyOD-like interface (`Detector`): `fit` on normal tracks,
`decision_function` (higher = more abnormal, in metres), `threshold` from a contamination,
`predict`, `save` and `load_detector`. `dati` is the paper's method; `bc` and `nearest` are the
baselines it is measured against.

    from aisdati.detectors import NearestDetector
    det = NearestDetector().fit(train_tracks)       # tracks: aisdati.tracks.store.load_tracks
    flagged = det.predict(test_tracks, contamination=0.05)
"""

from __future__ import annotations

# isort: off
# the detectors register themselves (`DETECTORS`) as they are imported, in the order `--method`
# lists them: the paper's method first, then its baselines
from aisdati.detectors.dati import DATIDetector
from aisdati.detectors.bc import BCDetector
from aisdati.detectors.nearest import NearestDetector

# isort: on
from aisdati.ais.training import TrainSettings
from aisdati.detectors.base import (
    DEFAULT_CONTAMINATION,
    DETECTORS,
    Detector,
    detector_class,
    load_detector,
)
from aisdati.detectors.registry import load_detectors, model_name, parse_detectors
from aisdati.detectors.scoring import Scores, ScoreSettings

__all__ = [
    "DEFAULT_CONTAMINATION",
    "DETECTORS",
    "BCDetector",
    "DATIDetector",
    "Detector",
    "NearestDetector",
    "ScoreSettings",
    "Scores",
    "TrainSettings",
    "detector_class",
    "load_detector",
    "load_detectors",
    "model_name",
    "parse_detectors",
]
