"""`aisdati evaluate`: the detection benchmark on the user's own data, with a spinner or bars
while each detector trains, and the results table."""

from __future__ import annotations

import glob
import json
from contextlib import nullcontext
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Any

import pandas as pd
from rich.markup import escape

from aisdati.ais.training import TrainSettings
from aisdati.commands.common import console, err_console, lane_settings, shows_progress, spinner
from aisdati.commands.options import EvaluateOptions
from aisdati.commands.tables import event_metrics_table, fleet_table, pooled_table, results_table
from aisdati.detectors import ScoreSettings, parse_detectors
from aisdati.detectors.train import Trained, routes_bar, train_detector, train_routes
from aisdati.evaluation.fleet import parse_fleet_kinds
from aisdati.evaluation.inject import parse_kinds, parse_params
from aisdati.evaluation.outputs import (
    REPORT,
    RESULTS,
    ashore_summary,
    report,
    routes_report,
    write,
    write_routes,
)
from aisdati.evaluation.run import (
    ALL_ROUTES,
    EvaluateSettings,
    check,
    evaluate,
    evaluate_routes,
)
from aisdati.execution import Execution, Runner, open_runner, resolve_device
from aisdati.options import check_options
from aisdati.outdir import OutputSet, removed_if_left_empty, staged_outputs
from aisdati.preprocess.settings import parse_duration
from aisdati.progress import TrainingProgress
from aisdati.storage import fetched_models, shown_folder
from aisdati.tracks.store import read_track_table, routes_with, select_cluster


def run(o: EvaluateOptions) -> None:
    """`aisdati evaluate` with its options (`aisdati.commands.options.EvaluateOptions`)."""
    check_options(
        {
            "--contamination": o.contamination,
            "--seed": o.seed,
        }
    )
    settings = EvaluateSettings(
        data_dir=o.data,
        cluster=o.cluster.strip().lower(),
        out_dir=o.out or Path("runs") / f"evaluate-{datetime.now():%Y%m%d-%H%M%S}",
        detectors=parse_detectors(o.detectors),
        kinds=parse_kinds(o.kinds),
        params=parse_params(o.param),
        seed=o.seed,
        episodes=o.episodes,
        ashore=o.ashore,
        contamination=o.contamination,
        models_dir=None,
        before=None if o.before is None else pd.Timestamp(o.before, tz="UTC"),
        altered=o.altered,
        strength=o.strength,
        at_sea=o.at_sea,
        thin_s=None if o.thin is None else parse_duration(o.thin, "--thin"),
        fleet_kinds=parse_fleet_kinds(o.fleet_kinds),
        fleet_cases=o.fleet_cases,
        device=resolve_device(o.device),
        **lane_settings(o.preset, o.lane, o.cluster),
    )
    with fetched_models(o.models, (), "--models") if o.models else nullcontext(None) as local:
        # a URL's models: a local copy, named by the URL in messages
        settings = replace(settings, models_dir=local, models_shown=shown_folder(o.models))
        check(settings)
        evaluate_with(settings, Execution.parse(o.workers), o.as_json)


def evaluate_with(settings: EvaluateSettings, execution: Execution, as_json: bool) -> None:
    """Evaluate with the settings checked, models (if any) in a local folder."""
    with (
        removed_if_left_empty(settings.out_dir),
        open_runner(execution) as runner,  # before the outputs: a cluster out of reach
        staged_outputs(settings.out_dir, owned_outputs(settings), REPORT) as outputs,
    ):
        outputs.retire_earlier()  # the data and models it describes are about to change
        shown = Display(settings, runner, show=shows_progress(as_json))
        if settings.cluster == ALL_ROUTES:
            evaluate_every_route(settings, shown, outputs, as_json)
        else:
            evaluate_one(settings, shown, outputs, as_json)


def owned_outputs(settings: EvaluateSettings) -> tuple[str, ...]:
    """The names the evaluation writes in its folder, with every route's under `--cluster
    routes`; a cluster or route that is not there fails here, before any work."""
    if settings.cluster != ALL_ROUTES:
        select_cluster(read_track_table(settings.data_dir), settings.cluster, settings.data_dir)
        return RESULTS
    routes = [glob.escape(r) for r in routes_with(settings.data_dir, "evaluate")]
    return RESULTS + tuple(f"{route}/{name}" for route in routes for name in RESULTS)


class Display:
    """What the operator sees while the evaluation runs (nothing when not `show`): a dim line
    per stage, bars while DATI trains, a spinner while the other detectors train; and where
    the tasks run (`runner`)."""

    def __init__(self, settings: EvaluateSettings, runner: Runner, show: bool):
        self.settings = settings
        self.runner = runner
        self.show = show

    def stage(self, text: str) -> None:
        """The evaluation's `on_stage`: what it is doing now."""
        if self.show:
            err_console.print(f"[dim]{escape(text)}[/]", highlight=False)

    def train(self, method: str, train_settings: TrainSettings, how: ScoreSettings) -> Trained:
        """The evaluation's `train_detector`: `train_detector` with a bar or a spinner."""
        if method != "dati" or not self.show:
            with spinner(err_console, f"training {method}", self.show):
                return train_detector(method, train_settings, how)
        with TrainingProgress(self.settings.episodes, "training dati") as bar:

            def on_step(trainer: Any, logs: list[Any]) -> None:
                for log in logs:
                    bar.episode_done(log.episode, log.mean_reward, log.final_dtw)

            return train_detector(method, train_settings, how, on_step=on_step)

    def train_routes(
        self, method: str, group: list[TrainSettings], how: ScoreSettings
    ) -> list[Trained]:
        """The evaluation's `train_routes`: `train_routes` with a bar over every member."""
        label = f"training {method} on {len(group)} routes"
        with routes_bar(method, group, label, disable=not self.show) as bars:
            return train_routes(
                method, group, how, on_step=bars.on_step, runner=self.runner,
                on_task=bars.members_done,
            )  # fmt: skip


def evaluate_one(
    settings: EvaluateSettings, shown: Display, outputs: OutputSet, as_json: bool
) -> None:
    """One cluster or route: evaluate, write, print the table and the timings."""
    result = evaluate(settings, shown.stage, shown.train, shown.runner)
    files = write(result, outputs.folder)
    outputs.commit()
    if as_json:
        print(json.dumps(report(result), default=str))
        return
    console.print(results_table(result, console.width))
    console.print(event_metrics_table(result.event_table, console.width))
    if result.alerts is not None:
        console.print(alerts_line(result.alerts))
    if result.fleet is not None:
        console.print(fleet_table(result.fleet, console.width))
    if settings.ashore:
        n = ashore_summary(result.scores)
        console.print(
            f"ashore rule (every detector): flagged {n['altered']} altered and {n['normal']} "
            "normal tracks for reports well inland",
            highlight=False,
        )
    if settings.at_sea:
        left = result.split.not_at_sea
        console.print(
            f"--at-sea: {len(left)} tracks drawn for an anomaly could not take one at sea and "
            f"stay normal{': ' + ', '.join(map(str, left)) if left else ''}",
            highlight=False,
        )
    for method, t in result.timings.items():
        line = f"{method}: training {t['train_s']:.1f} s, scoring {t['score_s']:.1f} s"
        console.print(line, highlight=False)
    console.print(
        f"wrote {escape(', '.join(f.name for f in files))}, data/ and models/ to "
        f"[bold]{escape(str(settings.out_dir))}[/]",
        highlight=False,
    )


def evaluate_every_route(
    settings: EvaluateSettings, shown: Display, outputs: OutputSet, as_json: bool
) -> None:
    """`--cluster routes`: each route judged by its own model, pooled into one table."""
    routes = evaluate_routes(settings, shown.stage, shown.train, shown.train_routes, shown.runner)
    files = write_routes(routes, outputs.folder)
    outputs.commit()
    if as_json:
        print(json.dumps(routes_report(routes), default=str))
        return
    console.print(pooled_table(routes, console.width))
    console.print(event_metrics_table(routes.event_table, console.width))
    if routes.fleet is not None:
        console.print(fleet_table(routes.fleet, console.width))
    for ev in routes.routes:
        times = ", ".join(
            f"{m} {t['train_s']:.0f} + {t['score_s']:.0f} s" for m, t in ev.timings.items()
        )
        console.print(
            f"{escape(ev.settings.cluster)}: {len(ev.split.train_ids)} training / "
            f"{len(ev.split.heldout_ids)} held-out tracks; training + scoring: {times}",
            highlight=False,
        )
    console.print(
        f"wrote {escape(', '.join(f.name for f in files))} and one folder per route to "
        f"[bold]{escape(str(settings.out_dir))}[/]",
        highlight=False,
    )


def alerts_line(alerts: dict) -> str:
    """The measure of record in one paragraph: what the analyst would have met on the later
    period's untouched traffic (`aisdati.evaluation.events.forward_alerts`)."""
    low, high = alerts["alerts_per_1000_ci"]
    kinds = ", ".join(
        f"{kind} {row['per_1000']:.1f}"
        for kind, row in alerts["by_kind"].items()
        if row["class"] == "alert"
    )
    share = 100 * (alerts["tracks_flagged_share"] or 0.0)
    return (
        f"untouched later traffic ({alerts['vessel_days']:,.0f} vessel-days, every report): "
        f"{alerts['alerts']} alerts, {alerts['alerts_per_1000']:.1f} per 1,000 vessel-days "
        f"[{low:.1f}, {high:.1f}] ({kinds or 'none'}); {alerts['tracks_flagged']} of "
        f"{alerts['tracks']} tracks ({share:.1f} %) flagged by an alert; "
        f"{alerts['activity_per_1000']:.0f} activities per 1,000 vessel-days"
        + _coverage_words(alerts.get("gaps_by_coverage"))
    )


def _coverage_words(rates: dict | None) -> str:
    """The gaps per 1,000 vessel-days by coverage (heard: others kept reporting; quiet: the area
    went silent)."""
    if not rates:
        return ""
    return " (gaps: " + ", ".join(f"{k} {v:.1f}" for k, v in rates.items()) + ")"
