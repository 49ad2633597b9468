"""Detectors by name: parsing `--method` / `--detectors`, model file names and the models of a
folder. Which class each method is lives with the classes (`aisdati.detectors.base.DETECTORS`,
filled as each concrete detector is defined)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

from aisdati.detectors.base import DETECTORS, Detector, detector_class, load_detector
from aisdati.errors import UserError
from aisdati.options import parse_names


def parse_detectors(text: str | Iterable[str]) -> tuple[str, ...]:
    """'dati,nearest' -> ('dati', 'nearest'); an unknown name is a one-line `UserError`."""
    return parse_names(text, DETECTORS, "detector")


def model_name(cluster: str, method: str) -> str:
    """The file stem of `method`'s model of `cluster` (`Detector.model_name`)."""
    return detector_class(method).model_name(cluster)


def check_model_names(names: Sequence[str]) -> None:
    """Model names (`--model`) are the stems of files in the model folder, never paths: a name
    that climbs out of the folder or names another one (`../x`, `/abs/x`, `a/b`) would load a
    model from anywhere the user (or a server behind a URL folder) can reach."""
    for name in names:
        if not name or name in (".", "..") or Path(name).name != name:
            raise UserError(
                f"--model {name!r}: give a model's name in --models (such as route-2 or "
                "all-bc), not a path"
            )


def load_detectors(models_dir: Path, names: Sequence[str], cluster: str = "all") -> list[Detector]:
    """The named models of a folder, or every model in it; an empty folder is a one-line error
    that suggests training `cluster` (what the caller was asked to judge)."""
    check_model_names(names)
    if names:
        stems = [models_dir / n for n in names]
    else:
        stems = sorted(p.with_suffix("") for p in models_dir.glob("*.json"))
        stems = [s for s in stems if not s.name.endswith(".log")]
        if not stems:
            raise UserError(
                f"no models in {models_dir}: run `aisdati train --cluster {cluster}` first"
            )
    return [load_detector(s) for s in stems]
