"""`aisdati train`: train one detector on a cluster's tracks (or one per route), with progress
bars, an honest message on Ctrl-C about what was saved, and the model's table."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer
from rich.markup import escape

from aisdati.ais.training import TrainSettings
from aisdati.commands.common import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    console,
    err_console,
    lane_settings,
)
from aisdati.commands.tables import dati_model_table, route_models_table
from aisdati.detectors import model_name, parse_detectors
from aisdati.detectors.train import Trained, train_detector, train_routes
from aisdati.interrupts import Terminated
from aisdati.options import check_options
from aisdati.outdir import prepare_output_dir
from aisdati.progress import EpisodeProgress, TrainingProgress
from aisdati.tracks.store import read_track_table, routes_with, select_cluster

MODEL_SUFFIXES = (".pt", ".json", ".npz", ".corridor.npz", ".log.jsonl", ".ckpt")
"""The files a model `<stem>` may have in --out: none of them may be a folder."""


def run(
    cluster: str,
    method: str,
    data: Path,
    out: Path,
    preset: str | None,
    lane: list[str] | None,
    episodes: int,
    seed: int,
    max_tracks: int,
    patience: int,
    resume: bool,
    quiet: bool,
    as_json: bool,
) -> None:
    """`aisdati train` with its options (see `aisdati.cli.train`)."""
    check_options({"--seed": seed})
    (method,) = parse_detectors(method)[:1]
    if cluster.strip().lower() == "routes":
        return train_every_route(
            method, data, out, preset, lane, episodes, seed, patience, max_tracks, quiet
        )
    select_cluster(read_track_table(data), cluster.strip().lower(), data)  # fail before the bars
    stem = model_name(cluster.strip().lower(), method)
    prepare_output_dir(out, "--out", [stem + x for x in MODEL_SUFFIXES])
    settings = TrainSettings(
        data_dir=data,
        cluster=cluster.strip().lower(),
        out_dir=out,
        **lane_settings(preset, lane, cluster),
        episodes=episodes,
        seed=seed,
        max_tracks=max_tracks or None,
        patience=patience,
        resume=resume,
    )
    resuming = resume and (out / f"{stem}.ckpt").is_file()
    result = train_with_bars(method, settings, resuming, disable=quiet or as_json)
    if as_json:
        print(json.dumps({"model": str(result.model), "card": result.card}, default=str))
    elif quiet:
        return
    elif method != "dati":
        console.print(
            f"{method} model of cluster {escape(repr(settings.cluster))} on "
            f"{result.card['data']['tracks_used']} tracks in {result.wall_seconds:.1f} s: "
            f"wrote [bold]{escape(str(result.model))}[/]",
            highlight=False,
        )
    else:
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
            message = interrupted_message(method, saved, settings.out_dir)
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


def interrupted_message(method: str, saved: bool, out: Path) -> str:
    """What a stopped training leaves behind: DATI saves the best model after every episode."""
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


def train_every_route(
    method: str,
    data: Path,
    out: Path,
    preset: str | None,
    lane: list[str] | None,
    episodes: int,
    seed: int,
    patience: int,
    max_tracks: int,
    quiet: bool,
) -> None:
    """`train --cluster routes`: every route with enough tracks, DATI as one batched ensemble."""
    routes = routes_with(data, "train")
    prepare_output_dir(out, "--out")
    settings = [
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
    members = len(routes) * (settings[0].lane.members if method == "dati" else 1)
    with EpisodeProgress(members, episodes, f"training {method}", disable=quiet) as bar:
        trained = train_routes(method, settings, on_step=bar.on_step)
    if not quiet:
        console.print(route_models_table(method, routes, trained))
