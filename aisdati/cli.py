"""Command line of aisdati: the Typer app and its options. Each command's body is one call into
`aisdati.commands.<command>`, imported only when that command runs, so that `aisdati --help`
stays fast; every user mistake surfaces as a `UserError` and is shown as one red line."""

from __future__ import annotations

import inspect
import os
import shutil
from datetime import datetime
from pathlib import Path

# Before torch loads: DATI's networks are small and batched, so OpenMP/MKL worker threads only
# spin; on 2 busy cores one such thread made AIS training ~10x slower. Users may still set these.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import typer

from aisdati.ais import AREA_PRESET, DEFAULT_PRESET
from aisdati.commands import run_command
from aisdati.commands.common import user_errors
from aisdati.startup import end_startup_guard
from aisdati.tracks.ashore import AshoreCheck

RICH_HELP_COLUMNS = 100
"""Narrowest terminal that gets rich's help panels: their option columns take about 45
characters (`--lane-traffic` beside `--no-lane-traffic`, a metavar), so at 80 columns each
option's help was squeezed into 20."""


def help_markup(columns: int) -> str | None:
    """Rich's help panels at `RICH_HELP_COLUMNS` or more; below (an 80-column terminal, a pipe,
    a log) click's plain layout, which puts a long option's help under it at full width."""
    return "rich" if columns >= RICH_HELP_COLUMNS else None


app = typer.Typer(
    help="aisdati: find abnormal vessel tracks in AIS data with DATI (domain-adaptive trajectory "
    "imitation).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=help_markup(shutil.get_terminal_size().columns),
)


PRESET_OPTION = typer.Option(
    None,
    "--preset",
    help=f"DATI's AIS set-up: {DEFAULT_PRESET} (the default for a cluster or route), "
    f"{AREA_PRESET} (the default for --cluster all: {DEFAULT_PRESET} bound for each track's "
    "destination, calibrated by cross-fitting) or paper (the paper's own configuration).",
    show_default=False,
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
ASHORE = AshoreCheck()
ASHORE_OPTION = typer.Option(
    True,
    "--ashore/--no-ashore",
    help=f"Flag every track with at least {ASHORE.min_reports} reports {ASHORE.margin_m:g} m or "
    "more inland, whatever its score, and rank those first (a vessel cannot sail there); "
    "--no-ashore judges by the model alone, as the paper does (use it on lakes and rivers "
    "above the tidal limit, which the coastline holds as land).",
)
WORKERS_OPTION = typer.Option(
    "1",
    "--workers",
    envvar="AISDATI_WORKERS",
    help="Where the command's tasks run: N local Dask processes (1: in this process), or the "
    "address of an existing Dask cluster (tcp://HOST:PORT; every worker must see the input and "
    "output folders). Results do not depend on it.",
)
DEVICE_OPTION = typer.Option(
    "cpu",
    "--device",
    help="Where DATI's networks run: cpu, cuda, cuda:N or auto (CUDA when torch sees a GPU). "
    "The environments, DTW and the other detectors always run on the CPU.",
)
LANE_OPTION = typer.Option(
    None,
    "--lane",
    help="Override one lever of the preset, KEY=VALUE (repeatable): validation=true, "
    "region=box|corridor, corridor_km=2, state=position|motion, "
    "ranges=max|quantile, noise=gaussian|ou, fourier=6 (octaves of position features; 0 off), "
    "pretrain=50 (epochs of cloning before the adversarial training; 0 off), members=3 (seeds "
    "trained as one lane model), validation_tracks=8, validation_rollouts=3, "
    "validate_by=rollout|step, crossfit=true (members calibrated on vessel folds they did "
    "not train on).",
)


@app.command()
@user_errors
def ingest(
    inputs: list[str] = typer.Option(
        None,
        "--input",
        "-i",
        help="AIS file, glob or folder (.zip .csv .parquet; NMEA .nmea .ais .txt); repeatable.",
    ),
    download: str = typer.Option(
        None,
        "--download",
        help="Download MarineCadastre's files of this period (2015 on): YYYY, YYYY-MM or "
        "YYYY-MM-DD, or a range A..B (2018-07-01..2018-07-07); 2015-2017 come by month, in "
        "the UTM zones --roi spans. A mirror: set AISDATI_BASE_URL.",
        show_default=False,
    ),
    data_dir: Path = typer.Option(
        Path("data/raw"), help="Download cache folder (a complete file is not fetched again)."
    ),
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
    route_min_tracks: int = typer.Option(5, help="Fewest tracks of a route."),
    route_eps_km: str = typer.Option(
        "auto",
        help="Route endpoint radius and shape tolerance in km; auto: HDBSCAN, no fixed scale.",
    ),
    keep_rejects: bool = typer.Option(
        False, "--keep-rejects", help="Write every rejected row with its reason to rejects.parquet."
    ),
    workers: str = WORKERS_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON on stdout."),
) -> None:
    """Read MarineCadastre AIS files (downloaded or local), then filter, clean, segment and
    cluster them into points.parquet, tracks.parquet and ingest_report.json (with route
    clusters: routes.parquet, routes.geojson and routes.png)."""
    run_command("ingest", locals())


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
        "four), dati-no-time-embedding, dati-no-reward-input; or table2: the paper's ablation "
        "(DATI with and without time embedding and reward input; default family: circles).",
    ),
    seeds: int = typer.Option(10, help="Training seeds per family (paper: 10)."),
    episodes: int = typer.Option(100, help="Maximum training episodes per seed (paper: 100)."),
    steps: int | None = typer.Option(
        None, help="Steps per episode τ (default: the family's, 200)."
    ),
    references: int = typer.Option(10, help="Unseen test references per family (paper: 10)."),
    workers: str = typer.Option(
        "2",
        "--workers",
        envvar="AISDATI_WORKERS",
        help="Train the members on a local Dask cluster of this many processes (one per core; "
        "1: in this process), or on the existing one at this address (tcp://HOST:PORT).",
    ),
    device: str = DEVICE_OPTION,
    preset: str = SELFTEST_PRESET_OPTION,
    repeats: int = typer.Option(
        1, help="Run the whole protocol this many times on further seed blocks (its spread)."
    ),
    quick: bool = typer.Option(
        False, "--quick", help="Smoke check: 2 seeds x 3 episodes x 40 steps."
    ),
    out: Path | None = typer.Option(None, help="Output folder (default runs/selftest-<time>)."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON on stdout."),
) -> None:
    """Train DATI (and the baselines or ablations) on the paper's synthetic families and compare
    with its Tables 1 and 2."""
    run_command("selftest", locals())


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
    method: str | None = typer.Option(
        None,
        "--method",
        help="Detector: dati (the paper's), bc (behavioural cloning) or nearest (no learning). "
        "Default: bc for --cluster all (cross-fitted, judged by stepspread: it measured best "
        "forward in time), dati for a cluster or route.",
        show_default=False,
    ),
    data: Path = typer.Option(Path("data/processed"), "--data", help="Ingest output folder."),
    out: str = typer.Option(
        "models",
        "--out",
        help="Model folder, or a URL the models are copied to (s3://bucket/models with s3fs, "
        "ftp://user:password@host/models, any fsspec URL): what a cluster's workers all reach.",
    ),
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
    workers: str = WORKERS_OPTION,
    device: str = DEVICE_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print the model card as JSON on stdout."),
) -> None:
    """Train a detector on one cluster's tracks. DATI writes <out>/<cluster>.pt (weights only),
    the model card <cluster>.json, the training log <cluster>.log.jsonl and a resume checkpoint
    <cluster>.ckpt after every episode (removed when training finishes); bc and nearest write
    <cluster>-<method>.json beside their weights or tracks."""
    run_command("train", locals())


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
    before: datetime | None = typer.Option(
        None,
        "--before",
        formats=["%Y-%m-%d", "%Y-%m-%dT%H:%M:%S"],
        help="Split by time instead of by vessel: train on the tracks that start before this "
        "day (UTC), judge every later one (forward in time), e.g. 2018-08-01.",
    ),
    altered: float = typer.Option(
        0.5, "--altered", help="Share of the judged tracks that take an anomaly."
    ),
    strength: float = typer.Option(
        1.0, "--strength", help="Anomaly distances x this (0.3: the subtle tier)."
    ),
    at_sea: bool = typer.Option(
        False,
        "--at-sea",
        help="Write only anomalies that put no more reports ashore than their track had "
        "(redrawn with new parameters, else the track stays normal and is counted): what a vessel "
        "could sail, which the ashore rule cannot see.",
    ),
    models: str | None = typer.Option(
        None,
        "--models",
        help="Use the models trained on this cluster in this folder or URL (and their "
        "training tracks) instead of training new ones.",
    ),
    preset: str = PRESET_OPTION,
    lane: list[str] = LANE_OPTION,
    episodes: int = typer.Option(170, help="Training episodes of dati and bc."),
    ashore: bool = ASHORE_OPTION,
    contamination: float = typer.Option(
        0.05, help="Calibrated flagging: share of training tracks a detector would flag."
    ),
    seed: int = typer.Option(0, help="Seed of the split, the injections and the training."),
    workers: str = WORKERS_OPTION,
    device: str = DEVICE_OPTION,
    as_json: bool = typer.Option(False, "--json", help="Print evaluation.json on stdout."),
) -> None:
    """Measure detection on your own data: split a cluster's tracks by vessel, write anomalies
    (detours, position jumps, loitering, speed changes, gaps, point noise) into half of the
    held-out tracks, train the detectors on the rest and report how well each ranks and flags
    the altered tracks (ROC AUC, average precision, precision/recall/F1), per anomaly kind.
    Writes data/ (the injected set in ingest's schema, with labels.csv), models/,
    evaluation.json, scores.parquet, roc_pr.png and examples.png."""
    run_command("evaluate", locals())


@app.command()
@user_errors
def detect(
    data: Path = typer.Option(Path("data/processed"), "--data", help="Ingest output folder."),
    models_dir: str = typer.Option(
        "models", "--models", help="Model folder, or the URL `train --out` copied them to."
    ),
    model: list[str] = typer.Option(
        None, "--model", "-m", help="Model name in --models (repeatable); default: all."
    ),
    method: str | None = typer.Option(
        None,
        "--method",
        help="Use the models of this detector: dati, bc or nearest. Default: the first of "
        "these the folder has models of.",
    ),
    score: str | None = typer.Option(
        None,
        "--score",
        help="How a policy judges a track: lane (distance to where its K free rollouts go; "
        "for nearest: to where the training tracks go), rollout (the best free rollout's DTW, "
        "the paper's), step (teacher-forced one-step errors, m) or stepspread (those errors "
        "over the spread of the model's draws). Default: the model's own (its card says).",
        show_default=False,
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
    ashore: bool = ASHORE_OPTION,
    contamination: float = typer.Option(
        0.05,
        "--contamination",
        help="The default rule: flag scores above each model's calibrated threshold, which "
        "flags this share of its own training tracks; a track's flag does not depend on the "
        "other tracks judged with it.",
    ),
    threshold: float | None = typer.Option(
        None,
        "--threshold",
        help="The paper's rule instead (Λ, section 6.2: 0.75): flag scores above this share of "
        "the largest score of the tracks judged together, in (0, 1]; depends on the batch.",
        show_default=False,
    ),
    top_percent: float | None = typer.Option(
        None,
        "--top-percent",
        help="Flag this percentage of the highest scores of the batch instead.",
        show_default=False,
    ),
    near_km: float = typer.Option(
        10.0, "--near-km", help="Test tracks start within this distance of a training start."
    ),
    workers: str = WORKERS_OPTION,
    device: str = DEVICE_OPTION,
    labels: Path | None = typer.Option(
        None,
        "--labels",
        help="CSV of labels: track_id,label[,kind], mmsi,start,label[,kind] (0/1), or an "
        "incident list mmsi,start,end[,kind] (a track overlapping a window of its vessel is an "
        "anomaly, every other one normal); with kinds, metrics per kind.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON on stdout."),
) -> None:
    """Score test tracks against trained models: writes scores.parquet, profiles.parquet,
    anomalies.geojson, map.png, map.html and report.json to --out and prints the flagged
    tracks."""
    run_command("detect", locals())


def one_line_summaries(commands: typer.Typer) -> None:
    """Each command's line in `aisdati --help`: its docstring's first paragraph with the line
    breaks joined (typer's rich help keeps them there, so the list broke mid-sentence)."""
    for info in commands.registered_commands:
        doc = inspect.cleandoc((info.callback.__doc__ if info.callback else None) or "")
        info.short_help = " ".join(doc.split("\n\n")[0].split())


one_line_summaries(app)
end_startup_guard()  # loaded: from here Ctrl-C is click's and each command's to handle

if __name__ == "__main__":
    app()
