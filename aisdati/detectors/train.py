"""Training any detector on the tracks of an ingest folder: `aisdati train --method`.

Many routes are trained as tasks (`aisdati.execution`): `route_tasks` cuts the routes into
groups of `routes_per_task` in route order (the command line: one route a task), and each group
is one batched ensemble (DATI) on one worker. The cut depends on the routes alone, so the models
are the same whatever runs the tasks; fewer routes per task spread wider over workers, more
batch better in one process (the Python API's `train_routes(..., routes_per_task=0)`: all in
one).
Models bound for a URL (`TrainSettings.publish_to`) are written into a local folder on the
machine that trains them and copied there (`aisdati.storage`), so that tasks on other machines
need no shared disk.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais.training import TrainSettings, check_settings, model_stem, training_set
from aisdati.detectors.base import detector_class
from aisdati.detectors.scoring import ScoreSettings
from aisdati.errors import UserError
from aisdati.events.calibrate import calibration, training_period
from aisdati.events.reports import vessels
from aisdati.execution import InProcess, Runner
from aisdati.model.trainer import Callback
from aisdati.progress import EpisodeProgress
from aisdati.storage import RemoteFolder, staging_folder
from aisdati.tracks.reports import motion_derived, read_reports, read_vessels
from aisdati.tracks.store import Track, read_track_table, select_cluster

ROUTES_PER_TASK = 1
"""Routes one training task holds by default: each route is a task of its own."""


@dataclass
class Trained:
    model: Path | str
    """The model's file, or its URL where it was published (`TrainSettings.publish_to`)."""
    card: dict[str, Any]
    """The card as written beside the model (`ModelCard.to_dict`)."""
    wall_seconds: float
    resumed_from: int = 0


def route_tasks(count: int, routes_per_task: int) -> list[range]:
    """The routes (by index) each training task holds: consecutive groups of
    `routes_per_task` (0: all in one task)."""
    size = routes_per_task if routes_per_task > 0 else max(count, 1)
    return [range(i, min(i + size, count)) for i in range(0, count, size)]


def train_routes(
    method: str,
    settings: Sequence[TrainSettings],
    how: ScoreSettings | None = None,
    on_step: Callback | None = None,
    runner: Runner | None = None,
    routes_per_task: int = ROUTES_PER_TASK,
    on_task: Callable[[range], None] | None = None,
) -> list[Trained]:
    """One model of `method` per settings (route or cluster), calibrated on its training tracks
    and saved in its `out_dir`, the routes trained as tasks of `routes_per_task` on `runner`
    (module docstring; default: in this process). `on_step` follows the members' training
    where the tasks run here (member indices counted over all tasks); on a cluster,
    `on_task(members)` is told of each task's members as it ends."""
    cls = detector_class(method)
    settings = [replace(s, stem=s.stem or cls.model_name(s.cluster)) for s in settings]
    for s in settings:
        check_settings(s)  # before reading any data
        if s.out_dir is None and s.publish_to is None:
            raise UserError("training from an ingest folder needs an output folder (--out)")
    runner = runner or InProcess()
    counts = [cls.members(s) for s in settings]
    groups = route_tasks(len(settings), routes_per_task)
    jobs = [(range(sum(counts[: g.start]), sum(counts[: g.stop])), [settings[k] for k in g])
            for g in groups]  # fmt: skip
    cost = training_costs(settings)
    costs = [sum(cost[k] * counts[k] for k in g) for g in groups]
    follow = on_step if isinstance(runner, InProcess) else None  # callbacks stay in this process
    ended = None if on_task is None else (lambda i: on_task(jobs[i][0]))
    done = runner.map(functools.partial(train_task, method, how, follow), jobs, ended, costs)
    return [t for group in done for t in group]


def routes_bar(
    method: str, settings: Sequence[TrainSettings], label: str, disable: bool = False
) -> EpisodeProgress:
    """A bar over every member of `method`'s route models, for `train_routes`'s `on_step` and
    `on_task`: each detector's own members and episodes (nearest: a model per route, learnt in
    one pass)."""
    cls = detector_class(method)
    members = sum(cls.members(s) for s in settings)
    return EpisodeProgress(
        members, cls.episodes(settings[0]), label, disable=disable, unit=cls.progress_unit
    )


def training_costs(settings: Sequence[TrainSettings]) -> list[float]:
    """Each model's expected training work per member, for the order the tasks start in: the
    mean report count of its tracks (a DATI episode sails one track, and every route has the
    same episode budget). Only an order: 1 where the tracks cannot be read here. Each ingest
    folder's track table is read once, and its routes' means taken in one pass (a selection
    per route took 9 ms: 99 s before the first task for the 11,038 routes of 100 M rows)."""
    tables: dict[Path, pd.DataFrame | None] = {}
    route_means: dict[Path, dict[str, float]] = {}
    out = []
    for s in settings:
        if s.data_dir is not None and s.data_dir not in tables:
            try:
                tables[s.data_dir] = read_track_table(s.data_dir)
            except UserError:
                tables[s.data_dir] = None
            route_means[s.data_dir] = _route_means(tables[s.data_dir])
        table = tables.get(s.data_dir) if s.data_dir is not None else None
        if s.data_dir is not None and s.cluster in route_means[s.data_dir]:
            out.append(route_means[s.data_dir][s.cluster])
            continue
        try:
            chosen = None if table is None else select_cluster(table, s.cluster, s.data_dir, 1)
        except UserError:
            chosen = None
        out.append(1.0 if chosen is None else float(chosen["n_points"].mean()))
    return out


def _route_means(table: pd.DataFrame | None) -> dict[str, float]:
    """The mean report count of each route's tracks in a track table."""
    if table is None or "route" not in table.columns:
        return {}
    points = table["n_points"].to_numpy()
    return {
        str(route): float(points[rows].mean())
        for route, rows in table.groupby("route").indices.items()
    }


def train_task(
    method: str,
    how: ScoreSettings | None,
    on_step: Callback | None,
    job: tuple[range, list[TrainSettings]],
) -> list[Trained]:
    """One task of `train_routes`: (its members' indices among all tasks', its routes);
    `on_step` sees member indices counted over all tasks."""
    members, settings = job
    first = members.start
    follow = None
    if on_step is not None:

        def follow(trainer: object, logs: list) -> None:
            on_step(trainer, [replace(log, member=log.member + first) for log in logs])

    return train_group(method, how, follow, settings, first)


def train_group(
    method: str,
    how: ScoreSettings | None,
    on_step: Callback | None,
    settings: Sequence[TrainSettings],
    first_member: int = 0,
) -> list[Trained]:
    """The routes of `settings` fitted together (`Detector.fit_routes`: DATI as one batched
    ensemble, the others one after the other), each calibrated and saved; those bound for a
    URL are trained in a local staging folder and copied there (module docstring)."""
    if not any(s.publish_to for s in settings):
        return fit_and_save(method, how, on_step, settings, first_member)
    with staging_folder() as local:
        staged = [replace(s, out_dir=local) if s.publish_to else s for s in settings]
        trained = fit_and_save(method, how, on_step, staged, first_member)
        return [published(t, s) for t, s in zip(trained, staged, strict=True)]


def published(trained: Trained, settings: TrainSettings) -> Trained:
    """Copy a model trained in a staging folder to its URL (`RemoteFolder.publish`); the
    `Trained` then names the URL."""
    if settings.publish_to is None:
        return trained
    stem = model_stem(settings)
    assert stem is not None  # staged: out_dir is the staging folder
    folder = RemoteFolder(settings.publish_to)
    folder.publish(sorted(stem.parent.glob(stem.name + ".*")))
    return replace(trained, model=folder.join(Path(trained.model).name))


def fit_and_save(
    method: str,
    how: ScoreSettings | None,
    on_step: Callback | None,
    settings: Sequence[TrainSettings],
    first_member: int,
) -> list[Trained]:
    """`train_group` for models written where their settings' `out_dir` says."""
    cls = detector_class(method)
    t0 = time.perf_counter()
    sets = [training_set(s) for s in settings]
    detectors = cls.fit_routes(settings, sets, how, on_step, first_member)
    trained = []
    for s, det, (tracks, _) in zip(settings, detectors, sets, strict=True):
        stem = model_stem(s)
        assert stem is not None  # every settings has an out_dir (checked above)
        det.card.calibration |= event_calibration(s.data_dir, tracks, det.card.data.ashore)
        det.save(stem)
        wall = time.perf_counter() - t0
        model = stem.with_suffix(det.model_suffix)
        trained.append(Trained(model, det.card.to_dict(), wall, det.resumed_from))
    return trained


def event_calibration(
    data_dir: Path | None, tracks: Sequence[Track], seen: np.ndarray
) -> dict[str, list[float]]:
    """The alert budget's record of the training period (`aisdati.events.calibrate`): every
    report over the training tracks' span (slow ones too, as detection judges them), for the
    card beside its scores; `seen`: where the training traffic reported ashore."""
    if data_dir is None:
        return {}
    span = pd.DataFrame(
        {
            "start": [t.start for t in tracks],
            "end": [t.start + pd.Timedelta(hours=float(np.sum(t.dts))) for t in tracks],
        }
    )
    period = training_period(read_reports(data_dir), span)
    lengths = read_vessels(data_dir)["length_m"].dropna().to_dict()
    reported = not motion_derived(data_dir)
    return calibration(vessels(period), lengths=lengths, seen=seen, reported_motion=reported)


def train_detector(
    method: str,
    settings: TrainSettings,
    how: ScoreSettings | None = None,
    on_step: Callback | None = None,
) -> Trained:
    """Train `method` on the settings' tracks, calibrate it on them, save it."""
    return train_routes(method, [settings], how, on_step)[0]
