"""Which class each detector method is, and loading any saved detector by its card.

Every concrete `Detector` registers itself under its `method` when its class is defined
(`Detector.__init_subclass__`), as Gymnasium registers environments by id: adding a detector is
writing its module and importing it in `aisdati.detectors`, and nothing dispatches on names.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from aisdati.ais.card import CalibratedWith, read_card
from aisdati.errors import UserError
from aisdati.options import parse_names

if TYPE_CHECKING:
    from aisdati.detectors.base import Detector

DETECTORS: dict[str, type[Detector]] = {}
"""Every registered detector class by method, in the order they were defined."""


def register(cls: type[Detector]) -> None:
    """Make `cls` the detector of `cls.method` (`--method`, the card's format)."""
    known = DETECTORS.get(cls.method)
    if known is not None and known.__qualname__ != cls.__qualname__:
        raise ValueError(f"two detectors named {cls.method!r}: {known} and {cls}")
    DETECTORS[cls.method] = cls


def detector_class(method: str) -> type[Detector]:
    if method not in DETECTORS:
        raise UserError(f"unknown detector {method!r}; choose from {', '.join(DETECTORS)}")
    return DETECTORS[method]


def parse_detectors(text: str | Iterable[str]) -> tuple[str, ...]:
    """'dati,nearest' -> ('dati', 'nearest'); an unknown name is a one-line `UserError`."""
    return parse_names(text, DETECTORS, "detector")


def model_name(cluster: str, method: str) -> str:
    """The file stem of `method`'s model of `cluster` (`Detector.model_name`)."""
    return detector_class(method).model_name(cluster)


def load_detector(stem: Path) -> Detector:
    """Any saved detector, by its card's format; damage or a foreign file is one line."""
    path = stem.with_suffix(".json")
    card = read_card(path)  # size, types, ranges: one line naming the field
    det = detector_class(card.method).from_files(stem, card)
    recorded = card.calibrated_with or CalibratedWith()
    # `decision_function` judges by its own score, with the settings its threshold was made with
    det.how = replace(
        det.how,
        score=card.score,
        lane_course_km=recorded.lane_course_km,
        lane_traffic=recorded.lane_traffic,
    )
    det.loaded_from = path
    return det


def load_detectors(models_dir: Path, names: Sequence[str]) -> list[Detector]:
    """The named models of a folder, or every model in it."""
    if names:
        stems = [models_dir / n for n in names]
    else:
        stems = sorted(p.with_suffix("") for p in models_dir.glob("*.json"))
        stems = [s for s in stems if not s.name.endswith(".log")]
        if not stems:
            raise UserError(f"no models in {models_dir}: run `aisdati train --cluster up` first")
    return [load_detector(s) for s in stems]
