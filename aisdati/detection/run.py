"""Detection of abnormal tracks (section 6.2 of the paper): scores -> flags.

Each test track goes to a model (`route_test_tracks`): the route or cluster model whose
training tracks are bound as it is (start and end within `near_km`; the paper's rule, by start
alone, for cards that do not record where their tracks end), else an area model (`--cluster
all`), which judges any track; a track no model covers is listed with the reason, never dropped
unsaid. The model's detector (`aisdati.detectors`) scores it: by default DATI, judged by the
lane its K free rollouts from the track's first point cover (`--score lane`, the default), with
the origin-destination term added (`--score area`), by its best rollout
(`--score rollout`, the paper's), by its teacher-forced one-step predictions along the track
(`--score step`) or by rollout and step together (`--score both`). Higher means more abnormal.
Flags: scores divided by their maximum over the test set above `threshold` (the paper's
Λ = 0.75), or the `top_percent` highest, or scores above the model's calibrated threshold
(`contamination`: the share of its own training tracks it would flag; cross-fitted for an area
model), which does not depend on the test set; and, unless `ashore` is off, every track with
reports well inland (`aisdati.tracks.ashore`), which also rank first. For every track the
point of largest local deviation (the peak of its deviation profile) tells where it strays most.

Default test set (section 6.2): tracks of the `other` cluster, not used in training; `--cluster
all`: every track of the ingest.

What is written is `aisdati.detection.outputs`'s; hand labels are `aisdati.detection.labels`'s.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais import AREA_METHOD
from aisdati.ais.card import card_methods, training_mask
from aisdati.detection.labels import evaluate_labels, read_labels
from aisdati.detectors import DETECTORS, SCORES, Detector, ScoreSettings, load_detectors
from aisdati.detectors.base import score_each
from aisdati.detectors.od import track_ends
from aisdati.errors import UserError
from aisdati.execution import InProcess, Runner
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track, load_tracks, read_track_table, select_cluster


def score_settings(settings: Any, **override: Any) -> ScoreSettings:
    """The `ScoreSettings` of a command's settings (`DetectSettings`, `EvaluateSettings`): every
    field of ScoreSettings that `settings` has by the same name is taken from it, the others
    keep their defaults, and `override` has the last word."""
    names = [f.name for f in fields(ScoreSettings) if hasattr(settings, f.name)]
    return ScoreSettings(**{**{n: getattr(settings, n) for n in names}, **override})


@dataclass(frozen=True)
class DetectSettings:
    data_dir: Path
    models_dir: Path
    out_dir: Path
    models: tuple[str, ...] = ()
    """Model names (<models_dir>/<name>.json); empty: every model of `method` in the folder."""
    models_shown: str | None = None
    """How messages name the model folder: the URL its models were copied from
    (`aisdati.storage.fetched_models`); None: `models_dir`."""
    method: str | None = None
    """The detector whose models judge; None: the folder's own (`with_own_method`)."""
    cluster: str = "other"
    """Test tracks: a cluster (up, down, other), a route (route-<n>, unrouted) or all."""
    track_ids: tuple[int, ...] = ()
    """Explicit test tracks (overrides the cluster and the start rule)."""
    score: str | None = None
    """None: each judging model's own (`ModelCard.score`: lane; step for the area preset)."""
    rollouts: int = 10
    lane_rollouts: int = ScoreSettings().lane_rollouts
    lane_course_km: float = ScoreSettings().lane_course_km
    lane_traffic: bool = ScoreSettings().lane_traffic
    threshold: float = 0.75
    top_percent: float | None = None
    contamination: float | None = None
    near_km: float = 10.0
    seed: int = 0
    labels: Path | None = None
    """CSV of hand labels (track_id or mmsi + start, label 0/1) for precision/recall/F1/AUC."""
    device: str = "cpu"
    """Where DATI's networks roll out (`aisdati.execution.device`)."""
    ashore: bool = True
    """Flag tracks with reports well inland whatever their score (`aisdati.tracks.ashore`);
    False scores the paper's way, by the model alone."""

    @property
    def models_named(self) -> str | Path | None:
        """The model folder as messages name it (`models_shown`)."""
        return self.models_shown or self.models_dir

    @property
    def how(self) -> ScoreSettings:
        return score_settings(self)


EVIDENCE = {
    "rollout": "best rollout",
    "both": "best rollout",
    "steplane": "one-step predictions",
    "steptraffic": "one-step predictions",
    "lane": "best rollout",
    "area": "best rollout",
    "step": "one-step predictions",
    "steprate": "one-step predictions",
    "stepspread": "one-step predictions",
    "stepod": "one-step predictions",
    "nearest": "nearest training track",
}
"""What a track was compared with, by score (by method for `nearest`)."""
STEP_ERRORS = "one-step prediction error (m)"
PROFILES = {
    "rollout": "distance to the best rollout (m)",
    "both": STEP_ERRORS,
    "steplane": STEP_ERRORS,
    "steptraffic": STEP_ERRORS,
    "lane": "distance to the lane (m)",
    "area": "distance to the lane (m)",
    "step": STEP_ERRORS,
    "steprate": STEP_ERRORS,
    "stepspread": STEP_ERRORS,
    "stepod": STEP_ERRORS,
    "nearest": "distance to the nearest training track (m)",
}
"""What a track's profile (profiles.parquet, the evidence figures' lower panel) measures at
each report, by score (by method for `nearest`): the sums of two scores show the one-step
errors (`aisdati.detectors.policy`), `area` its lane's distances."""


NOT_JUDGED_TRAINING = "a training track of every model in reach"
NOT_JUDGED_FAR = "no model covers its start and end (none within --near-km, no area model)"


@dataclass(frozen=True)
class Coverage:
    """What became of every track of the chosen test set: judged (by which model) or not, and
    why (with the ids), so that no track leaves it uncounted."""

    candidates: int
    judged_by: dict[str, int]
    not_judged: dict[str, list[int]]

    @property
    def judged(self) -> int:
        return sum(self.judged_by.values())

    def as_dict(self) -> dict[str, Any]:
        return {
            "candidates": self.candidates,
            "judged": self.judged,
            "judged_by": self.judged_by,
            "not_judged": {k: len(v) for k, v in self.not_judged.items()},
            "not_judged_tracks": self.not_judged,
        }


@dataclass
class Detection:
    scores: pd.DataFrame
    tracks: list[Track]
    rollouts: list[np.ndarray]
    """What each track was compared with (best rollout, nearest training track or one-step
    predictions), in the order of `tracks`."""
    models: list[Detector]
    profiles: list[np.ndarray] = field(default_factory=list)
    """Each track's local deviation (m) at each of its points."""
    timings: dict[str, float] = field(default_factory=dict)
    settings: DetectSettings | None = None
    metrics: dict[str, Any] | None = None
    coverage: Coverage | None = None

    @property
    def score(self) -> str:
        """The score the tracks were judged by (`with_own_score`); `lane` for a detection made
        without settings, the score of models from before cards recorded theirs."""
        return self.settings.score if self.settings and self.settings.score else "lane"

    @property
    def evidence_kind(self) -> str:
        """What `rollouts` holds, in words (`EVIDENCE`), for legends and the GeoJSON."""
        return EVIDENCE.get(self._judged_by, "")

    @property
    def profile_kind(self) -> str:
        """What `profiles` hold, in words with their unit (`PROFILES`), for the figures."""
        return PROFILES.get(self._judged_by, "deviation (m)")

    @property
    def _judged_by(self) -> str:
        """The score the tracks were judged by, or `nearest` for that method."""
        s = self.settings
        return s.method if s and s.method == "nearest" else s.score if s else ""


# ------------------------------------------------------------------------------------ models
def with_own_method(settings: DetectSettings) -> DetectSettings:
    """Settings with a method: the given one, else the first detector the named models, or
    the folder's, are of, so that `detect` uses what `train --method` wrote without being told
    again, and names what judged a track by the models that did. The order is (dati, bc,
    nearest), but for `--cluster all` the area's default (`AREA_METHOD`) comes first: `train
    --cluster all` fits it beside routes trained by DATI, and judging the area is its job."""
    if settings.method is not None:
        return settings
    present = card_methods(settings.models_dir, settings.models)
    order = sorted(DETECTORS, key=lambda m: settings.cluster == AREA and m != AREA_METHOD)
    method = next((m for m in order if m in present), order[0])
    return replace(settings, method=method)


def load_models(settings: DetectSettings) -> list[Detector]:
    models = load_detectors(settings.models_dir, settings.models)
    if not settings.models:
        models = [m for m in models if m.method == settings.method]
        if not models:
            folder = settings.models_named
            raise UserError(
                f"no {settings.method} models in {folder}: run "
                f"`aisdati train --method {settings.method} --cluster ...` first"
            )
    for model in models:
        model.to_device(settings.device)
    return models


# --------------------------------------------------------------------------------- test set
def is_area_model(model: Detector) -> bool:
    """A model of a whole area (`--cluster all`): it judges any track of its region."""
    return model.card.cluster == AREA


def reach_km(model: Detector, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """How far (km) each track (its first and last positions) is from being bound the way the
    model's training tracks are (`Detector.od_m`: start and end, or start alone for older
    cards, the paper's rule)."""
    return model.od_m(starts, ends) / 1000.0


def route_test_tracks(
    settings: DetectSettings, models: Sequence[Detector], table: pd.DataFrame, tracks: list[Track]
) -> tuple[np.ndarray, Coverage]:
    """For each track (rows of `table`, loaded as `tracks`), the index of the model that judges
    it (-1: none) and the `Coverage`. A model never judges its own training tracks. A route or
    cluster model judges the tracks bound as its own are (`reach_km` within `near_km`), the
    nearest in reach; a track no such model reaches goes to an area model; with none, it is
    listed as not judged, with the reason. `track_ids` given: the nearest model judges."""
    n = len(tracks)
    starts, ends = track_ends([t.positions for t in tracks])
    reach = np.stack([reach_km(m, starts, ends) for m in models], axis=1)
    trained_any = np.zeros(n, dtype=bool)
    if not settings.track_ids:
        for m, model in enumerate(models):
            trained = training_mask(model.card, table)  # by vessel and time where it can
            reach[trained, m] = np.inf
            trained_any |= trained
    area = np.array([is_area_model(m) for m in models])
    local = (
        reach
        if settings.track_ids
        else np.where(area[None, :] | (reach > settings.near_km), np.inf, reach)
    )
    owner = np.where(np.isfinite(local).any(axis=1), local.argmin(axis=1), -1)
    if area.any():
        spare = np.where(area[None, :], reach, np.inf)
        fallback = np.where(np.isfinite(spare).any(axis=1), spare.argmin(axis=1), -1)
        owner = np.where(owner < 0, fallback, owner)
    ids = table["track_id"].to_numpy()
    names = [m.name for m in models]
    judged = pd.Series([names[o] for o in owner if o >= 0], dtype=object).value_counts()
    left = owner < 0
    not_judged = {
        reason: [int(i) for i in ids[mask]]
        for reason, mask in ((NOT_JUDGED_TRAINING, left & trained_any),
                             (NOT_JUDGED_FAR, left & ~trained_any))
        if mask.any()
    }  # fmt: skip
    coverage = Coverage(
        candidates=n,
        judged_by={str(k): int(v) for k, v in judged.sort_index().items()},
        not_judged=not_judged,
    )
    return owner, coverage


def candidate_table(settings: DetectSettings) -> pd.DataFrame:
    """The chosen test set's rows of tracks.parquet (`track_ids`, a cluster, or all)."""
    table = read_track_table(settings.data_dir)
    if settings.track_ids:
        missing = set(settings.track_ids) - set(table["track_id"])
        if missing:
            raise UserError(f"tracks not in {settings.data_dir}: {sorted(missing)[:5]}")
        return table[table["track_id"].isin(settings.track_ids)]
    if settings.cluster != AREA:
        return select_cluster(table, settings.cluster, settings.data_dir, needed=1)
    return table


def check_region(models: Sequence[Detector], tracks: Sequence[Track]) -> None:
    """Refuse models of another region, in one line."""
    starts = np.array([t.positions[0] for t in tracks])
    inside = np.zeros(len(tracks), dtype=bool)
    for model in models:
        inside |= model.contains(starts)
    if not inside.any():
        lo, hi = models[0].bounds
        raise UserError(
            f"no test track starts inside the model's region (lon {lo[0]:.2f}..{hi[0]:.2f}, "
            f"lat {lo[1]:.2f}..{hi[1]:.2f}): is the model from another region?"
        )


def flag(scores: np.ndarray, threshold: float, top_percent: float | None) -> np.ndarray:
    if top_percent is not None:
        count = math.ceil(len(scores) * top_percent / 100.0)
        order = np.argsort(-scores, kind="stable")
        flagged = np.zeros(len(scores), dtype=bool)
        flagged[order[:count]] = True
        return flagged
    return scores > threshold


def check_settings(settings: DetectSettings) -> None:
    if not (0.0 < settings.threshold <= 1.0):
        raise UserError(f"--threshold must be in (0, 1], got {settings.threshold:g}")
    if settings.top_percent is not None and not (0.0 < settings.top_percent <= 100.0):
        raise UserError(f"--top-percent must be in (0, 100], got {settings.top_percent:g}")
    if settings.contamination is not None and not (0.0 < settings.contamination < 1.0):
        raise UserError(f"--contamination must be in (0, 1), got {settings.contamination:g}")
    if settings.top_percent is not None and settings.contamination is not None:
        raise UserError("give --top-percent or --contamination, not both")
    if settings.rollouts < 1 or settings.lane_rollouts < 1:
        raise UserError(
            f"--rollouts and --lane-rollouts must be at least 1, got {settings.rollouts} and "
            f"{settings.lane_rollouts}"
        )
    if not settings.near_km > 0:
        raise UserError(f"--near-km must be positive, got {settings.near_km:g}")
    if settings.score is not None and settings.score not in SCORES:
        raise UserError(f"--score must be one of {', '.join(SCORES)}, got {settings.score!r}")


def with_own_score(settings: DetectSettings, models: Sequence[Detector]) -> DetectSettings:
    """`settings` with the score it judges by: `--score`'s, or else the judging models' own
    (`ModelCard.score`), which must agree: scores of different kinds are not comparable."""
    if settings.score is not None:
        return settings
    own = sorted({m.card.score for m in models})
    if len(own) > 1:
        names = {s: ", ".join(m.name for m in models if m.card.score == s) for s in own}
        by = "; ".join(f"{s}: {n}" for s, n in names.items())
        raise UserError(f"the judging models score differently ({by}): pass --score")
    return replace(settings, score=own[0] if own else "lane")


def detect(settings: DetectSettings, runner: Runner | None = None) -> Detection:
    """Score the test tracks (in chunks, as tasks of `runner`: `Detector.score`); see the
    module docstring."""
    check_settings(settings)
    if settings.labels is not None:
        read_labels(settings.labels)  # fail on a bad file before the scoring
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    settings = with_own_method(settings)
    models = load_models(settings)
    table = candidate_table(settings)
    candidates = load_tracks(settings.data_dir, [int(i) for i in table["track_id"]])
    check_region(models, candidates)
    owners, coverage = route_test_tracks(settings, models, table, candidates)
    if coverage.judged == 0:
        raise UserError(
            f"no test track is judged by any model ({', '.join(coverage.not_judged)}): train an "
            "area model (`aisdati train --cluster all`), raise --near-km, or pass --cluster all"
        )
    tracks = [t for t, o in zip(candidates, owners, strict=True) if o >= 0]
    owner = [int(o) for o in owners if o >= 0]
    settings = with_own_score(settings, [models[m] for m in sorted(set(owner))])
    timings["load_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    raw, threshold, evidence, profiles = _score_by_model(settings, models, tracks, owner, runner)
    timings["score_s"] = time.perf_counter() - t1
    n = len(tracks)
    top = float(np.max(raw)) if n else 1.0
    norm = raw / top if top > 0 else np.zeros(n)
    if settings.contamination is not None:
        flagged = raw > threshold
    else:
        flagged = flag(norm, settings.threshold, settings.top_percent)
    check = AshoreCheck()
    ashore = np.zeros(n, np.int64)
    if settings.ashore:
        ashore = ashore_counts(models, tracks, owner, runner)
    flagged = flagged | check.flags(ashore)
    lengths = np.array([len(t.positions) for t in tracks])
    order = np.argsort(-check.ranked(norm, ashore, lengths), kind="stable")
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(1, n + 1)
    peak = [int(np.argmax(p)) for p in profiles]
    scores = pd.DataFrame(
        {
            "track_id": [t.track_id for t in tracks],
            "mmsi": [t.mmsi for t in tracks],
            "model": [models[o].name for o in owner],
            "n_points": lengths,
            "score_m": raw,
            "score": norm,
            "flagged": flagged,
            "rank": rank,
            "max_dev_m": [float(p[k]) for p, k in zip(profiles, peak, strict=True)],
            "max_dev_lon": [t.positions[k, 0] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_lat": [t.positions[k, 1] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_index": peak,
            "ashore_reports": ashore,
        }
    )
    timings["total_s"] = time.perf_counter() - t0
    result = Detection(
        scores, tracks, evidence, models, profiles, timings, settings, coverage=coverage
    )
    if settings.labels is not None:
        result.metrics = evaluate_labels(scores, tracks, settings.labels)
    return result


ASHORE_TRACKS = 1024
"""Tracks per task of the ashore check (`ashore_counts`): ~2 M reports/s, so a task of 1,024
tracks of a few hundred reports takes a fraction of a second, well above a task's overhead."""


def ashore_counts(
    models: Sequence[Detector],
    tracks: Sequence[Track],
    owner: Sequence[int],
    runner: Runner | None = None,
) -> np.ndarray:
    """Each track's reports ashore (`aisdati.tracks.ashore`), excusing the water that its
    judging model's training traffic sailed; in chunks of `ASHORE_TRACKS`, as tasks of
    `runner` (default: here)."""
    out = np.zeros(len(tracks), np.int64)
    if not AshoreCheck.available():
        warnings.warn(
            "the ashore rule is off: only the coarse fallback coastline is installed (pip "
            "install roaring-landmask for the harbour-scale one)",
            RuntimeWarning,
            stacklevel=2,
        )
        return out
    owner_of = np.asarray(owner, np.int64)
    rows = []
    jobs = []
    for m in np.unique(owner_of):
        mine = np.flatnonzero(owner_of == m)
        for lo in range(0, len(mine), ASHORE_TRACKS):
            rows.append(mine[lo : lo + ASHORE_TRACKS])
            jobs.append((models[m].ashore_points, [tracks[i].positions for i in rows[-1]]))
    for idx, counts in zip(rows, (runner or InProcess()).map(ashore_job, jobs), strict=True):
        out[idx] = counts
    return out


def ashore_job(job: tuple[np.ndarray, list[np.ndarray]]) -> np.ndarray:
    """One task of `ashore_counts`: (seen water, positions of each track) -> counts."""
    seen, positions = job
    return AshoreCheck().counts(positions, seen)


def _score_by_model(
    settings: DetectSettings,
    models: Sequence[Detector],
    tracks: list[Track],
    owner: list[int],
    runner: Runner | None,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Each track scored by the model that judges it: (score in metres, that model's calibrated
    threshold or NaN without `contamination`, evidence, deviation profile), in track order."""
    n = len(tracks)
    raw = np.full(n, np.nan)
    threshold = np.full(n, np.nan)
    evidence: list[np.ndarray] = [np.empty((0, 2))] * n
    profiles: list[np.ndarray] = [np.empty(0)] * n
    used = sorted({int(o) for o in owner})
    cut: dict[int, float] = {}  # calibrated thresholds, before any scoring: fail fast
    if settings.contamination is not None:
        for m in used:
            cut[m] = models[m].threshold(settings.how, settings.contamination)
    rows = {m: [i for i in range(n) if owner[i] == m] for m in used}
    scored = score_each(
        [(models[m], [tracks[i] for i in rows[m]]) for m in used], settings.how, (), runner
    )
    for m, got in zip(used, scored, strict=True):
        idx = rows[m]
        if settings.contamination is not None:
            threshold[idx] = cut[m]
        for j, i in enumerate(idx):
            raw[i] = got.score_m[j]
            evidence[i] = got.evidence[j]
            profiles[i] = got.profiles[j]
    return raw, threshold, evidence, profiles
