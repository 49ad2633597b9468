"""One interface for every detector, after PyOD's `BaseDetector`: `fit` on normal tracks,
`decision_function` (higher = more abnormal, in metres), a flagging `threshold` calibrated on
the training tracks' own scores (`contamination`: the share of normal traffic one accepts to
flag, which does not depend on the test set), `predict`, `save` and `load`.

    det = NearestDetector().fit(train_tracks)
    flagged = det.predict(test_tracks, contamination=0.05)

A detector is constructed with how to train it (`TrainSettings`: episodes, seed, lane
configuration) and how to score (`ScoreSettings`); fitting or loading gives it a `card`
(`ModelCard`), which says what it was trained on and holds its calibration scores.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np

from aisdati.ais.card import (
    CalibratedWith,
    DataCard,
    ModelCard,
    check_files,
    read_card,
    write_model,
)
from aisdati.ais.corridor import Corridor
from aisdati.ais.training import TrainSettings, check_settings
from aisdati.detectors.scoring import Scores, ScoreSettings, joined, score_chunks
from aisdati.errors import UserError
from aisdati.execution import InProcess, Runner
from aisdati.model.readers import first_line
from aisdati.model.trainer import Callback
from aisdati.scores import scores_from
from aisdati.tracks.store import Track

DEFAULT_CONTAMINATION = 0.05
"""The share of normal traffic a threshold flags unless told otherwise (`aisdati evaluate`'s)."""
SPREAD_DRAWS = 200
SPREAD_SEED = 0
D = TypeVar("D", bound="Detector")
STEP_SETTINGS = ("reported_motion",)
"""The `ScoreSettings` the step scores depend on beyond K: a threshold needs them as
calibrated."""

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


class Detector(ABC):
    """A detector of one group of tracks (a cluster or route), saved as `<stem>.json` (its
    card) beside method-specific files; see the module docstring."""

    method: ClassVar[str]
    """The name it is registered and chosen (`--method`) under; its card's format."""
    lane_settings: ClassVar[tuple[str, ...]] = ("lane_course_km",)
    """The `ScoreSettings` its lane score depends on: a threshold needs them as calibrated."""
    model_suffix: ClassVar[str] = ".json"
    """The file `aisdati train` reports as the model."""

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        if "method" in vars(cls):  # a concrete detector (not a shared base like PolicyDetector)
            register(cls)

    def __init__(
        self,
        settings: TrainSettings | None = None,
        how: ScoreSettings | None = None,
        name: str | None = None,
    ):
        self.settings = settings or TrainSettings()
        check_settings(self.settings)
        self.how = how or ScoreSettings()
        self.name = name or self.settings.stem or self.model_name(self.settings.cluster)
        self.corridor: Corridor | None = None
        """The corridor of the training tracks (`region="corridor"`), saved beside the model."""
        self.resumed_from = 0
        """Episodes a resumed training had done before this fit (DATI's `--resume`)."""
        self.loaded_from: Path | None = None
        """The card it was loaded from (`load_detector`); None when fitted here."""
        self._card: ModelCard | None = None

    @classmethod
    def model_name(cls, cluster: str) -> str:
        """The file stem of this method's model of `cluster`: `<cluster>-<method>`."""
        return f"{cluster}-{cls.method}"

    @property
    def card(self) -> ModelCard:
        if self._card is None:
            raise UserError(f"the {self.method} detector is not fitted: fit it or load one")
        return self._card

    @card.setter
    def card(self, card: ModelCard) -> None:
        self._card = card

    # ----------------------------------------------------------------------------- fitting
    @abstractmethod
    def fit(
        self: D,
        tracks: Sequence[Track],
        data: DataCard | None = None,
        on_step: Callback | None = None,
    ) -> D:
        """Learn the normal traffic of `tracks` and calibrate the threshold on them; returns
        the detector. `data` is the card's description of the tracks (`aisdati.ais.training.
        training_set` reads it from an ingest folder; default: from the tracks themselves).
        `on_step` follows DATI's training (`aisdati.model.trainer.Callback`)."""

    @classmethod
    def members(cls, settings: TrainSettings) -> int:
        """Models one training run of `settings` holds (a progress bar counts their episodes)."""
        return 1

    progress_unit = "episodes"
    """What a training progress bar counts for this detector (`episodes`)."""

    @classmethod
    def episodes(cls, settings: TrainSettings) -> int:
        """Episodes one member trains at most, for the progress bar: `settings.episodes`; a
        detector that learns in one pass counts each of its models as one."""
        return settings.episodes

    @classmethod
    def fit_routes(
        cls,
        settings: Sequence[TrainSettings],
        training_sets: Sequence[tuple[list[Track], DataCard]],
        how: ScoreSettings | None = None,
        on_step: Callback | None = None,
        first_member: int = 0,
    ) -> list[Detector]:
        """One detector per route (settings and training set each); the default fits them one
        after the other, DATI trains them as one batched ensemble (its members' seeds counted
        from `first_member`: the routes trained before them in other tasks)."""
        return [
            cls(s, how).fit(tracks, data, on_step)
            for s, (tracks, data) in zip(settings, training_sets, strict=True)
        ]

    @staticmethod
    def describe(tracks: Sequence[Track], data: DataCard | None) -> DataCard:
        """The card's data section of the training tracks (`data` where the caller has it)."""
        return data if data is not None else DataCard.of_tracks(tracks)

    # ----------------------------------------------------------------------------- scoring
    def score(
        self,
        tracks: Sequence[Track],
        how: ScoreSettings | None = None,
        also: Sequence[str] = (),
        runner: Runner | None = None,
    ) -> Scores:
        """Score tracks the way `how.score` says (default: the detector's `how`; higher = more
        abnormal), and compute the kinds in `also` in the same pass (into `Scores.parts`), in
        chunks (`score_chunks`) run as tasks of `runner` (default: here). Numbers a kernel
        refuses (`aisdati.dtw`: NaN or inf) are a one-line `UserError` naming the model."""
        self.card  # noqa: B018 (refuses, in one line, a detector not fitted or loaded)
        return score_each([(self, tracks, how or self.how)], also, runner)[0]

    @abstractmethod
    def score_tracks(
        self, tracks: Sequence[Track], how: ScoreSettings, also: Sequence[str]
    ) -> Scores:
        """`score`'s work, with the settings chosen."""

    def to_device(self, device: str) -> None:
        """Run the detector's networks on `device` (`aisdati.execution.device`) from now on;
        a detector without torch networks (or one whose networks are too small to gain from
        a GPU: BC) runs on the CPU whatever it is told."""
        del device  # only DATI's networks move (`DATIDetector.to_device`)

    def decision_function(self, tracks: Sequence[Track]) -> np.ndarray:
        """Each track's score (higher = more abnormal) of the detector's `how`, in its unit
        (`aisdati.scores.Score.unit`: metres, or multiples of the draws' spread)."""
        return self.score(tracks).score

    def calibration_key(self, how: ScoreSettings) -> str:
        return how.score

    def threshold(
        self, how: ScoreSettings | None = None, contamination: float = DEFAULT_CONTAMINATION
    ) -> float:
        """The (1 - contamination) quantile of the training tracks' own scores."""
        how = how or self.how
        key = self.calibration_key(how)
        cal = self.card.calibration.get(key)
        if not cal:
            raise UserError(
                f"model {self.name} has no calibration scores for --score {how.score}: "
                "retrain it, or flag with --threshold / --top-percent"
            )
        recorded = self.card.calibrated_with or CalibratedWith()
        kind = "lane" if key == "lane" else "step" if key in scores_from("steps") else None
        names = {"lane": self.lane_settings, "step": STEP_SETTINGS}.get(kind or "", ())
        for name in names:
            was, now = getattr(recorded, name), getattr(how, name)
            if not math.isclose(float(was), float(now)):
                raise UserError(
                    f"model {self.name}'s {kind} scores were calibrated with {name}={was}, not "
                    f"{now}: score with its card's settings (`calibrated_with`) or retrain it"
                )
        return float(np.quantile(np.asarray(cal, np.float64), 1.0 - contamination))

    def threshold_spread(
        self, how: ScoreSettings | None = None, contamination: float = DEFAULT_CONTAMINATION
    ) -> tuple[float, float]:
        """The 5th and 95th percentiles of `threshold` over `SPREAD_DRAWS` seeded bootstrap
        resamples of the calibration scores: how much the threshold rests on which training
        tracks happened to calibrate it (a few hundred scores put a 0.95 quantile on a handful
        of tracks)."""
        self.threshold(how, contamination)  # the same checks, the same one-line refusals
        cal = np.asarray(self.card.calibration[self.calibration_key(how or self.how)], np.float64)
        rng = np.random.default_rng(SPREAD_SEED)
        draws = rng.choice(cal, size=(SPREAD_DRAWS, len(cal)), replace=True)
        cuts = np.quantile(draws, 1.0 - contamination, axis=1)
        return float(np.quantile(cuts, 0.05)), float(np.quantile(cuts, 0.95))

    def predict(
        self, tracks: Sequence[Track], contamination: float = DEFAULT_CONTAMINATION
    ) -> np.ndarray:
        """Whether each track is flagged: scored above `threshold(contamination=...)`."""
        cut = self.threshold(contamination=contamination)  # no calibration: fail before scoring
        return self.decision_function(tracks) > cut

    # ------------------------------------------------------------------------------- files
    @abstractmethod
    def save(self, stem: Path) -> None:
        """Write <stem>.json (the card) and the method's own files beside it."""

    @classmethod
    def load(cls, stem: Path) -> Detector:
        """The detector saved at `stem` (`load_detector`): any method when called on
        `Detector`, this one when called on a detector's class."""
        det = load_detector(stem)
        if not isinstance(det, cls):
            raise UserError(f"{stem} is a {det.method} model, not a {cls.__name__}")
        return det

    @classmethod
    @abstractmethod
    def from_files(cls: type[D], stem: Path, card: ModelCard) -> D:
        """The detector saved at `stem`, whose card (already read and checked) is `card`."""

    def write_model(
        self, stem: Path, files: dict[str, bytes], card_extra: dict[str, Any] | None = None
    ) -> None:
        """Write the model's files (by suffix; the corridor added where there is one), then
        the card, last, with their digests (`ModelCard.files`): a model is its card, and a card
        never names files that are not its own (`aisdati.ais.card.check_files`)."""
        if self.corridor is not None:
            files = {**files, ".corridor.npz": self.corridor.to_bytes()}
        write_model(stem, files, self.card, card_extra)


def load_detector(stem: Path) -> Detector:
    """Any saved detector, by its card's format (`DETECTORS`); damage or a foreign file is one
    line."""
    path = stem.with_suffix(".json")
    card = read_card(path)  # size, types, ranges: one line naming the field
    check_files(stem, card)
    det = detector_class(card.method).from_files(stem, card)
    recorded = card.calibrated_with or CalibratedWith()
    # `decision_function` judges by its own score, with the settings its threshold was made with
    det.how = replace(
        det.how,
        score=card.score,
        lane_course_km=recorded.lane_course_km,
        lane_traffic=recorded.lane_traffic,
        rollouts=recorded.rollouts,
        lane_rollouts=recorded.lane_rollouts,
        reported_motion=recorded.reported_motion,
    )
    det.loaded_from = path
    return det


def score_each(
    work: Sequence[tuple[Detector, Sequence[Track], ScoreSettings]],
    also: Sequence[str] = (),
    runner: Runner | None = None,
) -> list[Scores]:
    """`Detector.score` of several detectors, each on its own tracks and with its own settings,
    as one set of tasks (every detector's chunks at once, so that many models of a few tracks
    each still fill the workers)."""
    jobs = [
        (k, detector, list(tracks[r.start : r.stop]), how)
        for k, (detector, tracks, how) in enumerate(work)
        for r in score_chunks(len(tracks))
    ]
    done = (runner or InProcess()).map(functools.partial(score_chunk, tuple(also)), jobs)
    return [joined([c for (j, *_), c in zip(jobs, done, strict=True) if j == k])
            for k in range(len(work))]  # fmt: skip


def score_chunk(
    also: tuple[str, ...], job: tuple[int, Detector, list[Track], ScoreSettings]
) -> Scores:
    """One scoring task of `score_each`: a chunk of one detector's tracks."""
    _, detector, tracks, how = job
    try:
        return detector.score_tracks(tracks, how, also)
    except ValueError as exc:
        where = detector.loaded_from or f"model {detector.name}"
        raise UserError(f"cannot score with {where}: {first_line(exc)}") from None
