"""`aisdati train`: train one detector on a cluster's tracks (or one per route), with progress
bars, an honest message on Ctrl-C about what was saved, and the model's table."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import typer
from rich.markup import escape

from aisdati.ais.training import TrainSettings
from aisdati.commands.common import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    console,
    default_method,
    err_console,
    lane_settings,
    shows_progress,
    warn,
)
from aisdati.commands.options import TrainOptions
from aisdati.commands.tables import dati_model_table, route_models_table
from aisdati.detectors import model_name, parse_detectors
from aisdati.detectors.train import Trained, routes_bar, train_detector, train_routes
from aisdati.errors import UserError
from aisdati.execution import Execution, open_runner, resolve_device
from aisdati.interrupts import Terminated
from aisdati.options import check_options
from aisdati.outdir import prepare_output_dir
from aisdati.progress import TrainingProgress
from aisdati.storage import RemoteFolder, is_url
from aisdati.tracks.store import read_track_table, routes_with, select_cluster

MODEL_SUFFIXES = (".pt", ".json", ".npz", ".corridor.npz", ".log.jsonl", ".ckpt")
"""The files a model `<stem>` may have in --out: none of them may be a folder."""


def run(o: TrainOptions) -> None:
    """`aisdati train` with its options (`aisdati.commands.options.TrainOptions`)."""
    check_options({"--seed": o.seed})
    (method,) = parse_detectors(default_method(o.method, o.cluster))[:1]
    execution = Execution.parse(o.workers)
    device = resolve_device(o.device)
    cluster = o.cluster.strip().lower()
    if cluster == "routes":
        local, url = model_folder(o.out, o.resume)
        settings = route_settings(
            o.data, local, o.preset, o.lane, o.episodes, o.seed, o.patience, o.max_tracks
        )
        settings = [replace(s, device=device, publish_to=url) for s in settings]
        return train_every_route(method, settings, execution, o.as_json)
    if execution.distributed:
        warn("one model trains in this process: --workers spreads --cluster routes")
    select_cluster(read_track_table(o.data), cluster, o.data)  # fail before the bars
    stem = model_name(cluster, method)
    local, url = model_folder(o.out, o.resume, [stem + x for x in MODEL_SUFFIXES])
    settings = TrainSettings(
        data_dir=o.data,
        cluster=cluster,
        out_dir=local,
        publish_to=url,
        **lane_settings(o.preset, o.lane, o.cluster),
        episodes=o.episodes,
        seed=o.seed,
        max_tracks=o.max_tracks or None,
        patience=o.patience,
        resume=o.resume,
        device=device,
    )
    resuming = o.resume and local is not None and (local / f"{stem}.ckpt").is_file()
    result = train_with_bars(method, settings, resuming, disable=not shows_progress(o.as_json))
    if o.as_json:
        print(json.dumps({"model": str(result.model), "card": result.card}, default=str))
    else:
        print_trained(method, settings, result)


def print_trained(method: str, settings: TrainSettings, result: Trained) -> None:
    """What was trained, and where it was written."""
    if method != "dati":
        console.print(
            f"{method} model of cluster {escape(repr(settings.cluster))} on "
            f"{result.card['data']['tracks_used']} tracks in {result.wall_seconds:.1f} s, "
            f"judging by {result.card['score']}: wrote [bold]{escape(str(result.model))}[/]",
            highlight=False,
        )
        return
    console.print(dati_model_table(settings.cluster, result))
    console.print(
        f"wrote [bold]{escape(str(result.model))}[/] and its card and log", highlight=False
    )


def train_with_bars(method: str, settings: TrainSettings, resuming: bool, disable: bool) -> Trained:
    """Train under a bar of episodes and one of the running episode's steps; on Ctrl-C or
    SIGTERM, say what was saved and how to go on, and exit 130 / 143."""
    episodes_done = [0]  # episodes this run finished (each one saves the model)
    label = escape(f"training {settings.cluster}")  # the bars' text is rich markup
    with TrainingProgress(settings.episodes, label, disable=disable) as bar:
        try:
            return train_detector(method, settings, on_step=show_steps(bar, episodes_done))
        except KeyboardInterrupt as exc:
            saved = bool(episodes_done[0]) or resuming
            message = interrupted_message(method, saved, settings)
            kind = "terminated" if isinstance(exc, Terminated) else "interrupted"
            err_console.print(f"[yellow]{kind}:[/] {escape(message)}", highlight=False)
            code = EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
            raise typer.Exit(code) from None


def show_steps(bar: TrainingProgress, episodes_done: list[int]) -> Callable[[Any, list[Any]], None]:
    """The trainer's step callback: count and show ended episodes, then the running one's step."""

    def on_step(trainer: Any, logs: list[Any]) -> None:
        episodes_done[0] += len(logs)
        for log in logs:
            bar.episode_done(log.episode, log.mean_reward, log.final_dtw)
        if trainer.done:
            return
        env = trainer.envs[0]
        _, mean_reward = trainer.running_episode(0)
        bar.step(trainer.episode[0] + 1, env.t, env.horizon, mean_reward, env.smoothed)

    return on_step


def model_folder(
    out: str, resume: bool, outputs: list[str] | None = None
) -> tuple[Path | None, str | None]:
    """--out as (a local folder, checked and made; None) or (None; a URL, checked writable:
    `aisdati.storage`)."""
    if not is_url(out):
        return prepare_output_dir(Path(out), "--out", outputs or []), None
    if resume:
        raise UserError("--resume needs a local --out folder: checkpoints are not copied to a URL")
    RemoteFolder(out, "--out").check_writable()
    return None, out


def interrupted_message(method: str, saved: bool, settings: TrainSettings) -> str:
    """What a stopped training leaves behind: DATI saves the best model after every episode
    (into --out, or for a URL into a staging folder that is removed: nothing was copied)."""
    out = settings.out_dir
    if settings.publish_to is not None:
        return (
            "stopped before the model was copied to "
            f"{RemoteFolder(settings.publish_to).shown}; run the same command again"
        )
    if method != "dati":
        return "stopped before the model was saved; run the same command again"
    if saved:
        return (
            f"the model of the best episode so far is in {out}; "
            "run the same command with --resume to continue"
        )
    return (
        "stopped during the first episode, before any model was saved; "
        "run the same command again to start over"
    )


def route_settings(
    data: Path,
    out: Path | None,
    preset: str | None,
    lane: list[str] | None,
    episodes: int,
    seed: int,
    patience: int,
    max_tracks: int,
) -> list[TrainSettings]:
    """`train --cluster routes`: the settings of every route with enough tracks."""
    routes = routes_with(data, "train")
    return [
        TrainSettings(
            data_dir=data,
            cluster=route,
            out_dir=out,
            **lane_settings(preset, lane, route),
            episodes=episodes,
            seed=seed,
            patience=patience,
            max_tracks=max_tracks or None,
        )
        for route in routes
    ]


def train_every_route(
    method: str,
    settings: list[TrainSettings],
    execution: Execution,
    as_json: bool,
) -> None:
    """Every route's model, the routes trained as tasks (`aisdati.detectors.train`) here or on
    the Dask cluster of `execution`."""
    label = f"training {method}" + (
        "" if not execution.distributed else f" on {execution.describe()}"
    )
    with (
        open_runner(execution) as runner,
        routes_bar(method, settings, label, disable=not shows_progress(as_json)) as bar,
    ):
        trained = train_routes(
            method, settings, on_step=bar.on_step, runner=runner, on_task=bar.members_done,
        )  # fmt: skip
    if as_json:
        print(json.dumps({"models": [str(t.model) for t in trained]}, default=str))
    else:
        console.print(route_models_table(method, [s.cluster for s in settings], trained))
