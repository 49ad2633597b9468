"""`aisdati evaluate`: a detection benchmark on the user's own ingested data.

1. Split one cluster's (or route's, or the whole area's: `all`) tracks by vessel into training
   and held-out sets (seeded), or by time (`before` given: the tracks that start before
   `before` train, every later one is judged: the forward protocol), or take the training set
   from existing model cards (`models_dir`).
2. Write anomalies of the chosen kinds (at `strength` x their usual distances) into a seeded
   share (`altered`, half by default) of the held-out tracks
   (`aisdati.evaluation.inject`); save everything in ingest's schema under `<out>/data`.
3. Train every detector asked for on the training tracks (`<out>/models`), or load it.
4. Score the held-out tracks and report, per detector, score and anomaly kind: ROC AUC, average
   precision, precision / recall / F1 at the detector's calibrated flagging rule (the
   (1 - contamination) quantile of its training tracks' scores), and the median score of normal
   and altered tracks. Policy detectors (dati, bc) are scored every way (rollout, step, lane,
   stepspread) in one scoring pass. For them the median normal rollout score is the *lane
   fidelity*: how far (mean metres along the DTW path) the best of K rollouts stays from unseen
   normal tracks.
5. Find the held-out tracks' events as `aisdati detect` does (`aisdati.evaluation.events`:
   the model-free kinds, and off-traffic from each detector's `DETECT_SCORE`) and report, per
   detector and kind, how they find the injected stretches (`event_metrics`).
6. The fleet kinds asked (`fleet_kinds`): cases constructed in the area's untouched later
   traffic, their recall, and the same kinds' events on that traffic per 1,000 vessel-days
   (`aisdati.evaluation.fleet`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais import DEFAULT_PRESET
from aisdati.ais.space import PRESETS, LaneConfig
from aisdati.ais.training import TrainSettings
from aisdati.detectors import DETECTORS, Detector, ScoreSettings, load_detector, model_name
from aisdati.errors import UserError
from aisdati.evaluation import dataset
from aisdati.evaluation.events import forward_alerts, model_free, on_reports, with_off_traffic
from aisdati.evaluation.fleet import FleetSettings, measure, read_area
from aisdati.evaluation.inject import parse_params, with_strength
from aisdati.evaluation.metrics import event_metrics
from aisdati.execution import Runner
from aisdati.metrics import flagging, ranking
from aisdati.scores import score
from aisdati.tracks.ashore import AshoreCheck, ashore_counts
from aisdati.tracks.store import load_tracks, read_track_table, routes_with, select_cluster

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
    contamination: float = 0.05
    models_dir: Path | None = None
    models_shown: str | None = None
    """How messages name the model folder: the URL its models were copied from
    (`aisdati.storage.fetched_models`); None: `models_dir`."""
    preset: str = DEFAULT_PRESET
    lane: LaneConfig = field(default_factory=lambda: PRESETS[DEFAULT_PRESET])
    before: pd.Timestamp | None = None
    """None: split by vessel (held-out vessels, seeded); a time: the tracks from then on are
    judged, forward in time."""
    altered: float = 0.5
    """Share of the held-out tracks that take an anomaly."""
    strength: float = 1.0
    """Anomaly distances x this (`aisdati.evaluation.inject.with_strength`; 0.3: subtle)."""
    device: str = "cpu"
    """Where DATI's networks train and score (`aisdati.execution.device`)."""
    ashore: bool = True
    """Every detector's flags and ranking go through the ashore rule (`aisdati.tracks.ashore`);
    False: the models' scores alone, the paper's way."""
    at_sea: bool = False
    """Write only anomalies that put no more reports ashore than their track had
    (`aisdati.evaluation.dataset`): what a vessel could sail, which the ashore rule cannot see."""
    thin_s: float | None = None
    """Every track thinned to one report per this many seconds before injection; None: all."""
    fleet_kinds: tuple[str, ...] = ()
    """Fleet cases constructed and measured (`aisdati.evaluation.fleet`); (): none."""
    fleet_cases: int = 20
    """Fleet cases asked per kind (`seed` the one seed)."""

    @property
    def models_named(self) -> str | Path | None:
        """The model folder as messages name it (`models_shown`)."""
        return self.models_shown or self.models_dir

    @property
    def split(self) -> str:
        """vessel or time (`before` given)."""
        return "vessel" if self.before is None else "time"

    @property
    def anomaly_params(self) -> dict[str, Any]:
        return with_strength(self.params or parse_params(None), self.strength)


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
    events: pd.DataFrame = field(default_factory=pd.DataFrame)
    """The held-out tracks' events per detector: `detector` and `EVENT_FIELDS`."""
    event_table: pd.DataFrame = field(default_factory=pd.DataFrame)
    """One row per detector x injected kind (`event_metrics`), and 'any'."""
    alerts: dict[str, Any] | None = None
    """With `before`: the measure of record on the untouched later traffic
    (`aisdati.evaluation.events.forward_alerts`)."""
    fleet: dict[str, Any] | None = None
    """With `fleet_kinds`: the fleet kinds' recall and untouched events (`fleet_measure`)."""


def check(settings: EvaluateSettings) -> None:
    if not 0.1 <= settings.train_fraction <= 0.9:
        raise UserError(f"--train-fraction must be in [0.1, 0.9], got {settings.train_fraction:g}")
    if not 0.0 < settings.contamination < 0.5:
        raise UserError(f"--contamination must be in (0, 0.5), got {settings.contamination:g}")
    if settings.episodes < 1:
        raise UserError("--episodes must be at least 1")
    if settings.fleet_cases < 1:
        raise UserError(f"--fleet-cases must be at least 1, got {settings.fleet_cases}")
    if not 0.05 <= settings.altered <= 0.95:
        raise UserError(f"--altered must be in [0.05, 0.95], got {settings.altered:g}")
    with_strength({}, settings.strength)  # a --strength out of range fails here


def _load(stem: Path, settings: EvaluateSettings) -> Detector:
    """The detector saved at `stem`, on the evaluation's device."""
    det = load_detector(stem)
    det.to_device(settings.device)
    return det


def _existing(settings: EvaluateSettings) -> dict[str, Detector]:
    """Detectors of `models_dir` trained on this cluster, by method."""
    found: dict[str, Detector] = {}
    if settings.models_dir is None:
        return found
    for method in settings.detectors:
        stem = settings.models_dir / model_name(settings.cluster, method)
        if stem.with_suffix(".json").is_file():
            found[method] = _load(stem, settings)
    if not found:
        raise UserError(
            f"no model of cluster {settings.cluster!r} for {', '.join(settings.detectors)} in "
            f"{settings.models_named}"
        )
    return found


def _same_region(settings: EvaluateSettings, models: dict[str, Detector]) -> None:
    """Models given with --models must come from the area of the data they are evaluated on."""
    table = select_cluster(read_track_table(settings.data_dir), settings.cluster, settings.data_dir)
    ids = [int(i) for i in table["track_id"]]
    starts = np.array([t.positions[0] for t in load_tracks(settings.data_dir, ids)])
    for method, det in models.items():
        if not det.card.region.contains(starts).any():
            lo, hi = det.card.region.bounds
            raise UserError(
                f"the {method} model in {settings.models_named} was "
                "trained on another region "
                f"(lon {lo[0]:.2f}..{hi[0]:.2f}, lat {lo[1]:.2f}..{hi[1]:.2f}): no track of "
                f"{settings.cluster!r} starts there"
            )


@dataclass
class _Prepared:
    """One group's split, injected and written, with the models given for it."""

    settings: EvaluateSettings
    split: dataset.Split
    existing: dict[str, Detector]

    @property
    def data(self) -> Path:
        return self.settings.out_dir / "data"

    def train_settings(self) -> TrainSettings:
        s = self.settings
        return TrainSettings(
            data_dir=self.data,
            cluster=s.cluster,
            out_dir=s.out_dir / "models",
            episodes=s.episodes,
            seed=s.seed,
            max_tracks=None,
            track_ids=tuple(self.split.train_ids),
            preset=s.preset,
            lane=s.lane,
            device=s.device,
        )


HOW = ScoreSettings(score="rollout")
"""How the held-out tracks are scored: as `detect` scores (the default settings), every score
in one pass (`scored_kinds`)."""


def _checked_models(settings: EvaluateSettings) -> dict[str, Detector]:
    """The models given with --models, checked (region, calibration) before any work, so a
    folder found wanting is one line before the first progress line."""
    existing = _existing(settings)
    if existing:
        _same_region(settings, existing)
        for det in existing.values():  # calibrated as this run scores
            det.threshold(replace(HOW, score="lane"), settings.contamination)
    return existing


def _prepare(settings: EvaluateSettings, existing: dict[str, Detector]) -> _Prepared:
    train_ids = None
    if existing:
        train_ids = [int(i) for i in next(iter(existing.values())).card.data.track_ids]
    split = dataset.build(
        settings.data_dir,
        settings.cluster,
        settings.out_dir / "data",
        settings.kinds,
        settings.anomaly_params,
        settings.train_fraction,
        settings.seed,
        train_ids,
        settings.before,
        settings.altered,
        settings.at_sea,
        settings.thin_s,
    )
    return _Prepared(settings, split, existing)


def evaluate(
    settings: EvaluateSettings,
    on_stage: Callable[[str], None] | None = None,
    train_detector: Callable[..., Any] | None = None,
    runner: Runner | None = None,
) -> Evaluation:
    """Run the benchmark; `train_detector(method, TrainSettings, ScoreSettings)` trains one
    detector (the CLI passes one with progress bars); the held-out tracks are scored as tasks
    of `runner` (`Detector.score`)."""
    from aisdati.detectors.train import train_detector as plain_train

    check(settings)
    train = train_detector or plain_train
    say = on_stage or (lambda _: None)
    existing = _checked_models(settings)
    say("splitting and injecting")
    prepared = _prepare(settings, existing)
    detectors: dict[str, Detector] = {}
    train_s: dict[str, float] = {}
    for method in settings.detectors:
        t0 = time.perf_counter()
        if method in prepared.existing:
            detectors[method] = prepared.existing[method]
        else:
            say(f"training {method}")
            trained = train(method, prepared.train_settings(), HOW)
            detectors[method] = _load(trained.model.with_suffix(""), settings)
        train_s[method] = time.perf_counter() - t0
    result = _score(prepared, detectors, train_s, say, runner)
    result.fleet = fleet_measure(settings, say)
    return result


def _score(
    prepared: _Prepared,
    detectors: dict[str, Detector],
    train_s: dict[str, float],
    say: Callable[[str], None],
    runner: Runner | None,
) -> Evaluation:
    """Score the held-out tracks with every detector and tabulate (see the module docstring)."""
    settings, split = prepared.settings, prepared.split
    heldout = load_tracks(prepared.data, split.heldout_ids)
    labels = split.labels.set_index("track_id").loc[split.heldout_ids]
    rule = AshoreCheck()
    lengths = np.array([len(t.positions) for t in heldout])
    per_track = []
    timings: dict[str, dict[str, float]] = {}
    rows, score_rows = [], []
    result = Evaluation(settings, split, pd.DataFrame(), pd.DataFrame(), timings, detectors)
    for method in settings.detectors:
        det = detectors[method]
        how = replace(HOW, reported_motion=det.how.reported_motion)  # as its card calibrated
        t1 = time.perf_counter()
        say(f"scoring {settings.cluster} with {method}")
        kinds = scored_kinds(det)
        scored = det.score(heldout, how, also=kinds, runner=runner)
        timings[method] = {"train_s": train_s[method], "score_s": time.perf_counter() - t1}
        ashore = np.zeros(len(heldout), np.int64)
        if settings.ashore:
            seen = [det.card.data.ashore]
            ashore = ashore_counts(seen, [t.positions for t in heldout], [0] * len(heldout), runner)
        per_track.append(pd.DataFrame({"detector": method, "track_id": split.heldout_ids,
                                       "n_points": lengths, "ashore_reports": ashore}))  # fmt: skip
        for kind in kinds:
            values = scored.parts[kind]
            threshold = det.threshold(replace(how, score=kind), settings.contamination)
            flagged = (values > threshold) | rule.flags(ashore)
            ranked = rule.ranked(values, ashore, lengths)
            key = (method, kind)
            result.profiles[key] = scored.profiles
            result.evidence[key] = scored.evidence
            for tid, v, f in zip(split.heldout_ids, values, flagged, strict=True):
                score_rows.append((method, kind, tid, float(v), float(threshold), bool(f)))
            unit = score(kind).unit
            rows += _rows(
                method, kind, labels, values, ranked, flagged, threshold, settings.kinds, unit
            )
    result.table = pd.DataFrame(rows)
    columns = ["detector", "score", "track_id", "value", "threshold", "flagged"]
    scores = pd.DataFrame(score_rows, columns=columns)
    scores = scores.merge(pd.concat(per_track), on=["detector", "track_id"], how="left")
    result.scores = scores.merge(split.labels, on="track_id", how="left")
    say("finding events")
    result.events = _events(prepared, detectors, heldout, result)
    result.event_table = _event_table(result.events, split.labels, settings)
    if settings.before is not None:
        say("counting alerts on the untouched later traffic")
        result.alerts = forward_alerts(settings.data_dir, settings.before, list(detectors.values()))
    return result


def fleet_measure(settings: EvaluateSettings, say: Callable[[str], None]) -> dict[str, Any] | None:
    """The fleet kinds asked measured on the area's untouched later traffic (from `before`, else
    from the middle of its time span: `aisdati.evaluation.fleet`); None where none is asked."""
    if not settings.fleet_kinds:
        return None
    say(f"constructing {', '.join(settings.fleet_kinds)} cases in the untouched later traffic")
    fleet = FleetSettings(settings.fleet_kinds, settings.fleet_cases, (settings.seed,),
                          settings.before)  # fmt: skip
    return measure([read_area(settings.data_dir, settings.before)], fleet, say)


DETECT_SCORE = ScoreSettings().score
"""The score whose flags make off-traffic events: the one `aisdati detect` uses by default."""


def _events(
    prepared: _Prepared, detectors: dict[str, Detector], heldout: list, result: Evaluation
) -> pd.DataFrame:
    """Each detector's events of the held-out tracks on their reports (`aisdati.evaluation.
    events`): the model-free ones, the same for all, and its own off-traffic ones."""
    settings = prepared.settings
    free = model_free(prepared.data, prepared.split.heldout_ids, list(detectors.values()),
                      settings.ashore)  # fmt: skip
    parts = []
    for method, det in detectors.items():
        s = result.scores[(result.scores["detector"] == method)]
        s = s[s["score"] == DETECT_SCORE].set_index("track_id").loc[prepared.split.heldout_ids]
        profiles = result.profiles[(method, DETECT_SCORE)]
        threshold = float(s["threshold"].iloc[0])
        events = with_off_traffic(free, heldout, s["value"].to_numpy(), threshold, profiles,
                                  det.name)  # fmt: skip
        parts.append(on_reports(events, heldout).assign(detector=method))
    return pd.concat(parts, ignore_index=True)


def _event_table(
    events: pd.DataFrame, labels: pd.DataFrame, settings: EvaluateSettings
) -> pd.DataFrame:
    """`event_metrics` of each detector's events."""
    rows = [
        {"detector": method, **row}
        for method in settings.detectors
        for row in event_metrics(labels, events[events["detector"] == method], settings.kinds)
    ]
    return pd.DataFrame(rows)


def scored_kinds(det: Detector) -> list[str]:
    """The scores a detector gives the held-out tracks in one pass: nearest's two; a policy's
    four (`stepspread` where its card was calibrated with it: cards from before it are not)."""
    if det.method == "nearest":
        return ["nearest", "lane"]
    spread = ["stepspread"] if det.card.calibration.get("stepspread") else []
    return ["rollout", "step", "lane", *spread]


ALL_ROUTES = "routes"
"""`--cluster routes`: evaluate every route that can be split, and pool the results."""


@dataclass
class RoutesEvaluation:
    """`aisdati evaluate --cluster routes`: one `Evaluation` per route, and the pooled table."""

    settings: EvaluateSettings
    routes: list[Evaluation]
    skipped: dict[str, str]
    """Routes with too few tracks (or vessels) to split, and why."""
    table: pd.DataFrame
    """As `Evaluation.table`, over the held-out tracks of all routes, each score divided by
    its route model's calibrated threshold (medians in multiples of the threshold)."""
    scores: pd.DataFrame
    """Every route's `Evaluation.scores`, with `route` and `ratio` (value / threshold)."""
    event_table: pd.DataFrame = field(default_factory=pd.DataFrame)
    """As `Evaluation.event_table`, over the held-out tracks of all routes."""
    fleet: dict[str, Any] | None = None
    """As `Evaluation.fleet`: the area's, once."""


def evaluate_routes(
    settings: EvaluateSettings,
    on_stage: Callable[[str], None] | None = None,
    train_detector: Callable[..., Any] | None = None,
    train_routes: Callable[..., Any] | None = None,
    runner: Runner | None = None,
) -> RoutesEvaluation:
    """Evaluate every route of the data with at least `MIN_ROUTE_TRACKS` tracks: split and
    inject each on its own, train one model per route (DATI's routes as one batched ensemble,
    `train_routes(method, [TrainSettings], ScoreSettings)`), score each route's held-out
    tracks with its own route's model, and pool. Scores of different routes are put on one
    scale by dividing each by its route model's calibrated threshold (the (1 - contamination)
    quantile of that model's training scores): "how many times what this route's normal
    traffic reaches", which is also what flags a track. Held-out tracks are scored as tasks of
    `runner`; `train_routes` is the one to spread the training."""
    from aisdati.detectors.train import train_detector as plain_train
    from aisdati.detectors.train import train_routes as plain_routes

    check(settings)
    train = train_detector or plain_train
    train_all = train_routes or plain_routes
    say = on_stage or (lambda _: None)
    prepared, skipped = _prepare_routes(settings, say)
    detectors: list[dict[str, Detector]] = [dict(p.existing) for p in prepared]
    train_s: list[dict[str, float]] = [dict.fromkeys(p.existing, 0.0) for p in prepared]
    for method in settings.detectors:
        todo = [k for k, p in enumerate(prepared) if method not in p.existing]
        if not todo:
            continue
        say(f"training {method} on {len(todo)} routes")
        t0 = time.perf_counter()
        if method == "dati":
            group = [prepared[k].train_settings() for k in todo]
            models = [t.model for t in train_all(method, group, HOW)]
        else:
            models = [train(method, prepared[k].train_settings(), HOW).model for k in todo]
        share = (time.perf_counter() - t0) / len(todo)  # an ensemble's time, shared out
        for k, model in zip(todo, models, strict=True):
            detectors[k][method] = _load(model.with_suffix(""), settings)
            train_s[k][method] = share
    evaluations = [
        _score(p, d, t, say, runner) for p, d, t in zip(prepared, detectors, train_s, strict=True)
    ]
    scores, table = _pooled(evaluations, settings.kinds)
    events = _pooled_events(evaluations, settings)
    fleet = fleet_measure(settings, say)
    return RoutesEvaluation(settings, evaluations, skipped, table, scores, events, fleet)


def _prepare_routes(
    settings: EvaluateSettings, say: Callable[[str], None]
) -> tuple[list[_Prepared], dict[str, str]]:
    """Every route split and injected on its own, and the routes that could not be (with
    why); none that could is one line."""
    routes = routes_with(settings.data_dir, "evaluate")
    prepared: list[_Prepared] = []
    skipped: dict[str, str] = {}
    say(f"splitting and injecting {len(routes)} routes")
    for route in routes:
        sub = replace(settings, cluster=route, out_dir=settings.out_dir / route)
        try:
            prepared.append(_prepare(sub, _checked_models(sub)))
        except UserError as exc:
            skipped[route] = str(exc)
    if not prepared:
        raise UserError(f"no route of {settings.data_dir} can be split: {skipped[routes[0]]}")
    return prepared, skipped


def _pooled(
    evaluations: Sequence[Evaluation], kinds: Sequence[str]
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every route's held-out scores as one table, each over its own model's threshold
    (`POOLED_UNIT`), and the pooled results table of them."""
    scores = pd.concat(
        [ev.scores.assign(route=ev.settings.cluster) for ev in evaluations], ignore_index=True
    )
    scores["ratio"] = scores["value"] / scores["threshold"]
    rule = AshoreCheck()
    rows = []
    for (method, kind), g in scores.groupby(["detector", "score"], sort=False):
        labels = g.set_index("track_id")[["label", "kind"]]
        values = g["ratio"].to_numpy()
        ranked = rule.ranked(values, g["ashore_reports"], g["n_points"])
        flagged = g["flagged"].to_numpy()
        rows += _rows(method, kind, labels, values, ranked, flagged, 1.0, kinds, POOLED_UNIT)
    return scores, pd.DataFrame(rows)


def _pooled_events(evaluations: Sequence[Evaluation], settings: EvaluateSettings) -> pd.DataFrame:
    """`event_metrics` over every route's held-out tracks, each named by route and id (the
    altered tracks of two routes may share an id)."""

    def named(frame: pd.DataFrame, route: str) -> pd.DataFrame:
        return frame.assign(track_id=route + "/" + frame["track_id"].astype(str))

    routes = [ev.settings.cluster for ev in evaluations]
    events = pd.concat([named(ev.events, r) for ev, r in zip(evaluations, routes, strict=True)])
    labels = pd.concat(
        [named(ev.split.labels, r) for ev, r in zip(evaluations, routes, strict=True)]
    )
    return _event_table(events, labels, settings)


POOLED_UNIT = "x threshold"
"""The unit of the pooled routes' values: each track's score over its own model's threshold."""


def _rows(
    method: str,
    score: str,
    labels: pd.DataFrame,
    values: np.ndarray,
    ranked: np.ndarray,
    flagged: np.ndarray,
    threshold: float,
    kinds: tuple[str, ...],
    unit: str,
) -> list[dict[str, Any]]:
    """The table's rows of one detector and score: per anomaly kind (and pooled), how `ranked`
    orders and `flagged` flags the altered tracks against the normal ones, and the median
    `values` of each, in `unit` (`aisdati.scores.Score.unit`)."""
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
            **ranking(y[keep], ranked[keep]),
            **flagging(y[keep], flagged[keep]),
            "threshold": float(threshold),
            "median_normal": float(np.median(values[normal])),
            "median_anomalous": float(np.median(values[anomalous])) if anomalous.any() else None,
            "unit": unit,
        }
        out.append(row)
    return out


__all__ = [
    "ALL_ROUTES",
    "DETECTORS",
    "EvaluateSettings",
    "Evaluation",
    "RoutesEvaluation",
    "evaluate",
    "evaluate_routes",
]
