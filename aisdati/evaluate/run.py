"""`aisdati evaluate`: a detection benchmark on the user's own ingested data.

1. Split one cluster's (or route's) tracks by vessel into training and held-out sets (seeded),
   or take the training set from existing model cards (`models_dir`).
2. Write anomalies of the chosen kinds into a seeded half of the held-out tracks
   (`aisdati.evaluate.inject`); save everything in ingest's schema under `<out>/data`.
3. Train every detector asked for on the training tracks (`<out>/models`), or load it.
4. Score the held-out tracks and report, per detector, score and anomaly kind: ROC AUC, average
   precision, precision / recall / F1 at the detector's calibrated flagging rule (the
   (1 - contamination) quantile of its training tracks' scores), and the median score of normal
   and altered tracks. Policy detectors (dati, bc) are scored all three ways (rollout, step,
   both) from one scoring pass. For them the median normal rollout score is the *lane
   fidelity*: how far (mean metres along the DTW path) the best of K rollouts stays from unseen
   normal tracks.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.detectors import DETECTORS, Detector, ScoreSettings, load_detector, model_name
from aisdati.errors import UserError
from aisdati.evaluate import dataset
from aisdati.evaluate.metrics import flagging, ranking
from aisdati.model.ais import TrainSettings
from aisdati.model.ais_space import PRESETS, LaneConfig
from aisdati.trackdata import load_tracks, read_track_table, select_cluster

POSITION_KINDS = ("detour", "jump", "loiter")
"""The summary row the README's targets use: anomalies a position-only score can see."""


@dataclass(frozen=True)
class EvaluateSettings:
    data_dir: Path
    cluster: str
    out_dir: Path
    detectors: tuple[str, ...] = ("nearest", "dati", "bc")
    kinds: tuple[str, ...] = ("detour", "jump", "loiter", "speed", "gap", "noise")
    params: dict[str, Any] = field(default_factory=dict)
    train_fraction: float = 0.6
    seed: int = 0
    episodes: int = 170
    patience: int = 10
    rollouts: int = 10
    near_km: float = 10.0
    contamination: float = 0.05
    models_dir: Path | None = None
    preset: str = "lanes"
    lane: LaneConfig = field(default_factory=lambda: PRESETS["lanes"])


@dataclass
class Evaluation:
    settings: EvaluateSettings
    split: dataset.Split
    table: pd.DataFrame
    """One row per detector x score x kind (and 'all', 'detour+jump+loiter')."""
    scores: pd.DataFrame
    """One row per detector x score x held-out track."""
    timings: dict[str, dict[str, float]]
    detectors: dict[str, Detector]
    profiles: dict[tuple[str, str], list[np.ndarray]] = field(default_factory=dict)
    evidence: dict[tuple[str, str], list[np.ndarray]] = field(default_factory=dict)


def check(settings: EvaluateSettings) -> None:
    if not 0.1 <= settings.train_fraction <= 0.9:
        raise UserError(f"--train-fraction must be in [0.1, 0.9], got {settings.train_fraction:g}")
    if not 0.0 < settings.contamination < 0.5:
        raise UserError(f"--contamination must be in (0, 0.5), got {settings.contamination:g}")
    if settings.rollouts < 1 or settings.episodes < 1:
        raise UserError("--rollouts and --episodes must be at least 1")
    if not np.isfinite(settings.near_km) or settings.near_km <= 0:
        raise UserError(f"--near-km must be a positive number, got {settings.near_km:g}")


def _existing(settings: EvaluateSettings) -> dict[str, Detector]:
    """Detectors of `models_dir` trained on this cluster, by method."""
    found: dict[str, Detector] = {}
    if settings.models_dir is None:
        return found
    for method in settings.detectors:
        stem = settings.models_dir / model_name(settings.cluster, method)
        if stem.with_suffix(".json").is_file():
            found[method] = load_detector(stem)
    if not found:
        raise UserError(
            f"no model of cluster {settings.cluster!r} for {', '.join(settings.detectors)} in "
            f"{settings.models_dir}"
        )
    return found


def _same_region(settings: EvaluateSettings, models: dict[str, Detector]) -> None:
    """Models given with --models must come from the area of the data they are evaluated on."""
    table = select_cluster(read_track_table(settings.data_dir), settings.cluster, settings.data_dir)
    ids = [int(i) for i in table["track_id"]]
    starts = np.array([t.positions[0] for t in load_tracks(settings.data_dir, ids)])
    for method, det in models.items():
        if not det.contains(starts).any():
            lo, hi = det.bounds
            raise UserError(
                f"the {method} model in {settings.models_dir} was trained on another region "
                f"(lon {lo[0]:.2f}..{hi[0]:.2f}, lat {lo[1]:.2f}..{hi[1]:.2f}): no track of "
                f"{settings.cluster!r} starts there"
            )


def evaluate(
    settings: EvaluateSettings,
    on_stage: Callable[[str], None] | None = None,
    train_detector: Callable[..., Any] | None = None,
) -> Evaluation:
    """Run the benchmark; `train_detector(method, TrainSettings, ScoreSettings)` trains one
    detector (the CLI passes one with progress bars)."""
    from aisdati.detectors.train import train_detector as plain_train

    check(settings)
    train = train_detector or plain_train
    say = on_stage or (lambda _: None)
    existing = _existing(settings)
    train_ids = None
    if existing:
        train_ids = [int(i) for i in next(iter(existing.values())).card["data"]["track_ids"]]
        _same_region(settings, existing)
    say("splitting and injecting")
    data = settings.out_dir / "data"
    split = dataset.build(
        settings.data_dir,
        settings.cluster,
        data,
        settings.kinds,
        settings.params,
        settings.train_fraction,
        settings.seed,
        train_ids,
    )
    how = ScoreSettings("both", settings.rollouts, settings.near_km, settings.seed)
    heldout = load_tracks(data, split.heldout_ids)
    labels = split.labels.set_index("track_id").loc[split.heldout_ids]
    timings: dict[str, dict[str, float]] = {}
    rows, score_rows = [], []
    detectors: dict[str, Detector] = {}
    result = Evaluation(settings, split, pd.DataFrame(), pd.DataFrame(), timings, detectors)
    for method in settings.detectors:
        t0 = time.perf_counter()
        if method in existing:
            det = existing[method]
        else:
            say(f"training {method}")
            trained = train(
                method,
                TrainSettings(
                    data_dir=data,
                    cluster=settings.cluster,
                    out_dir=settings.out_dir / "models",
                    episodes=settings.episodes,
                    seed=settings.seed,
                    max_tracks=None,
                    patience=settings.patience,
                    track_ids=tuple(split.train_ids),
                    preset=settings.preset,
                    lane=settings.lane,
                ),
                how,
            )
            det = load_detector(trained.model.with_suffix(""))
        detectors[method] = det
        t1 = time.perf_counter()
        say(f"scoring with {method}")
        kinds = ["nearest"] if method == "nearest" else ["rollout", "step", "both"]
        scored = det.score(heldout, how if method != "nearest" else replace(how, score="step"))
        t2 = time.perf_counter()
        timings[method] = {"train_s": t1 - t0, "score_s": t2 - t1}
        for kind in kinds:
            values = scored.score_m if kind in ("nearest", "both") else scored.parts[kind]
            threshold = det.threshold(replace(how, score=kind), settings.contamination)
            flagged = values > threshold
            key = (method, kind)
            result.profiles[key] = scored.profiles
            result.evidence[key] = scored.evidence
            for tid, v, f in zip(split.heldout_ids, values, flagged, strict=True):
                score_rows.append((method, kind, tid, float(v), bool(f)))
            rows += _rows(method, kind, labels, values, flagged, threshold, settings.kinds)
    result.table = pd.DataFrame(rows)
    scores = pd.DataFrame(score_rows, columns=["detector", "score", "track_id", "value", "flagged"])
    result.scores = scores.merge(split.labels, on="track_id", how="left")
    return result


def _rows(
    method: str,
    score: str,
    labels: pd.DataFrame,
    values: np.ndarray,
    flagged: np.ndarray,
    threshold: float,
    kinds: tuple[str, ...],
) -> list[dict[str, Any]]:
    y = labels["label"].to_numpy()
    kind = labels["kind"].to_numpy()
    normal = y == 0
    groups = [(k, kind == k) for k in kinds]
    pos = tuple(k for k in POSITION_KINDS if k in kinds)
    if 1 < len(pos) < len(kinds):
        groups.append(("+".join(pos), np.isin(kind, pos)))
    groups.append(("all", y == 1))
    out = []
    for name, anomalous in groups:
        keep = normal | anomalous
        row = {
            "detector": method,
            "score": score,
            "kind": name,
            "anomalies": int(anomalous.sum()),
            "normal": int(normal.sum()),
            **ranking(y[keep], values[keep]),
            **flagging(y[keep], flagged[keep]),
            "threshold_m": float(threshold),
            "median_normal_m": float(np.median(values[normal])),
            "median_anomalous_m": float(np.median(values[anomalous])) if anomalous.any() else None,
        }
        out.append(row)
    return out


__all__ = ["DETECTORS", "EvaluateSettings", "Evaluation", "evaluate"]
