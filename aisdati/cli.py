"""Command line of aisdati: thin wrappers that parse options, call one function per stage and
print with rich. Every user mistake surfaces as a `UserError` and is shown as one red line."""

from __future__ import annotations

import errno
import functools
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

# Before torch loads: DATI's networks are small and batched, so OpenMP/MKL worker threads only
# spin; on 2 busy cores one such thread made AIS training ~10x slower. Users may still set these.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from aisdati.errors import UserError
from aisdati.options import (
    Terminated,
    check_options,
    handle_termination,
    prepare_output_dir,
    raise_if_interrupted,
)

app = typer.Typer(
    help="aisdati: find abnormal vessel tracks in AIS data with DATI (domain-adaptive trajectory "
    "imitation).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


PATH_ERRNOS = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.ENOENT)


PRESET_OPTION = typer.Option(
    "lanes",
    "--preset",
    help="DATI's AIS set-up: lanes (the default, what measured best) or paper (the "
    "paper's own configuration).",
)
SELFTEST_PRESET_OPTION = typer.Option(
    "paper",
    "--preset",
    help="The self-test's set-up: paper (the default, what measured best: the authors' code as "
    "far as it reads: 100 episodes and the final actor, Time2Vec frozen under the adversarial "
    "loss, OU noise at the family's dt but Gaussian for Ribbons, exact region and speeds, "
    "references per seed) or ours (early stopping keeping the lowest-loss actor, region and "
    "speeds with margins, shared references).",
)
LANE_COURSE_OPTION = typer.Option(
    2.0,
    "--lane-course-km",
    help="Lane score: what sailing against the lane's course costs, in km (across it: 0.7 x "
    "as much; 0: position only). As the models were calibrated (training uses the default).",
)
LANE_TRAFFIC_OPTION = typer.Option(
    True,
    "--lane-traffic/--no-lane-traffic",
    help="Lane score of dati and bc: the lane also holds one rollout from every training "
    "track's start (where the model's traffic goes). As the models were calibrated.",
)
LANE_OPTION = typer.Option(
    None,
    "--lane",
    help="Override one lever of the preset, KEY=VALUE (repeatable): validation=true, "
    "region=box|corridor, corridor_km=2, state=position|motion, time=step|progress, "
    "ranges=max|quantile, noise=gaussian|ou, fourier=6 (octaves of position features; 0 off), "
    "pretrain=50 (epochs of cloning before the adversarial training; 0 off), members=3 (seeds "
    "trained as one lane model), average=0 (decay of a moving-average actor; 0 off), "
    "critic=decision|state, validation_tracks=8, validation_rollouts=3.",
)


def lane_settings(preset: str, lane: list[str] | None) -> dict[str, Any]:
    """The `preset` (its name and overrides, for the model card) and `lane` (the resolved
    LaneConfig) of the train and evaluate settings, from --preset and --lane."""
    from aisdati.ais.space import lane_config

    name = preset if not lane else f"{preset} + {', '.join(lane)}"
    return {"preset": name, "lane": lane_config(preset, lane or ())}


def user_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Turn `UserError` (and Ctrl-C, SIGTERM, a file system refusing a path) into a one-line
    message and a non-zero exit code: 2 for user mistakes, 130 / 143 for SIGINT / SIGTERM."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            with handle_termination():
                result = func(*args, **kwargs)
                raise_if_interrupted()  # a Ctrl-C swallowed where nothing was left to commit
                return result
        except UserError as exc:
            message = escape(str(exc))  # a message may hold [brackets]: not markup
            err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None
        except Terminated:
            err_console.print("[yellow]terminated[/]")
            raise typer.Exit(143) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/]")
            raise typer.Exit(130) from None
        except OSError as exc:  # disk full, permissions changed mid-run: one line, no traceback
            if exc.filename is None:
                raise
            message = escape(f"{exc.filename}: {exc.strerror or type(exc).__name__}")
            err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
            raise typer.Exit(2 if exc.errno in PATH_ERRNOS else 1) from None

    return wrapper


ensure_writable_dir = prepare_output_dir
"""Kept for callers of the old name: every command prepares its output folder this way."""


def warn(message: str) -> None:
    """One yellow line on stderr: something the operator should know, not an error."""
    err_console.print(f"[yellow]warning:[/] {escape(message)}", highlight=False, soft_wrap=True)


def _ours(value: float, paper: float | None, sd: float = float("nan")) -> str:
    """Our number, green where it is at or below the paper's; `± sd` over repeats when known."""
    style = "green" if paper is not None and value <= paper else "yellow"
    spread = "" if math.isnan(sd) else f" ± {sd:.3f}"  # NaN: a single repeat
    return f"[{style}]{value:.3f}{spread}[/]"


def _best_label(rows: list[dict[str, Any]], what: str) -> str:
    repeats = max((r.get("repeats", 1) for r in rows), default=1)
    return what if repeats == 1 else f"{what}, mean ± sd of {repeats} repeats"


def _paper(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def selftest_table(rows: list[dict[str, Any]], wall_seconds: float) -> Table:
    """Ours beside the paper's Table 1 (lower is better); one row per method x family."""
    from aisdati.selftest.protocol import METHODS

    methods = list(dict.fromkeys(r.get("method", "dati") for r in rows))
    name = "DATI" if methods == ["dati"] else "Table 1"
    table = Table(
        title=f"{name} self-test: normalised smoothed DTW (wall time {wall_seconds / 60:.1f} min)"
    )
    cols = (
        "method",
        "family",
        _best_label(rows, "best (paper's metric)"),
        "paper",
        "median",
        "IQM [95% CI]",
        "episodes",
    )
    for col in cols:
        table.add_column(col, justify="left" if col in ("method", "family") else "right")
    for r in rows:
        method = r.get("method", "dati")
        table.add_row(
            METHODS.get(method, method),
            r["family"],
            _ours(r["best"], r["paper_best"], r.get("best_sd", float("nan"))),
            _paper(r["paper_best"]),
            f"{r['median']:.3f}",
            f"{r['iqm']:.3f} [{r['iqm_ci_low']:.3f}, {r['iqm_ci_high']:.3f}]",
            f"{r['mean_episodes']:.1f}",
        )
    return table


def ablation_table(rows: list[dict[str, Any]], wall_seconds: float) -> Table:
    """Ours beside the paper's Table 2: top-1 and top-2 per DATI variant (lower is better)."""
    from aisdati.selftest.protocol import METHODS

    table = Table(
        title=f"DATI ablation: normalised smoothed DTW (wall time {wall_seconds / 60:.1f} min)"
    )
    cols = (
        "variant",
        "family",
        _best_label(rows, "top-1"),
        "paper",
        _best_label(rows, "top-2"),
        "paper",
        "median",
        "IQM [95% CI]",
        "episodes",
    )
    for col in cols:
        table.add_column(col, justify="left" if col in ("variant", "family") else "right")
    for r in rows:
        table.add_row(
            METHODS.get(r["method"], r["method"]),
            r["family"],
            _ours(r["best"], r["paper_best"], r.get("best_sd", float("nan"))),
            _paper(r["paper_best"]),
            _ours(r["second_best"], r["paper_second_best"], r.get("second_best_sd", float("nan"))),
            _paper(r["paper_second_best"]),
            f"{r['median']:.3f}",
            f"{r['iqm']:.3f} [{r['iqm_ci_low']:.3f}, {r['iqm_ci_high']:.3f}]",
            f"{r['mean_episodes']:.1f}",
        )
    return table


@app.command()
@user_errors
def ingest(
    inputs: list[str] = typer.Option(
        None,
        "--input",
        "-i",
        help="Local AIS file, glob or folder (.zip .csv .csv.gz .csv.zst .parquet); repeatable.",
    ),
    year: int = typer.Option(None, help="Download MarineCadastre files of this year (2015 on)."),
    months: str = typer.Option("1-12", help="Months to download, e.g. 1-3,7."),
    days: str = typer.Option(None, help="Days to download (daily years 2018 on), e.g. 1-7."),
    zone: int = typer.Option(None, help="UTM zone (monthly zone years 2015-2017), e.g. 17."),
    data_dir: Path = typer.Option(Path("data/raw"), help="Download cache folder."),
    base_url: str = typer.Option(
        None, envvar="AISDATI_BASE_URL", help="Server to download from instead of MarineCadastre."
    ),
    force: bool = typer.Option(False, "--force", help="Download again even if complete."),
    out: Path = typer.Option(Path("data/processed"), help="Output folder."),
    roi: str = typer.Option(
        "florida-straits",
        help="Region of interest: florida-straits (the paper's), none, or a "
        "GeoJSON Polygon/MultiPolygon file.",
    ),
    min_sog: float = typer.Option(3.0, help="Keep reports with SOG above this (knots)."),
    max_speed: float = typer.Option(
        50.0, help="Position outlier: implied speed from the previous kept report above this (kn)."
    ),
    stop_gap: str = typer.Option("1h", help="Split a vessel's reports at gaps longer than this."),
    min_points: int = typer.Option(900, help="Keep tracks with at least this many reports."),
    dwell_radius: float = typer.Option(
        500.0, help="Stop by dwell: the vessel stays within this many metres (see --dwell-time)."
    ),
    dwell_time: str = typer.Option(
        "5min",
        help="Split a track where the vessel dwells (within --dwell-radius) this long; 0: only "
        "at --stop-gap gaps (the paper).",
    ),
    clusters: str = typer.Option(
        "routes",
        help="routes: the paper's up/down/other plus route clusters (route-1, ...: lanes by "
        "entry, exit and shape); direction: the paper's rule only.",
    ),
    route_min_tracks: int = typer.Option(5, help="Fewest tracks of a route."),
    route_eps_km: str = typer.Option(
        "auto",
        help="Route endpoint radius and shape tolerance in km; auto: HDBSCAN, no fixed scale.",
    ),
    route_seed: int = typer.Option(0, help="Seed of the route clustering's samples."),
    keep_rejects: bool = typer.Option(
        False, "--keep-rejects", help="Write every rejected row with its reason to rejects.parquet."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars or table."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON on stdout."),
) -> None:
    """Read MarineCadastre AIS files (downloaded or local), then filter, clean, segment and
    cluster them into points.parquet, tracks.parquet and ingest_report.json (with route
    clusters: routes.parquet, routes.geojson and routes.png)."""
    import json

    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    from aisdati.preprocess.download import download, marinecadastre_files
    from aisdati.preprocess.output import OUTPUT_NAMES
    from aisdati.preprocess.pipeline import ingest as run_ingest
    from aisdati.preprocess.read import expand_inputs
    from aisdati.preprocess.report import summary_table
    from aisdati.preprocess.roi import load_roi
    from aisdati.preprocess.settings import IngestSettings, parse_duration

    check_options({"--min-sog": min_sog, "--max-speed": max_speed})
    if not inputs and year is None:
        raise UserError("nothing to ingest: give --input FILES or --year (with --months/--zone)")
    settings = IngestSettings(
        min_sog_kn=min_sog,
        max_speed_kn=max_speed,
        stop_gap_s=parse_duration(stop_gap),
        min_points=min_points,
        keep_rejects=keep_rejects,
        dwell_radius_m=dwell_radius,
        dwell_time_s=parse_duration(dwell_time, "--dwell-time", allow_zero=True),
        clusters=clusters.strip().lower(),
        route_min_tracks=route_min_tracks,
        route_eps_km=_route_eps(route_eps_km),
        route_seed=route_seed,
    )
    check_options(
        {
            "--stop-gap": settings.stop_gap_s,
            "--dwell-time": settings.dwell_time_s,
            "--dwell-radius": settings.dwell_radius_m,
            "--route-eps-km": settings.route_eps_km,
        }
    )
    area = load_roi(roi, warn=warn)
    remote = marinecadastre_files(year, months, days, zone) if year is not None else []
    local = expand_inputs(inputs) if inputs else []
    prepare_output_dir(out, "--out", OUTPUT_NAMES)
    if remote:
        prepare_output_dir(data_dir, "--data-dir")
    bar_console = err_console if as_json else console
    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        DownloadColumn(),
        TimeRemainingColumn(),
        console=bar_console,
        disable=quiet or not bar_console.is_terminal,
        transient=True,
    )
    with progress:
        files = download(remote, data_dir, base_url, force, progress=progress) + local
        result = run_ingest(files, out, settings, area, roi, progress)
    if as_json:
        print(json.dumps(result.as_dict(), default=str))
    elif not quiet:
        console.print(summary_table(result.counts))
        if result.routes is not None:
            console.print(routes_table(result.routes))
        console.print(f"wrote {', '.join(result.outputs.values())}", highlight=False)


def _route_eps(text: str) -> float | None:
    if text.strip().lower() == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--route-eps-km {text!r}: expected a number of km or auto") from None


def routes_table(summary: dict[str, Any], limit: int = 25) -> Table:
    """The routes found by ingest: size, entry, exit and median length, largest first."""
    rows = summary["routes"]
    table = Table(
        title=f"{len(rows)} routes ({summary['routed_tracks']:,} tracks; "
        f"{summary['unrouted_tracks']:,} fit no route)"
    )
    for col in ("route", "tracks", "entry (lat, lon)", "exit (lat, lon)", "median length"):
        table.add_column(col, justify="right" if col in ("tracks", "median length") else "left")
    for r in rows[:limit]:
        table.add_row(
            r["route"],
            f"{r['n_tracks']:,}",
            f"{r['entry_lat']:.4f}, {r['entry_lon']:.4f}",
            f"{r['exit_lat']:.4f}, {r['exit_lon']:.4f}",
            f"{r['median_length_km']:,.1f} km",
        )
    if len(rows) > limit:
        table.caption = f"... and {len(rows) - limit} more in routes.parquet"
    return table


@app.command()
@user_errors
def selftest(
    family: list[str] = typer.Option(
        ["all"],
        "--family",
        "-f",
        help="Family to run (repeatable or comma-separated); 'all' = the paper's four.",
    ),
    methods: str = typer.Option(
        "dati",
        "--methods",
        "-m",
        help="Methods to compare, comma-separated: dati, bc, bc-paper, ddpg-ti (Table 1: all "
        "four), dati-no-time-embedding, dati-no-reward-input.",
    ),
    ablation: bool = typer.Option(
        False,
        "--ablation",
        help="Table 2: DATI, DATI without time embedding and without reward input, everything "
        "else equal (default family: circles).",
    ),
    seeds: int = typer.Option(10, help="Training seeds per family (paper: 10)."),
    episodes: int = typer.Option(100, help="Maximum training episodes per seed (paper: 100)."),
    steps: int | None = typer.Option(
        None, help="Steps per episode τ (default: the family's, 200)."
    ),
    references: int = typer.Option(10, help="Unseen test references per family (paper: 10)."),
    workers: int = typer.Option(2, help="Processes to share the members out over (one per core)."),
    preset: str = SELFTEST_PRESET_OPTION,
    repeats: int = typer.Option(
        1, help="Run the whole protocol this many times on further seed blocks (its spread)."
    ),
    noise: str | None = typer.Option(
        None,
        help="DATI's latent noise: gaussian, ou or family (OU at the family's dt, Gaussian for "
        "Ribbons); default: the preset's.",
    ),
    time_embedding: bool = typer.Option(True, help="Time2Vec input (off: Table 2 ablation)."),
    reward_input: bool = typer.Option(True, help="Reward input to the critics (off: ablation)."),
    quick: bool = typer.Option(
        False, "--quick", help="Smoke check: 2 seeds x 3 episodes x 40 steps."
    ),
    out: Path | None = typer.Option(None, help="Output folder (default runs/selftest-<time>)."),
    quiet: bool = typer.Option(False, "--quiet", help="No progress bar or table."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON on stdout."),
) -> None:
    """Train DATI (and the baselines or ablations) on the paper's synthetic families and compare
    with its Tables 1 and 2."""
    import json
    from dataclasses import replace
    from datetime import datetime

    from aisdati.progress import EpisodeProgress
    from aisdati.selftest.families import FAMILIES
    from aisdati.selftest.protocol import (
        ABLATION,
        PAPER_FAMILIES,
        QUICK,
        parse_methods,
        preset_settings,
        result_rows,
        run_selftest,
        write_outputs,
    )

    names = [n.strip().lower() for item in family for n in item.split(",") if n.strip()]
    default_families = ["circles"] if ablation else list(PAPER_FAMILIES)
    names = default_families if names in ([], ["all"]) else names
    if ablation and methods.strip().lower() != "dati":
        raise UserError("--ablation runs the three DATI variants itself; leave out --methods")
    method_names = ABLATION if ablation else parse_methods(methods)
    for name in names:
        if name not in FAMILIES:
            raise UserError(f"unknown family {name!r}; choose from {', '.join(FAMILIES)}")
    if quick:
        seeds, references, steps, episodes = (
            QUICK[k] for k in ("seeds", "references", "steps", "episodes")
        )
    for label, value in (
        ("--seeds", seeds),
        ("--episodes", episodes),
        ("--references", references),
        ("--workers", workers),
        ("--repeats", repeats),
    ):
        if value < 1:
            raise UserError(f"{label} must be at least 1, got {value}")
    if steps is not None and steps < 2:
        raise UserError(f"--steps must be at least 2, got {steps}")
    settings = preset_settings(
        preset,
        episodes,
        noise,
        families=tuple(names),
        seeds=seeds,
        references=references,
        steps=steps,
        workers=workers,
        methods=tuple(method_names),
        repeats=repeats,
    )
    config = settings.config.with_network(time_embedding=time_embedding, reward_input=reward_input)
    settings = replace(settings, config=config)
    out = out or Path("runs") / f"selftest-{datetime.now():%Y%m%d-%H%M%S}"
    prepare_output_dir(out, "--out")
    total = len(method_names) * len(names) * seeds * repeats
    label = "training DATI" if list(method_names) == ["dati"] else "training"
    with EpisodeProgress(total, episodes, label, disable=quiet or as_json) as progress:
        result = run_selftest(settings, progress.update)
    files = write_outputs(result, out)
    rows = result_rows(result)
    if as_json:
        print(json.dumps({"results": rows, "wall_seconds": result.wall_seconds, "out": str(out)}))
    elif not quiet:
        make_table = ablation_table if ablation else selftest_table
        console.print(make_table(rows, result.wall_seconds))
        console.print(f"wrote {', '.join(f.name for f in files)} to [bold]{out}[/]")


# ------------------------------------------------------------------------------------ train
@app.command()
@user_errors
def train(
    cluster: str = typer.Option(
        ...,
        "--cluster",
        "-c",
        help="Tracks to learn: a cluster (up, down, other), a route (route-<n>, unrouted), or "
        "routes: every route with enough tracks (DATI trains them as one batched ensemble).",
    ),
    method: str = typer.Option(
        "dati",
        "--method",
        help="Detector: dati (the paper's), bc (behavioural cloning) or nearest (no learning).",
    ),
    data: Path = typer.Option(Path("data/processed"), "--data", help="Ingest output folder."),
    out: Path = typer.Option(Path("models"), "--out", help="Model folder."),
    preset: str = PRESET_OPTION,
    lane: list[str] = LANE_OPTION,
    episodes: int = typer.Option(170, help="Maximum training episodes, one track each (paper)."),
    seed: int = typer.Option(0, help="Random seed (networks, noise, track order, downsampling)."),
    max_tracks: int = typer.Option(
        170, help="Downsample the cluster to this many tracks (paper: 170); 0 keeps all."
    ),
    patience: int = typer.Option(10, help="Early stopping patience in episodes; 0 disables."),
    resume: bool = typer.Option(
        False, "--resume", help="Continue exactly from <out>/<cluster>.ckpt if it exists."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars or table."),
    as_json: bool = typer.Option(False, "--json", help="Print the model card as JSON on stdout."),
) -> None:
    """Train a detector on one cluster's tracks. DATI writes <out>/<cluster>.pt (weights only),
    the model card <cluster>.json, the training log <cluster>.log.jsonl and a resume checkpoint
    <cluster>.ckpt after every episode (removed when training finishes); bc and nearest write
    <cluster>-<method>.json beside their weights or tracks."""
    import json

    from aisdati.ais.training import TrainSettings
    from aisdati.detectors import model_name, parse_detectors
    from aisdati.detectors.train import train_detector
    from aisdati.progress import TrainingProgress
    from aisdati.tracks.store import read_track_table, select_cluster

    check_options({"--seed": seed})
    (method,) = parse_detectors(method)[:1]

    if cluster.strip().lower() == "routes":
        return _train_routes(
            method, data, out, preset, lane, episodes, seed, patience, max_tracks, quiet
        )
    select_cluster(read_track_table(data), cluster.strip().lower(), data)  # fail before the bars
    stem = model_name(cluster.strip().lower(), method)
    suffixes = (".pt", ".json", ".npz", ".corridor.npz", ".log.jsonl", ".ckpt")
    prepare_output_dir(out, "--out", [stem + x for x in suffixes])
    settings = TrainSettings(
        data_dir=data,
        cluster=cluster.strip().lower(),
        out_dir=out,
        **lane_settings(preset, lane),
        episodes=episodes,
        seed=seed,
        max_tracks=max_tracks or None,
        patience=patience,
        resume=resume,
    )
    resuming = resume and (out / f"{stem}.ckpt").is_file()
    episodes_done = [0]  # episodes this run finished (each one saves the model)
    with TrainingProgress(
        episodes, f"training {settings.cluster}", disable=quiet or as_json
    ) as bar:

        def on_step(trainer: Any, logs: list[Any]) -> None:
            episodes_done[0] += len(logs)
            for log in logs:
                bar.episode_done(log.episode, log.mean_reward, log.final_dtw)
            if trainer.done:
                return
            env = trainer.envs[0]
            _, mean_reward = trainer.running_episode(0)
            bar.step(trainer.episode[0] + 1, env.t, env.horizon, mean_reward, env.smoothed)

        try:
            result = train_detector(method, settings, on_step=on_step)
        except KeyboardInterrupt as exc:
            if method != "dati":
                message = "stopped before the model was saved; run the same command again"
            elif episodes_done[0] or resuming:
                message = (
                    f"the model of the best episode so far is in {out}; "
                    "run the same command with --resume to continue"
                )
            else:
                message = (
                    "stopped during the first episode, before any model was saved; "
                    "run the same command again to start over"
                )
            kind = "terminated" if isinstance(exc, Terminated) else "interrupted"
            err_console.print(f"[yellow]{kind}:[/] {message}", highlight=False)
            raise typer.Exit(143 if isinstance(exc, Terminated) else 130) from None
    card = result.card
    if as_json:
        print(json.dumps({"model": str(result.model), "card": card}, default=str))
        return
    if quiet:
        return
    if method != "dati":
        console.print(
            f"{method} model of cluster {settings.cluster!r} on {card['data']['tracks_used']} "
            f"tracks in {result.wall_seconds:.1f} s: wrote [bold]{result.model}[/]",
            highlight=False,
        )
        return
    tr = card["training"]
    used = card["data"]["tracks_used"]
    table = Table(title=f"DATI model of cluster {settings.cluster!r}")
    table.add_column("item")
    table.add_column("value", justify="right")
    rows = [
        ("resumed after episode", str(result.resumed_from)) if result.resumed_from else None,
        ("training tracks", f"{used} of {card['data']['tracks_in_cluster']}"),
        ("episodes run", f"{tr['episodes_run']} (best: {tr['best_episode']})"),
        ("mean reward, last episode", f"{tr['mean_reward'][-1]:+.3f}"),
        ("smoothed DTW at horizon, last", f"{tr['final_dtw_m'][-1]:,.0f} m"),
        ("steps/s", f"{tr['steps_per_second']}"),
        ("wall time", f"{result.wall_seconds:.1f} s"),
    ]
    for row in rows:
        if row:
            table.add_row(*row)
    console.print(table)
    console.print(f"wrote [bold]{result.model}[/] and its card and log", highlight=False)


# --------------------------------------------------------------------------------- evaluate
@app.command()
@user_errors
def evaluate(
    cluster: str = typer.Option(
        ...,
        "--cluster",
        "-c",
        help="Cluster (or route) whose tracks are split and altered; 'routes': every route "
        "with enough tracks, each judged by its own model, pooled into one table.",
    ),
    data: Path = typer.Option(Path("data/processed"), "--data", help="Ingest output folder."),
    out: Path | None = typer.Option(
        None, "--out", help="Output folder (default runs/evaluate-<time>)."
    ),
    detectors: str = typer.Option(
        "nearest,dati,bc", "--detectors", "-d", help="Detectors to compare, comma-separated."
    ),
    kinds: str = typer.Option(
        "detour,jump,loiter,speed,gap,noise",
        "--kinds",
        help="Anomaly kinds to inject, comma-separated (round-robin over the altered tracks).",
    ),
    param: list[str] = typer.Option(
        None,
        "--param",
        help="Change an anomaly parameter, KIND.NAME=LO-HI (repeatable): detour.span=0.2-0.35, "
        "detour.km=2-5, jump.span=0.1-0.2, jump.km=3-6, loiter.radius_km=0.5-1.5, "
        "loiter.loops=1-2, speed.span, speed.slow=0.3, speed.fast=2-3, gap.span=0.2-0.4, "
        "noise.fraction=0.2, noise.km=0.5-1.",
    ),
    train_fraction: float = typer.Option(
        0.6, "--train-fraction", help="Share of the tracks (by vessel) to train on."
    ),
    models: Path | None = typer.Option(
        None,
        "--models",
        help="Use the models trained on this cluster in this folder (and their training "
        "tracks) instead of training new ones.",
    ),
    preset: str = PRESET_OPTION,
    lane: list[str] = LANE_OPTION,
    episodes: int = typer.Option(170, help="Training episodes of dati and bc."),
    patience: int = typer.Option(10, help="DATI early stopping patience; 0 disables."),
    rollouts: int = typer.Option(10, "--rollouts", "-k", help="Rollouts / draws per track."),
    lane_rollouts: int = typer.Option(
        30, "--lane-rollouts", help="Rollouts per track that make up its lane (lane score)."
    ),
    lane_course_km: float = LANE_COURSE_OPTION,
    lane_traffic: bool = LANE_TRAFFIC_OPTION,
    near_km: float = typer.Option(10.0, "--near-km", help="nearest: start-distance filter."),
    contamination: float = typer.Option(
        0.05, help="Calibrated flagging: share of training tracks a detector would flag."
    ),
    seed: int = typer.Option(0, help="Seed of the split, the injections and the training."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress or table."),
    as_json: bool = typer.Option(False, "--json", help="Print evaluation.json on stdout."),
) -> None:
    """Measure detection on your own data: split a cluster's tracks by vessel, write anomalies
    (detours, position jumps, loitering, speed changes, gaps, point noise) into half of the
    held-out tracks, train the detectors on the rest and report how well each ranks and flags
    the altered tracks (ROC AUC, average precision, precision/recall/F1), per anomaly kind.
    Writes data/ (the injected set in ingest's schema, with labels.csv), models/,
    evaluation.json, scores.parquet, roc_pr.png and examples.png."""
    import json
    from datetime import datetime

    from aisdati.detectors import parse_detectors
    from aisdati.detectors.train import train_detector, train_routes
    from aisdati.evaluation.inject import parse_kinds, parse_params
    from aisdati.evaluation.outputs import (
        pooled_table,
        report,
        results_table,
        routes_report,
        write,
        write_routes,
    )
    from aisdati.evaluation.run import ALL_ROUTES, EvaluateSettings, check, evaluate_routes
    from aisdati.evaluation.run import evaluate as run_evaluate
    from aisdati.progress import EpisodeProgress, TrainingProgress
    from aisdati.tracks.store import read_track_table, select_cluster

    check_options(
        {
            "--train-fraction": train_fraction,
            "--near-km": near_km,
            "--lane-course-km": lane_course_km,
            "--contamination": contamination,
            "--seed": seed,
        }
    )
    settings = EvaluateSettings(
        data_dir=data,
        cluster=cluster.strip().lower(),
        out_dir=out or Path("runs") / f"evaluate-{datetime.now():%Y%m%d-%H%M%S}",
        detectors=parse_detectors(detectors),
        kinds=parse_kinds(kinds),
        params=parse_params(param),
        train_fraction=train_fraction,
        seed=seed,
        episodes=episodes,
        patience=patience,
        rollouts=rollouts,
        lane_rollouts=lane_rollouts,
        lane_course_km=lane_course_km,
        lane_traffic=lane_traffic,
        near_km=near_km,
        contamination=contamination,
        models_dir=models,
        **lane_settings(preset, lane),
    )
    check(settings)
    every_route = settings.cluster == ALL_ROUTES
    if not every_route:
        select_cluster(read_track_table(data), settings.cluster, data)  # fail before any work
    prepare_output_dir(settings.out_dir, "--out", ("evaluation.json", "scores.parquet"))
    show = not (quiet or as_json)

    def train_with_bars(method: str, train_settings: Any, how: Any) -> Any:
        if method != "dati" or not show:
            with err_console.status(f"training {method}", spinner="dots") if show else _null():
                return train_detector(method, train_settings, how)
        with TrainingProgress(settings.episodes, "training dati") as bar:

            def on_step(trainer: Any, logs: list[Any]) -> None:
                for log in logs:
                    bar.episode_done(log.episode, log.mean_reward, log.final_dtw)

            return train_detector(method, train_settings, how, on_step=on_step)

    def stage(text: str) -> None:
        if show:
            err_console.print(f"[dim]{text}[/]", highlight=False)

    def train_routes_with_bars(method: str, group: list[Any], how: Any) -> Any:
        members = len(group) * settings.lane.members
        label = f"training {method} on {len(group)} routes"
        with EpisodeProgress(members, settings.episodes, label, disable=not show) as bars:
            return train_routes(method, group, how, on_step=bars.on_step)

    if every_route:
        routes = evaluate_routes(settings, stage, train_with_bars, train_routes_with_bars)
        files = write_routes(routes, settings.out_dir)
        if as_json:
            print(json.dumps(routes_report(routes), default=str))
            return
        if quiet:
            return
        console.print(pooled_table(routes, console.width))
        for ev in routes.routes:
            times = ", ".join(
                f"{m} {t['train_s']:.0f} + {t['score_s']:.0f} s" for m, t in ev.timings.items()
            )
            console.print(
                f"{ev.settings.cluster}: {len(ev.split.train_ids)} training / "
                f"{len(ev.split.heldout_ids)} held-out tracks; training + scoring: {times}",
                highlight=False,
            )
        console.print(
            f"wrote {', '.join(f.name for f in files)} and one folder per route to "
            f"[bold]{settings.out_dir}[/]",
            highlight=False,
        )
        return
    result = run_evaluate(settings, stage, train_with_bars)
    files = write(result, settings.out_dir)
    if as_json:
        print(json.dumps(report(result), default=str))
        return
    if quiet:
        return
    console.print(results_table(result, console.width))
    for method, t in result.timings.items():
        line = f"{method}: training {t['train_s']:.1f} s, scoring {t['score_s']:.1f} s"
        console.print(line, highlight=False)
    console.print(
        f"wrote {', '.join(f.name for f in files)}, data/ and models/ to "
        f"[bold]{settings.out_dir}[/]",
        highlight=False,
    )


def _train_routes(
    method: str,
    data: Path,
    out: Path,
    preset: str,
    lane: list[str] | None,
    episodes: int,
    seed: int,
    patience: int,
    max_tracks: int,
    quiet: bool,
) -> None:
    """`train --cluster routes`: every route with enough tracks, DATI as one batched ensemble."""
    from aisdati.ais.training import TrainSettings
    from aisdati.detectors.train import train_routes
    from aisdati.progress import EpisodeProgress
    from aisdati.tracks.store import routes_with

    routes = routes_with(data, "train")
    prepare_output_dir(out, "--out")
    settings = [
        TrainSettings(
            data_dir=data,
            cluster=route,
            out_dir=out,
            **lane_settings(preset, lane),
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
    if quiet:
        return
    table_out = Table(title=f"{method} models of {len(routes)} routes")
    for col in ("route", "tracks", "episodes", "model"):
        table_out.add_column(col, justify="left" if col in ("route", "model") else "right")
    for route, t in zip(routes, trained, strict=True):
        runs = t.card.get("training", {}).get("episodes_run", "-")
        table_out.add_row(route, str(t.card["data"]["tracks_used"]), str(runs), str(t.model))
    console.print(table_out)


# ----------------------------------------------------------------------------------- detect
def detection_table(scores: Any, limit: int = 15) -> Table:
    """The flagged tracks (or, if none, the top of the ranking) with where they deviate most."""
    flagged = scores[scores["flagged"]].sort_values("rank")
    shown = flagged if len(flagged) else scores.sort_values("rank")
    title = (
        f"{len(flagged)} of {len(scores)} test tracks flagged"
        if len(flagged)
        else f"no track flagged among {len(scores)}; the highest scores"
    )
    from rich import box

    table = Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False)
    cols = ["rank", "track", "mmsi", "score", "mean dist", "max dev", "at (lat, lon)"]
    several = scores["model"].nunique() > 1
    if several:
        cols.insert(3, "model")
    for col in cols:
        table.add_column(
            col, justify="left" if col in ("model", "at (lat, lon)") else "right", no_wrap=True
        )
    for r in shown.head(limit).itertuples():
        row = [
            str(r.rank),
            str(r.track_id),
            str(r.mmsi),
            f"[{'red' if r.flagged else 'white'}]{r.score:.3f}[/]",
            f"{r.score_m / 1000:,.2f} km",
            f"{r.max_dev_m / 1000:,.2f} km",
            f"{r.max_dev_lat:.4f}, {r.max_dev_lon:.4f}",
        ]
        if several:
            row.insert(3, r.model)
        table.add_row(*row)
    if len(shown) > limit:
        table.caption = f"... and {len(shown) - limit} more in scores.parquet"
    return table


@app.command()
@user_errors
def detect(
    data: Path = typer.Option(Path("data/processed"), "--data", help="Ingest output folder."),
    models_dir: Path = typer.Option(Path("models"), "--models", help="Model folder."),
    model: list[str] = typer.Option(
        None, "--model", "-m", help="Model name in --models (repeatable); default: all."
    ),
    method: str = typer.Option(
        "dati", "--method", help="Use the models of this detector: dati, bc or nearest."
    ),
    score: str = typer.Option(
        "lane",
        "--score",
        help="How a policy judges a track: lane (distance to where its K free rollouts go; "
        "for nearest: to where the training tracks go), step (teacher-forced one-step "
        "errors), rollout (the best free rollout's DTW, the paper's) or both (rollout + step).",
    ),
    out: Path | None = typer.Option(None, "--out", help="Report folder (default reports/<time>)."),
    cluster: str = typer.Option(
        "other",
        "--cluster",
        help="Test tracks: a cluster (up, down, other), a route (route-<n>, unrouted) or all.",
    ),
    track: list[int] = typer.Option(
        None, "--track", help="Judge these track ids instead (repeatable)."
    ),
    rollouts: int = typer.Option(10, "--rollouts", "-k", help="Rollouts per track (paper: 1)."),
    lane_rollouts: int = typer.Option(
        30, "--lane-rollouts", help="Rollouts per track that make up its lane (lane score)."
    ),
    lane_course_km: float = LANE_COURSE_OPTION,
    lane_traffic: bool = LANE_TRAFFIC_OPTION,
    threshold: float = typer.Option(0.75, help="Flag normalised scores above this, in (0, 1]."),
    top_percent: float | None = typer.Option(
        None, "--top-percent", help="Flag this percentage of highest scores instead."
    ),
    contamination: float | None = typer.Option(
        None,
        "--contamination",
        help="Flag scores above the model's calibrated threshold instead: the share of its own "
        "training tracks it would flag (e.g. 0.05); independent of the test set.",
    ),
    near_km: float = typer.Option(
        10.0, "--near-km", help="Test tracks start within this distance of a training start."
    ),
    seed: int = typer.Option(0, help="Seed of the rollouts' latent noise."),
    labels: Path | None = typer.Option(
        None, "--labels", help="CSV of hand labels: track_id,label or mmsi,start,label (0/1)."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No table."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
) -> None:
    """Score test tracks against trained models: writes scores.parquet, profiles.parquet,
    anomalies.geojson, map.png, map.html and report.json to --out and prints the flagged
    tracks."""
    import json
    from datetime import datetime

    from aisdati.ais.card import unfinished_models
    from aisdati.detection.run import DetectSettings, check_settings, report_dict, write_outputs
    from aisdati.detection.run import detect as run_detect
    from aisdati.detectors import parse_detectors

    check_options(
        {
            "--threshold": threshold,
            "--top-percent": top_percent,
            "--contamination": contamination,
            "--near-km": near_km,
            "--lane-course-km": lane_course_km,
        }
    )
    settings = DetectSettings(
        data_dir=data,
        models_dir=models_dir,
        out_dir=out or Path("reports") / f"{datetime.now():%Y%m%d-%H%M%S}",
        models=tuple(model or ()),
        method=parse_detectors(method)[0],
        cluster=cluster.strip().lower(),
        track_ids=tuple(track or ()),
        score=score.strip().lower(),
        rollouts=rollouts,
        lane_rollouts=lane_rollouts,
        lane_course_km=lane_course_km,
        lane_traffic=lane_traffic,
        threshold=threshold,
        top_percent=top_percent,
        contamination=contamination,
        near_km=near_km,
        seed=seed,
        labels=labels,
    )
    check_settings(settings)
    prepare_output_dir(settings.out_dir, "--out", DETECT_OUTPUTS)
    for message in unfinished_models(models_dir, settings.models, settings.method):
        warn(message)
    status = err_console if as_json else console
    with status.status("scoring", spinner="dots") if not quiet else _null():
        result = run_detect(settings)
        files = write_outputs(result, settings.out_dir)
    if as_json:
        doc = report_dict(result)
        doc["files"] = [str(f) for f in files]
        print(json.dumps(doc, default=str))
        return
    if quiet:
        return
    console.print(detection_table(result.scores))
    if result.metrics is not None:
        m = result.metrics
        auc = "n/a (one class only)" if m["roc_auc"] is None else f"{m['roc_auc']:.3f}"
        console.print(
            f"against {m['labelled_tracks']} labelled tracks ({m['anomalies_labelled']} "
            f"anomalies): precision {m['precision']:.3f}, recall {m['recall']:.3f}, "
            f"weighted F1 {m['f1_weighted']:.3f} (paper: 0.78), ROC AUC {auc}",
            highlight=False,
        )
    t = result.timings
    console.print(
        f"scoring {t['score_s']:.1f} s; "
        f"wrote {', '.join(f.name for f in files if f.parent == settings.out_dir)}"
        f"{' and evidence/' if any(f.parent != settings.out_dir for f in files) else ''} "
        f"to [bold]{settings.out_dir}[/]",
        highlight=False,
    )


DETECT_OUTPUTS = (
    "scores.parquet",
    "profiles.parquet",
    "anomalies.geojson",
    "map.png",
    "map.html",
    "metrics.json",
    "report.json",
)


def _null() -> Any:
    import contextlib

    return contextlib.nullcontext()


if __name__ == "__main__":
    app()
