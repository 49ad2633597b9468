"""Training any detector on one cluster's (or route's) tracks: `aisdati train --method`."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import torch

from aisdati.ais.training import (
    StepCallback,
    TrainSettings,
    base_card,
    build_source,
    choose_training_tracks,
    data_card,
    make_env,
    model_stem,
    train_ais,
    train_ais_ensemble,
)
from aisdati.detectors import model_name
from aisdati.detectors.base import ScoreSettings
from aisdati.detectors.learnt import BCDetector, DATIDetector
from aisdati.detectors.nearest import NearestDetector
from aisdati.errors import UserError
from aisdati.model.bc import BCConfig, BCTrainer
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.tracks.store import load_tracks


def _calibrate_dati(stem: Path, how: ScoreSettings) -> dict[str, Any]:
    """Score a saved DATI model's own training tracks and write the scores into its card."""
    det = DATIDetector.load(stem, {})
    det.card["training"]["finished"] = True
    tracks = load_tracks(Path(det.card["data"]["dir"]), det.card["data"]["track_ids"])
    det.calibrate(tracks, how)
    atomic_write_bytes(stem.with_suffix(".json"), json.dumps(det.card, indent=2).encode())
    return det.card


def train_routes(
    method: str,
    settings: list[TrainSettings],
    how: ScoreSettings | None = None,
    on_step: StepCallback | None = None,
) -> list[Trained]:
    """One model per route: DATI trains all routes as one batched ensemble, the others one
    after the other."""
    how = how or ScoreSettings()
    settings = [replace(s, stem=s.stem or model_name(s.cluster, method)) for s in settings]
    if method != "dati":
        return [train_detector(method, s, how) for s in settings]
    t0 = time.perf_counter()
    results = train_ais_ensemble(settings, on_step)
    return [
        Trained(r.model, _calibrate_dati(model_stem(s), how), time.perf_counter() - t0)
        for r, s in zip(results, settings, strict=True)
    ]


@dataclass
class Trained:
    model: Path
    card: dict[str, Any]
    wall_seconds: float
    resumed_from: int = 0


def train_detector(
    method: str,
    settings: TrainSettings,
    how: ScoreSettings | None = None,
    on_step: StepCallback | None = None,
    on_episode: Callable[[int], None] | None = None,
) -> Trained:
    """Train `method` on the settings' tracks, calibrate it on them, save it."""
    how = how or ScoreSettings()
    settings = replace(settings, stem=settings.stem or model_name(settings.cluster, method))
    t0 = time.perf_counter()
    if method == "dati":
        result = train_ais(settings, on_step)
        card = _calibrate_dati(model_stem(settings), how)
        return Trained(result.model, card, time.perf_counter() - t0, result.resumed_from)
    if settings.episodes < 1:
        raise UserError(f"--episodes must be at least 1, got {settings.episodes}")
    ids, total = choose_training_tracks(settings)
    tracks = load_tracks(settings.data_dir, ids)
    # a lane's seed ensemble (`members`) is DATI's: the baselines are one model, and their cards
    # say so (a BC card's seeds must number its members)
    source = build_source(tracks, replace(settings.lane, members=1))
    card = base_card(settings, source, data_card(settings, tracks, total))
    stem = model_stem(settings)
    if method == "nearest":
        det = NearestDetector.fit(stem.name, tracks, card, how)
    elif method == "bc":
        torch.set_num_threads(1)
        config = BCConfig(episodes=settings.episodes)
        trainer = BCTrainer([make_env(source)], [settings.seed], config)
        policy = trainer.train(on_episode)
        card["training"] = {
            "episodes_run": trainer.episode,
            "final_loss": float(trainer.losses[-1][0]),
            "finished": True,
        }
        det = BCDetector(stem.name, card, policy)
        det.corridor = source.space.corridor
        det.calibrate(tracks, how)
    else:
        raise UserError(f"unknown method {method!r}")
    card["training"] = {**card.get("training", {}), "wall_seconds": time.perf_counter() - t0}
    det.save(stem)
    if source.space.corridor is not None:
        atomic_write_bytes(stem.with_suffix(".corridor.npz"), source.space.corridor.to_bytes())
    return Trained(stem.with_suffix(".json"), det.card, time.perf_counter() - t0)
