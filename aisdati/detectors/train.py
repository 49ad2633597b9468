"""Training any detector on the tracks of an ingest folder: `aisdati train --method`."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from aisdati.ais.training import TrainSettings, check_settings, model_stem, training_set
from aisdati.detectors.registry import detector_class
from aisdati.detectors.scoring import ScoreSettings
from aisdati.errors import UserError
from aisdati.model.trainer import Callback


@dataclass
class Trained:
    model: Path
    card: dict[str, Any]
    """The card as written beside the model (`ModelCard.to_dict`)."""
    wall_seconds: float
    resumed_from: int = 0


def train_routes(
    method: str,
    settings: Sequence[TrainSettings],
    how: ScoreSettings | None = None,
    on_step: Callback | None = None,
) -> list[Trained]:
    """One model of `method` per settings (route or cluster), calibrated on its training tracks
    and saved in its `out_dir`: DATI trains all routes as one batched ensemble, the others one
    after the other (`Detector.fit_routes`)."""
    cls = detector_class(method)
    settings = [replace(s, stem=s.stem or cls.model_name(s.cluster)) for s in settings]
    for s in settings:
        check_settings(s)  # before reading any data
        if s.out_dir is None:
            raise UserError("training from an ingest folder needs an output folder (--out)")
    t0 = time.perf_counter()
    detectors = cls.fit_routes(settings, [training_set(s) for s in settings], how, on_step)
    trained = []
    for s, det in zip(settings, detectors, strict=True):
        stem = model_stem(s)
        assert stem is not None  # every settings has an out_dir (checked above)
        det.save(stem)
        wall = time.perf_counter() - t0
        model = stem.with_suffix(det.model_suffix)
        trained.append(Trained(model, det.card.to_dict(), wall, det.resumed_from))
    return trained


def train_detector(
    method: str,
    settings: TrainSettings,
    how: ScoreSettings | None = None,
    on_step: Callback | None = None,
) -> Trained:
    """Train `method` on the settings' tracks, calibrate it on them, save it."""
    return train_routes(method, [settings], how, on_step)[0]
