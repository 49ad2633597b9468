"""Detection of abnormal tracks (section 6.2 of the paper): scores -> flags.

Each test track goes to a model (`route_test_tracks`): the route or cluster model whose
training tracks are bound as it is (start and end within `near_km`; the paper's rule, by start
alone, for cards that do not record where their tracks end), else an area model (`--cluster
all`), which judges any track; a track no model covers is listed with the reason, never dropped
unsaid. The model's detector (`aisdati.detectors`) scores it by the model's own score (its card
says which) or `--score`. Higher means more abnormal.

Flags (`FlagRule`): by default each score above its model's calibrated threshold (the share
`contamination` of its own training tracks it would flag; cross-fitted for an area model), so a
track's flag never depends on the other tracks judged with it. Asked for: the paper's rule,
scores over their maximum in the judged batch above `threshold` (Λ = 0.75), or the
`top_percent` highest. Unless `ashore` is off, every track with reports well inland
(`aisdati.tracks.ashore`) is flagged too and ranks first. For every track the point of largest
local deviation (the peak of its deviation profile) tells where it strays most.

Default test set (section 6.2): tracks of the `other` cluster, not used in training; `--cluster
all`: every track of the ingest.

What is written is `aisdati.detection.outputs`'s; hand labels are `aisdati.detection.labels`'s.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais import AREA_METHOD
from aisdati.ais.card import card_methods
from aisdati.detection.events import (
    all_events,
    empty_events,
    event_rules,
    judged_reports,
    judged_windows,
    model_free_events,
    off_traffic_events,
    uncalibrated_note,
    unseen_route_events,
    with_events,
    with_identity,
    within,
)
from aisdati.detection.labels import evaluate_labels, read_labels
from aisdati.detection.routing import Coverage, check_region, route_test_tracks
from aisdati.detectors import DETECTORS, Detector, ScoreSettings, load_detectors
from aisdati.detectors.base import DEFAULT_CONTAMINATION, score_each
from aisdati.errors import UserError
from aisdati.events.anchorages import Anchorages, area_ports
from aisdati.events.budget import ALERTS_PER_1000
from aisdati.events.rules import EventRules
from aisdati.execution import Runner
from aisdati.options import Range
from aisdati.scores import NEAREST, SCORES, Score, score
from aisdati.tracks.ashore import AshoreCheck, ashore_counts
from aisdati.tracks.reports import motion_derived, read_identities, read_reports, read_vessels
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track, load_tracks, read_track_table, select_cluster


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
    """Explicit test tracks instead of a cluster (judged by the same rules: a model does not
    judge its own training tracks, nor tracks out of its reach)."""
    score: str | None = None
    """None: each judging model's own (`ModelCard.score`: lane; step for the area preset)."""
    threshold: float | None = None
    """The paper's rule: flag scores over the batch's largest above this (Λ); asked for only."""
    top_percent: float | None = None
    contamination: float = DEFAULT_CONTAMINATION
    """The calibrated rule, the default: each model's threshold flags this share of its own
    training tracks."""
    near_km: float = 10.0
    labels: Path | None = None
    """CSV of hand labels (track_id or mmsi + start, label 0/1) for precision/recall/F1/AUC."""
    device: str = "cpu"
    """Where DATI's networks roll out (`aisdati.execution.device`)."""
    ashore: bool = True
    """Flag tracks with reports well inland whatever their score (`aisdati.tracks.ashore`);
    False scores the paper's way, by the model alone."""
    alerts_per_1000: float = ALERTS_PER_1000
    """The alert budget (`aisdati.events.budget`): the model-free alerts per 1,000
    vessel-days the models' training periods would have raised."""
    ports: Path | None = None
    """Ports and anchorages as GeoJSON (`aisdati.events.anchorages.read_ports`); None: learned
    from `data_dir`'s traffic."""

    @property
    def models_named(self) -> str | Path | None:
        """The model folder as messages name it (`models_shown`)."""
        return self.models_shown or self.models_dir

    @property
    def rule(self) -> str:
        """How tracks are flagged: `calibrated` (the default), `relative` (`--threshold`, the
        paper's) or `top` (`--top-percent`)."""
        if self.top_percent is not None:
            return "top"
        return "calibrated" if self.threshold is None else "relative"

    def how_for(self, model: Detector) -> ScoreSettings:
        """How `model` scores: the judging score, with the lane settings its calibration was
        computed with (`load_detector` reads them from its card), so that its threshold
        holds."""
        return replace(model.how, score=self.score or model.card.score)


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
    notes: list[str] = field(default_factory=list)
    """Warnings about the run itself (`small_batch_note`), printed and in report.json."""
    events: pd.DataFrame = field(default_factory=empty_events)
    """What happened (`aisdati.detection.events`): one row per event, `EVENT_COLUMNS`."""
    reports_judged: int = 0
    ports: Anchorages | None = None
    """The ports and anchorages the events were judged by (anchorages.geojson)."""

    @property
    def score(self) -> str:
        """The score the tracks were judged by (`with_own_score`); `lane` for a detection made
        without settings, the score of models from before cards recorded theirs."""
        return self.settings.score if self.settings and self.settings.score else "lane"

    @property
    def judged_by(self) -> Score:
        """The score the tracks were judged by (`aisdati.scores`)."""
        return score(self.score)

    @property
    def evidence_kind(self) -> str:
        """What `rollouts` holds, in words, for legends and the GeoJSON: the judging score's
        evidence; for `nearest`, whatever the score, the nearest training track."""
        return NEAREST.evidence if self.by_nearest else self.judged_by.evidence

    @property
    def profile_kind(self) -> str:
        """What `profiles` hold, in words with their unit, for the figures."""
        return NEAREST.profile if self.by_nearest else self.judged_by.profile

    @property
    def by_nearest(self) -> bool:
        return self.settings is not None and self.settings.method == "nearest"


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
    models = load_detectors(settings.models_dir, settings.models, settings.cluster)
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


MIN_RELATIVE_BATCH = 10
"""Fewest judged tracks for which a batch-relative rule (`--threshold`, `--top-percent`) flags
without a warning: over fewer, the batch says little of what is normal (a lone track is always
its own maximum, so `--threshold` flags it)."""


def small_batch_note(n: int, settings: DetectSettings) -> str | None:
    """The warning a batch-relative rule over fewer than `MIN_RELATIVE_BATCH` tracks earns."""
    if settings.rule == "calibrated" or n >= MIN_RELATIVE_BATCH:
        return None
    option = "--threshold" if settings.rule == "relative" else "--top-percent"
    return (
        f"{option} flags relative to the judged batch, and {n} judged track(s) are too few to "
        f"say what is normal (at least {MIN_RELATIVE_BATCH}): leave it out to flag by the "
        "models' calibrated thresholds"
    )


def relative_thresholds(raw: np.ndarray, settings: DetectSettings) -> np.ndarray:
    """[N] the threshold of a batch-relative rule in each score's unit: Λ x the batch's largest
    score (`--threshold`), or just below the score of the `top_percent`-th highest track."""
    n = len(raw)
    if settings.rule == "relative":
        return np.full(n, settings.threshold * float(np.max(raw)))
    count = math.ceil(n * settings.top_percent / 100.0)
    kth = float(np.sort(raw)[::-1][count - 1])
    return np.full(n, np.nextafter(kth, -np.inf))


def check_settings(settings: DetectSettings) -> None:
    if settings.threshold is not None and not (0.0 < settings.threshold <= 1.0):
        raise UserError(f"--threshold must be in (0, 1], got {settings.threshold:g}")
    if settings.top_percent is not None and not (0.0 < settings.top_percent <= 100.0):
        raise UserError(f"--top-percent must be in (0, 100], got {settings.top_percent:g}")
    if not (0.0 < settings.contamination < 1.0):
        raise UserError(f"--contamination must be in (0, 1), got {settings.contamination:g}")
    if settings.top_percent is not None and settings.threshold is not None:
        raise UserError("give --threshold or --top-percent, not both")
    if not Range(low=0.0, low_open=True).accepts(settings.alerts_per_1000):
        raise UserError(
            f"--alerts-per-1000 must be a finite number > 0, got {settings.alerts_per_1000:g}"
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
    t0 = time.perf_counter()
    settings, models, tracks, owner, coverage = judged_tracks(settings)
    timings = {"load_s": time.perf_counter() - t0}
    t1 = time.perf_counter()
    raw, threshold, evidence, profiles = _score_by_model(settings, models, tracks, owner, runner)
    timings["score_s"] = time.perf_counter() - t1
    if settings.rule != "calibrated":
        threshold = relative_thresholds(raw, settings)
    ashore = np.zeros(len(tracks), np.int64)
    if settings.ashore:
        seen = [m.card.data.ashore for m in models]
        ashore = ashore_counts(seen, [t.positions for t in tracks], owner, runner)
    names = [models[o].name for o in owner]
    scores = score_table(tracks, names, raw, threshold, profiles, ashore)
    t2 = time.perf_counter()
    identity = read_vessels(settings.data_dir)
    events, judged, ports = _events(settings, models, tracks, scores, profiles, coverage, identity)
    scores = with_identity(with_events(scores, events), identity)
    timings["events_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0
    judging = [m for m in models if m.name in set(scores["model"])]
    notes = [small_batch_note(len(tracks), settings), uncalibrated_note(judging)]
    result = Detection(
        scores, tracks, evidence, models, profiles, timings, settings, coverage=coverage,
        notes=[n for n in notes if n], events=events, reports_judged=judged, ports=ports,
    )  # fmt: skip
    if settings.labels is not None:
        result.metrics = evaluate_labels(scores, tracks, settings.labels)
    return result


def _events(
    settings: DetectSettings,
    models: Sequence[Detector],
    tracks: list[Track],
    scores: pd.DataFrame,
    profiles: Sequence[np.ndarray],
    coverage: Coverage,
    identity: pd.DataFrame,
) -> tuple[pd.DataFrame, int, Anchorages]:
    """The detection's events (`aisdati.detection.events`), the reports they judged
    (`identity`: vessels.parquet) and the ports and anchorages they were judged by."""
    every = settings.cluster == AREA and not settings.track_ids
    windows = judged_windows(tracks, every)
    reports = judged_reports(settings.data_dir, windows)
    judging = [m for m in models if m.name in set(scores["model"])]
    rules = event_rules(
        judging, settings.alerts_per_1000, not motion_derived(settings.data_dir),
        area_ports(settings.data_dir, settings.ports),
    )  # fmt: skip
    free = model_free_events(reports, identity, rules, read_identities(settings.data_dir))
    free = within(free, windows, coverage.training)
    if not settings.ashore:
        free = free[free["kind"] != "ashore"]
    learned = off_traffic_events(tracks, scores, profiles, identity)
    unseen = unseen_route_events(tracks, scores, models, identity, settings.near_km)
    judged = within(reports.assign(start=reports["time"], end=reports["time"]), windows,
                    coverage.training)  # fmt: skip
    return all_events([learned, unseen, free]), len(judged), rules.ports


def events_only(data_dir: Path, ports: Path | None = None) -> Detection:
    """The events that need no model (`aisdati.events.kinds.MODEL_FREE` and `FLEET`) over
    every report of an ingest output: `detect --models none` (`ports`: GeoJSON of its ports
    and anchorages; None: learned from its traffic)."""
    t0 = time.perf_counter()
    reports = read_reports(data_dir)
    rules = EventRules(
        reported_motion=not motion_derived(data_dir), ports=area_ports(data_dir, ports)
    )
    free = model_free_events(reports, read_vessels(data_dir), rules, read_identities(data_dir))
    events = all_events([free])
    scores = pd.DataFrame(columns=list(SCORE_COLUMNS))
    timings = {"events_s": time.perf_counter() - t0, "score_s": 0.0}
    judged = len(reports)
    return Detection(
        scores, [], [], [], timings=timings, events=events, reports_judged=judged,
        ports=rules.ports,
    )  # fmt: skip


def judged_tracks(
    settings: DetectSettings,
) -> tuple[DetectSettings, list[Detector], list[Track], list[int], Coverage]:
    """The models, the tracks they judge and which model judges each (`route_test_tracks`),
    the coverage, and the settings with the method and score that judge; none judged is one
    line that says what would judge them."""
    settings = with_own_method(settings)
    models = load_models(settings)
    table = candidate_table(settings)
    candidates = load_tracks(settings.data_dir, [int(i) for i in table["track_id"]])
    check_region(models, candidates)
    owners, coverage = route_test_tracks(models, table, candidates, settings.near_km)
    if coverage.judged == 0:
        raise UserError(
            f"no test track is judged by any model ({', '.join(coverage.not_judged)}): train an "
            "area model (`aisdati train --cluster all`), raise --near-km, or pass --cluster all"
        )
    tracks = [t for t, o in zip(candidates, owners, strict=True) if o >= 0]
    owner = [int(o) for o in owners if o >= 0]
    settings = with_own_score(settings, [models[m] for m in sorted(set(owner))])
    return settings, models, tracks, owner, coverage


SCORE_COLUMNS = (
    "track_id", "mmsi", "model", "n_points", "score", "threshold", "flagged", "rank",
    "max_dev_m", "max_dev_lon", "max_dev_lat", "max_dev_index", "ashore_reports", "events",
    "alerts", "event_kinds", "name", "ship_type",
)  # fmt: skip
"""scores.parquet's columns (`aisdati.detection.outputs.SCORES_SCHEMA`)."""


def score_table(
    tracks: Sequence[Track],
    models: Sequence[str],
    raw: np.ndarray,
    threshold: np.ndarray,
    profiles: Sequence[np.ndarray],
    ashore: np.ndarray,
) -> pd.DataFrame:
    """scores.parquet's rows (`aisdati.detection.outputs.SCORES_SCHEMA`): each track flagged
    above its threshold or for reports ashore, ranked (reports ashore first), with the point
    where it strays most (the peak of its profile)."""
    check = AshoreCheck()
    lengths = np.array([len(t.positions) for t in tracks])
    top = float(np.max(raw)) if len(raw) else 1.0
    order = np.argsort(-check.ranked(raw / top if top > 0 else raw, ashore, lengths), kind="stable")
    rank = np.empty(len(tracks), dtype=np.int64)
    rank[order] = np.arange(1, len(tracks) + 1)
    peak = [int(np.argmax(p)) for p in profiles]
    return pd.DataFrame(
        {
            "track_id": [t.track_id for t in tracks],
            "mmsi": [t.mmsi for t in tracks],
            "model": list(models),
            "n_points": lengths,
            "score": raw,
            "threshold": threshold,
            "flagged": (raw > threshold) | check.flags(ashore),
            "rank": rank,
            "max_dev_m": [float(p[k]) for p, k in zip(profiles, peak, strict=True)],
            "max_dev_lon": [t.positions[k, 0] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_lat": [t.positions[k, 1] for t, k in zip(tracks, peak, strict=True)],
            "max_dev_index": peak,
            "ashore_reports": ashore,
        }
    )


def _score_by_model(
    settings: DetectSettings,
    models: Sequence[Detector],
    tracks: list[Track],
    owner: list[int],
    runner: Runner | None,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Each track scored by the model that judges it: (score, that model's calibrated
    threshold, evidence, deviation profile), in track order."""
    n = len(tracks)
    raw = np.full(n, np.nan)
    threshold = np.full(n, np.nan)
    evidence: list[np.ndarray] = [np.empty((0, 2))] * n
    profiles: list[np.ndarray] = [np.empty(0)] * n
    used = sorted({int(o) for o in owner})
    how = {m: settings.how_for(models[m]) for m in used}
    cut: dict[int, float] = {}  # calibrated thresholds, before any scoring: fail fast
    if settings.rule == "calibrated":
        for m in used:
            cut[m] = models[m].threshold(how[m], settings.contamination)
    rows = {m: [i for i in range(n) if owner[i] == m] for m in used}
    jobs = [(models[m], [tracks[i] for i in rows[m]], how[m]) for m in used]
    scored = score_each(jobs, (), runner)
    for m, got in zip(used, scored, strict=True):
        idx = rows[m]
        threshold[idx] = cut.get(m, np.nan)
        for j, i in enumerate(idx):
            raw[i] = got.score[j]
            evidence[i] = got.evidence[j]
            profiles[i] = got.profiles[j]
    return raw, threshold, evidence, profiles
