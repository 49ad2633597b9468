"""Detectors behind one interface (`Detector`): fit on training tracks, score tracks (higher =
more abnormal), threshold from the training scores. `dati` is the paper's method; `bc` and
`nearest` are the baselines it is measured against."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from aisdati.ais.card import validate_ais_card
from aisdati.detectors.base import SCORES, Detector, Scores, ScoreSettings
from aisdati.detectors.learnt import BCDetector, DATIDetector
from aisdati.detectors.nearest import NearestDetector
from aisdati.errors import UserError
from aisdati.options import parse_names

DETECTORS: dict[str, type[Detector]] = {
    "dati": DATIDetector,
    "bc": BCDetector,
    "nearest": NearestDetector,
}
_FORMATS = {cls.format: cls for cls in DETECTORS.values()}

__all__ = ["DETECTORS", "SCORES", "Detector", "ScoreSettings", "Scores", "load_detector"]


def parse_detectors(text: str) -> tuple[str, ...]:
    """'dati,nearest' -> ('dati', 'nearest'); an unknown name is a one-line `UserError`."""
    return parse_names(text, DETECTORS, "detector")


def model_name(cluster: str, method: str) -> str:
    """`<cluster>` for DATI (as before detectors had names), `<cluster>-<method>` otherwise."""
    return cluster if method == "dati" else f"{cluster}-{method}"


def load_detector(stem: Path) -> Detector:
    """Any saved detector, by its card's format; damage or a foreign file is one line."""
    path = stem.with_suffix(".json")
    if not path.is_file():
        raise UserError(f"model file not found: {path}")
    try:
        card = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot read model card {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(card, dict) or card.get("format") not in _FORMATS:
        raise UserError(f"{path} is not an aisdati model card")
    if card.get("kind") != "ais" or any(k not in card for k in ("rule", "region", "data")):
        raise UserError(f"{path} is not an AIS model card (train one with `aisdati train`)")
    validate_ais_card(card, path)  # types, ranges, finiteness: one line naming the field
    if card["format"] == DATIDetector.format:
        weights = stem.with_suffix(".pt")
        if weights.is_file():
            with weights.open("rb") as fh:
                if fh.read(2) != b"PK":  # torch.save writes a zip archive
                    raise UserError(f"{weights} is not a model weights file (damaged or foreign)")
    return _FORMATS[card["format"]].load(stem, card)


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
