"""One interface for every detector (PyOD's `BaseDetector` is the model): fit on training
tracks, score tracks (higher = more abnormal, in metres), and a flagging threshold calibrated on
the training tracks' own scores (`contamination`: the share of normal traffic one accepts to
flag), which does not depend on the test set."""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from aisdati.errors import UserError
from aisdati.tracks.store import Track

SCORES = ("rollout", "step", "lane", "both")


def tail_mean(values: np.ndarray, fraction: float) -> float:
    """Mean of the largest `fraction` of the values (at least one): a short stretch far off
    counts as much in a long track as in a short one."""
    k = max(1, math.ceil(len(values) * fraction))
    return float(np.partition(values, len(values) - k)[-k:].mean())


@dataclass(frozen=True, kw_only=True)
class ScoreSettings:
    score: str = "lane"
    """lane, rollout (the paper's), step (teacher-forced) or both; see
    `aisdati.ais.policy`."""
    rollouts: int = 10
    """K: free rollouts per track (the rollout score is the best of K), and one-step draws
    per report."""
    lane_rollouts: int = 30
    """Lane score: free rollouts per track that make up its lane (the K of the rollout score
    and L - K more). A lane is where the policy goes, estimated from samples: on the Kitimat
    routes over three seeds and several noise draws, DATI's pooled lane AUC (by position only)
    averaged 0.879 with 10, 0.892 with 30 and 0.904 with 100 rollouts (README, "every route of
    an area"); with the course weighed, 100 add little. 30 keeps scoring and calibration
    affordable."""
    lane_reach: float = 2.0
    """Lane score: the rollouts run this many times the track's number of steps (the rollout
    score always uses the track's own number). DATI's rollouts on Kitimat ran at half to twice
    the real pace (SOG x dt), so over the track's number of steps a slow one stopped half-way
    and every later report was "far from the lane"; twice as many steps cover a model at half
    pace, and a fast one just goes on along the corridor."""
    lane_course_km: float = 2.0
    """Lane score: what sailing against the lane's course costs, km (across it: 0.7 x as
    much); 0 judges position only. See `aisdati.geo.lane_distances`. 2 km gave DATI the best
    pooled lane AUC averaged over two areas (Kitimat's fjord lanes, where 4 km was better, and
    NY Harbor's ferry crossings, where 4 km was worse than none; README, "every route")."""
    lane_traffic: bool = True
    """Lane score of a learnt policy: each track's lane also holds one rollout from every
    training track's start (`PolicyDetector.traffic`), so the lane is where the model's
    traffic goes, not only where it goes from this track's start. A real track that starts
    off the lane and joins it was judged only against rollouts that never reached the lane
    it joined. With it DATI's pooled lane AUC rose 0.942 -> 0.966 on Kitimat and 0.945 ->
    0.959 on NY Harbor (README, "every route of an area")."""
    tail: float = 0.1
    """Step and lane scores: the mean of the largest `tail` of a track's per-report distances.
    Measured at 0.05-1 on both areas (`benchmarks/lane_score.py --tail`): 0.1 gave DATI the
    best pooled lane AUC averaged over Kitimat and NY Harbor (0.15 was level; larger fractions
    dilute a short jump or loiter on the ferry routes, smaller ones let a few stray reports
    decide); README, "every route of an area"."""
    near_km: float = 10.0
    """`nearest`: compare with training tracks that start within this distance."""
    seed: int = 0

    def calibrated_with(self) -> dict[str, float | bool]:
        """What a card records of the settings its calibration scores were computed with:
        `Detector.threshold` refuses to flag with others."""
        return {"lane_course_km": self.lane_course_km, "lane_traffic": self.lane_traffic}


CALIBRATED_BEFORE: dict[str, float | bool] = {"lane_course_km": 0.0, "lane_traffic": False}
"""What a card that does not record a calibration setting was calibrated with."""


def _as_option(key: str, value: float | bool, named: bool = True) -> str:
    """`--lane-course-km 2` (or `2` unnamed) / `--lane-traffic` / `--no-lane-traffic`."""
    if isinstance(value, bool):
        return f"--{'' if value else 'no-'}{key.replace('_', '-')}"
    return f"--{key.replace('_', '-')} {value:g}" if named else f"{value:g}"


@dataclass
class Scores:
    """What a detector says about N tracks."""

    score_m: np.ndarray
    """[N] raw scores, metres; higher = more abnormal."""
    profiles: list[np.ndarray]
    """Per track, the local deviation (m) at each of its points: where it strays."""
    evidence: list[np.ndarray]
    """Per track, what it was compared with ([m, 2] lon/lat): best rollout, nearest training
    track, or the one-step predictions."""
    parts: dict[str, np.ndarray] = field(default_factory=dict)
    """Every score computed in the pass, by kind ([N] each, `score_m` among them)."""


class Detector(ABC):
    """A trained detector of one group of tracks (a cluster or route), saved as `<stem>.json`
    (its card) beside method-specific files."""

    method: ClassVar[str]
    format: ClassVar[str]
    lane_settings: ClassVar[tuple[str, ...]] = ("lane_course_km",)
    """The `ScoreSettings` its lane score depends on: a threshold needs them as calibrated."""

    def __init__(self, name: str, card: dict[str, Any]):
        self.name = name
        self.card = card

    # ------------------------------------------------------------------ identity
    @property
    def training_ids(self) -> set[int]:
        return {int(i) for i in self.card["data"]["track_ids"]}

    @property
    def start_points(self) -> np.ndarray:
        return np.asarray(self.card["data"]["start_points"], np.float64).reshape(-1, 2)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        reg = self.card["region"]
        return (
            np.array([reg["lon"][0], reg["lat"][0]], np.float64),
            np.array([reg["lon"][1], reg["lat"][1]], np.float64),
        )

    def contains(self, points: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds
        return np.all((points >= lo) & (points <= hi), axis=-1)

    # ------------------------------------------------------------------- scoring
    @abstractmethod
    def score(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str] = ()
    ) -> Scores:
        """Score tracks the way `how.score` says (higher = more abnormal), and compute the
        kinds in `also` in the same pass (into `Scores.parts`)."""

    def calibration_key(self, how: ScoreSettings) -> str:
        return how.score

    def threshold(self, how: ScoreSettings, contamination: float) -> float:
        """The (1 - contamination) quantile of the training tracks' own scores."""
        key = self.calibration_key(how)
        cal = self.card.get("calibration", {}).get(key)
        if not cal:
            raise UserError(
                f"model {self.name} has no calibration scores for --score {how.score}: "
                "retrain it, or flag with --threshold / --top-percent"
            )
        recorded = {**CALIBRATED_BEFORE, **self.card.get("calibrated_with", {})}
        for name in self.lane_settings if key == "lane" else ():
            was, now = recorded[name], getattr(how, name)
            if not math.isclose(float(was), float(now)):
                raise UserError(
                    f"model {self.name}'s lane scores were calibrated with "
                    f"{_as_option(name, was)}, not {_as_option(name, now, named=False)}: pass "
                    "that, retrain, or flag with --threshold / --top-percent"
                )
        return float(np.quantile(np.asarray(cal, np.float64), 1.0 - contamination))

    def save_card(self, stem: Path) -> None:
        from aisdati.model.checkpoint import atomic_write_bytes

        doc = {"format": self.format, "method": self.method, **self.card}
        atomic_write_bytes(stem.with_suffix(".json"), json.dumps(doc, indent=2).encode())
