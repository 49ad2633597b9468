"""Every command's options, declared once: one frozen dataclass per command whose fields are
the options (name, type, default and `--help` in the field's annotation). The command line is
built from these (`aisdati.cli`), and each command's `run` (`aisdati.commands.<name>`) receives
its dataclass, so an option is never spelt twice. Light on purpose: `aisdati --help` imports
this module and not the commands.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Annotated

import typer

from aisdati.ais import AREA_PRESET, DEFAULT_PRESET
from aisdati.events.budget import ALERTS_PER_1000
from aisdati.tracks.ashore import AshoreCheck

_RULE = AshoreCheck()
JSON = typer.Option("--json", help="Print the outcome as JSON on stdout, and nothing else.")

PRESET = typer.Option(
    "--preset",
    help=f"DATI's AIS set-up: {DEFAULT_PRESET} (the default for a cluster or route), "
    f"{AREA_PRESET} (the default for --cluster all: {DEFAULT_PRESET} bound for each track's "
    "destination, calibrated by cross-fitting) or paper (the paper's own configuration).",
    show_default=False,
)


SELFTEST_PRESET = typer.Option(
    "--preset",
    help="The self-test's set-up: paper (the default, what measured best: the authors' code as "
    "far as it reads: 100 episodes and the final actor, Time2Vec frozen under the adversarial "
    "loss, OU noise at the family's dt but Gaussian for Ribbons, exact region and speeds, "
    "references per seed) or ours (early stopping keeping the lowest-loss actor, region and "
    "speeds with margins, shared references).",
)


ASHORE = typer.Option(
    "--ashore/--no-ashore",
    help=f"Flag every track with at least {_RULE.min_reports} reports {_RULE.margin_m:g} m or "
    "more inland, whatever its score, and rank those first (a vessel cannot sail there); "
    "--no-ashore judges by the model alone, as the paper does (use it on lakes and rivers "
    "above the tidal limit, which the coastline holds as land).",
)


PORTS = typer.Option(
    "--ports",
    help="Ports and anchorages as GeoJSON (Points; Polygons for port areas; a `name` names the "
    "port): where a vessel is not at sea, for port visits and encounters. Default: learned from "
    "the traffic, 0.5 km cells where 3 or more vessels stopped (detect: every report of --data, "
    "written to anchorages.geojson in --out, to edit and give back here; watch: the vessels' "
    "recent reports).",
    show_default=False,
)


WORKERS = typer.Option(
    "--workers",
    envvar="AISDATI_WORKERS",
    help="Where the command's tasks run: N local Dask processes (1: in this process), or the "
    "address of an existing Dask cluster (tcp://HOST:PORT; every worker must see the input and "
    "output folders). Results do not depend on it.",
)


DEVICE = typer.Option(
    "--device",
    help="Where DATI's networks run: cpu, cuda, cuda:N or auto (CUDA when torch sees a GPU). "
    "The environments, DTW and the other detectors always run on the CPU.",
)


LANE = typer.Option(
    "--lane",
    help="Override one lever of the preset, KEY=VALUE (repeatable): validation=true, "
    "region=box|corridor, corridor_km=2, state=position|motion, "
    "ranges=max|quantile, noise=gaussian|ou, fourier=6 (octaves of position features; 0 off), "
    "pretrain=50 (epochs of cloning before the adversarial training; 0 off), members=3 (seeds "
    "trained as one lane model), validation_tracks=8, validation_rollouts=3, "
    "validate_by=rollout|step, crossfit=true (members calibrated on vessel folds they did "
    "not train on).",
)


@dataclass(frozen=True)
class IngestOptions:
    """Read AIS files (MarineCadastre's or the Danish Maritime Authority's CSV or parquet, NMEA
    0183 logs; or MarineCadastre's files of a period, downloaded), then filter, clean, segment
    and cluster them into points.parquet, tracks.parquet, reports.parquet and
    ingest_report.json (with route clusters: routes.parquet, routes.geojson and routes.png)."""

    inputs: Annotated[
        list[str] | None,
        typer.Option(
            "--input",
            "-i",
            help="AIS file, glob or folder (.zip .csv .parquet; NMEA .nmea .ais .txt); repeatable.",
        ),
    ] = None
    download: Annotated[
        str | None,
        typer.Option(
            "--download",
            help="Download MarineCadastre's files of this period (2015 on): YYYY, YYYY-MM or "
            "YYYY-MM-DD, or a range A..B (2018-07-01..2018-07-07); 2015-2017 come by month, in "
            "the UTM zones --roi spans. A mirror: set AISDATI_BASE_URL.",
            show_default=False,
        ),
    ] = None
    data_dir: Annotated[
        Path, typer.Option(help="Download cache folder (a complete file is not fetched again).")
    ] = Path("data/raw")
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("data/processed")
    roi: Annotated[
        str,
        typer.Option(
            help="Region of interest: florida-straits (the paper's), none, or a "
            "GeoJSON Polygon/MultiPolygon file."
        ),
    ] = "florida-straits"
    since: Annotated[
        str | None,
        typer.Option(
            "--since",
            help="Take the reports from this date or ISO time on (UTC unless a zone is given; "
            "inclusive), e.g. 2018-08-01; the others are counted as outside_period.",
            show_default=False,
        ),
    ] = None
    until: Annotated[
        str | None,
        typer.Option(
            "--until",
            help="Take the reports before this date or ISO time (exclusive), e.g. 2018-08-01 "
            "or 2018-08-01T12:00.",
            show_default=False,
        ),
    ] = None
    min_sog: Annotated[float, typer.Option(help="Keep reports with SOG above this (knots).")] = 3.0
    max_speed: Annotated[
        float,
        typer.Option(
            help="Position outlier: implied speed from the previous kept report above this (kn)."
        ),
    ] = 50.0
    stop_gap: Annotated[
        str, typer.Option(help="Split a vessel's reports at gaps longer than this.")
    ] = "1h"
    min_points: Annotated[
        int, typer.Option(help="Keep tracks with at least this many reports.")
    ] = 900
    dwell_radius: Annotated[
        float,
        typer.Option(
            help="Stop by dwell: the vessel stays within this many metres (see --dwell-time)."
        ),
    ] = 500.0
    dwell_time: Annotated[
        str,
        typer.Option(
            help="Split a track where the vessel dwells (within --dwell-radius) this long; 0: only "
            "at --stop-gap gaps (the paper)."
        ),
    ] = "5min"
    route_min_tracks: Annotated[int, typer.Option(help="Fewest tracks of a route.")] = 5
    route_eps_km: Annotated[
        str,
        typer.Option(
            help="Route endpoint radius and shape tolerance in km; auto: HDBSCAN, no fixed scale."
        ),
    ] = "auto"
    keep_rejects: Annotated[
        bool,
        typer.Option(
            "--keep-rejects", help="Write every rejected row with its reason to rejects.parquet."
        ),
    ] = False
    workers: Annotated[str, WORKERS] = "1"
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the summary as JSON on stdout.")
    ] = False


@dataclass(frozen=True)
class SelftestOptions:
    """Train DATI (and the baselines or ablations) on the paper's synthetic families and compare
    with its Tables 1 and 2."""

    family: Annotated[
        list[str],
        typer.Option(
            "--family",
            "-f",
            help="Family to run (repeatable or comma-separated); 'all' = the paper's four.",
        ),
    ] = field(default_factory=lambda: ["all"])
    methods: Annotated[
        str,
        typer.Option(
            "--methods",
            "-m",
            help="Methods to compare, comma-separated: dati, bc, bc-paper, ddpg-ti (Table 1: all "
            "four), dati-no-time-embedding, dati-no-reward-input; or table2: the paper's ablation "
            "(DATI with and without time embedding and reward input; default family: circles).",
        ),
    ] = "dati"
    seeds: Annotated[int, typer.Option(help="Training seeds per family (paper: 10).")] = 10
    episodes: Annotated[
        int, typer.Option(help="Maximum training episodes per seed (paper: 100).")
    ] = 100
    steps: Annotated[
        int | None, typer.Option(help="Steps per episode τ (default: the family's, 200).")
    ] = None
    references: Annotated[
        int, typer.Option(help="Unseen test references per family (paper: 10).")
    ] = 10
    workers: Annotated[
        str,
        typer.Option(
            "--workers",
            envvar="AISDATI_WORKERS",
            help="Train the members on a local Dask cluster of this many processes (one per core; "
            "1: in this process), or on the existing one at this address (tcp://HOST:PORT).",
        ),
    ] = "2"
    device: Annotated[str, DEVICE] = "cpu"
    preset: Annotated[str, SELFTEST_PRESET] = "paper"
    repeats: Annotated[
        int,
        typer.Option(
            help="Run the whole protocol this many times on further seed blocks (its spread)."
        ),
    ] = 1
    quick: Annotated[
        bool, typer.Option("--quick", help="Smoke check: 2 seeds x 3 episodes x 40 steps.")
    ] = False
    out: Annotated[
        Path | None, typer.Option(help="Output folder (default runs/selftest-<time>).")
    ] = None
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the results as JSON on stdout.")
    ] = False


@dataclass(frozen=True)
class TrainOptions:
    """Train a detector on one cluster's tracks. DATI writes <out>/<cluster>.pt (weights only),
    the model card <cluster>.json, the training log <cluster>.log.jsonl and a resume checkpoint
    <cluster>.ckpt after every episode (removed when training finishes); bc and nearest write
    <cluster>-<method>.json beside their weights or tracks."""

    cluster: Annotated[
        str,
        typer.Option(
            "--cluster",
            "-c",
            help="Tracks to learn: a cluster (up, down, other), a route (route-<n>, unrouted), "
            "all: one model of the whole area (behaviour cloning by default), or routes: every "
            "route with enough tracks, each its own model and task (--workers spreads them).",
        ),
    ]
    method: Annotated[
        str | None,
        typer.Option(
            "--method",
            help="Detector: dati (the paper's), bc (behavioural cloning) or nearest (no learning). "
            "Default: bc for --cluster all (cross-fitted, judged by stepspread: it measured best "
            "forward in time), dati for a cluster or route.",
            show_default=False,
        ),
    ] = None
    data: Annotated[Path, typer.Option("--data", help="Ingest output folder.")] = Path(
        "data/processed"
    )
    out: Annotated[
        str,
        typer.Option(
            "--out",
            help="Model folder, or a URL the models are copied to (s3://bucket/models with s3fs, "
            "ftp://user:password@host/models, any fsspec URL): what a cluster's workers all reach.",
        ),
    ] = "models"
    preset: Annotated[str | None, PRESET] = None
    lane: Annotated[list[str] | None, LANE] = None
    episodes: Annotated[
        int, typer.Option(help="Maximum training episodes, one track each (paper).")
    ] = 170
    seed: Annotated[
        int, typer.Option(help="Random seed (networks, noise, track order, downsampling).")
    ] = 0
    max_tracks: Annotated[
        int,
        typer.Option(help="Downsample the cluster to this many tracks (paper: 170); 0 keeps all."),
    ] = 170
    patience: Annotated[
        int, typer.Option(help="Early stopping patience in episodes; 0 disables.")
    ] = 10
    resume: Annotated[
        bool,
        typer.Option("--resume", help="Continue exactly from <out>/<cluster>.ckpt if it exists."),
    ] = False
    workers: Annotated[str, WORKERS] = "1"
    device: Annotated[str, DEVICE] = "cpu"
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the model card as JSON on stdout.")
    ] = False


@dataclass(frozen=True)
class EvaluateOptions:
    """Measure detection on your own data: split a cluster's tracks by vessel, write anomalies
    (detours, position jumps, loitering, speed changes, gaps, point noise, shifted stretches,
    noisy reported course or speed, drift) into half of the held-out tracks, train the
    detectors on the rest and report how well each ranks and flags the altered tracks (ROC AUC,
    average precision, precision/recall/F1) and how the events find the altered stretches, per
    anomaly kind.
    Writes data/ (the injected set in ingest's schema, with labels.csv), models/,
    evaluation.json, scores.parquet, roc_pr.png and examples.png."""

    cluster: Annotated[
        str,
        typer.Option(
            "--cluster",
            "-c",
            help="Cluster (or route) whose tracks are split and altered; 'routes': every route "
            "with enough tracks, each judged by its own model, pooled into one table.",
        ),
    ]
    data: Annotated[Path, typer.Option("--data", help="Ingest output folder.")] = Path(
        "data/processed"
    )
    out: Annotated[
        Path | None, typer.Option("--out", help="Output folder (default runs/evaluate-<time>).")
    ] = None
    detectors: Annotated[
        str, typer.Option("--detectors", "-d", help="Detectors to compare, comma-separated.")
    ] = "nearest,dati,bc"
    kinds: Annotated[
        str,
        typer.Option(
            "--kinds",
            help="Anomaly kinds to inject, comma-separated (round-robin over the altered tracks).",
        ),
    ] = "detour,jump,loiter,speed,gap,noise"
    param: Annotated[
        list[str] | None,
        typer.Option(
            "--param",
            help="Change an anomaly parameter, KIND.NAME=LO-HI (repeatable): detour.span=0.2-0.35, "
            "detour.km=2-5, jump.span=0.1-0.2, jump.km=3-6, loiter.radius_km=0.5-1.5, "
            "loiter.loops=1-2, speed.span, speed.slow=0.3, speed.fast=2-3, gap.span=0.2-0.4, "
            "noise.fraction=0.2, noise.km=0.5-1, shift.span=0.05-0.2, shift.km=1-2, "
            "course-noise.sigma_deg=10-20, speed-noise.sigma_kn=2-5, drift.knots=1-5, "
            "drift.heading_deg=60-120 (and each kind's span).",
        ),
    ] = None
    before: Annotated[
        datetime | None,
        typer.Option(
            "--before",
            formats=["%Y-%m-%d", "%Y-%m-%dT%H:%M:%S"],
            help="Split by time instead of by vessel: train on the tracks that start before this "
            "day (UTC), judge every later one (forward in time), e.g. 2018-08-01.",
        ),
    ] = None
    altered: Annotated[
        float, typer.Option("--altered", help="Share of the judged tracks that take an anomaly.")
    ] = 0.5
    strength: Annotated[
        float, typer.Option("--strength", help="Anomaly distances x this (0.3: the subtle tier).")
    ] = 1.0
    at_sea: Annotated[
        bool,
        typer.Option(
            "--at-sea",
            help="Write only anomalies that put no more reports ashore than their track had "
            "(redrawn with new parameters, else the track stays normal and is counted): what a "
            "vessel could sail, which the ashore rule cannot see.",
        ),
    ] = False
    thin: Annotated[
        str | None,
        typer.Option(
            "--thin",
            help="Thin every track to one report per DURATION (e.g. 10min) before injection: "
            "each kind measured where one report moves a vessel kilometres. Default: off.",
            metavar="DURATION",
        ),
    ] = None
    fleet_kinds: Annotated[
        str,
        typer.Option(
            "--fleet-kinds",
            help="Fleet cases to construct in the area's untouched later traffic (from --before, "
            "else its later half by time), comma-separated: encounter, port-visit, "
            "identity-conflict, identity-change, gnss-interference, gap-heard, gap-quiet; "
            "'all' or 'none'. Each reports its recall and its kind's events per 1,000 "
            "vessel-days of that traffic.",
        ),
    ] = "all"
    fleet_cases: Annotated[
        int, typer.Option("--fleet-cases", help="Fleet cases per kind (seeded by --seed).")
    ] = 20
    models: Annotated[
        str | None,
        typer.Option(
            "--models",
            help="Use the models trained on this cluster in this folder or URL (and their "
            "training tracks) instead of training new ones.",
        ),
    ] = None
    preset: Annotated[str | None, PRESET] = None
    lane: Annotated[list[str] | None, LANE] = None
    episodes: Annotated[int, typer.Option(help="Training episodes of dati and bc.")] = 170
    ashore: Annotated[bool, ASHORE] = True
    contamination: Annotated[
        float,
        typer.Option(help="Calibrated flagging: share of training tracks a detector would flag."),
    ] = 0.05
    seed: Annotated[
        int, typer.Option(help="Seed of the split, the injections and the training.")
    ] = 0
    workers: Annotated[str, WORKERS] = "1"
    device: Annotated[str, DEVICE] = "cpu"
    as_json: Annotated[bool, typer.Option("--json", help="Print evaluation.json on stdout.")] = (
        False
    )


@dataclass(frozen=True)
class DetectOptions:
    """Score test tracks against trained models and find events: writes scores.parquet,
    profiles.parquet, anomalies.geojson, events.parquet, events.geojson, map.png, map.html and
    report.json to --out and prints the flagged tracks and the events."""

    data: Annotated[Path, typer.Option("--data", help="Ingest output folder.")] = Path(
        "data/processed"
    )
    models_dir: Annotated[
        str,
        typer.Option(
            "--models",
            help="Model folder, or the URL `train --out` copied them to; `none`: no model, "
            "only the events that need none (drift, sudden speed change, gap, inconsistent "
            "motion, loitering, ashore) over every report.",
        ),
    ] = "models"
    model: Annotated[
        list[str] | None,
        typer.Option("--model", "-m", help="Model name in --models (repeatable); default: all."),
    ] = None
    method: Annotated[
        str | None,
        typer.Option(
            "--method",
            help="Use the models of this detector: dati, bc or nearest. Default: the first of "
            "these the folder has models of.",
        ),
    ] = None
    score: Annotated[
        str | None,
        typer.Option(
            "--score",
            help="How a policy judges a track: lane (distance to where its K free rollouts go; "
            "for nearest: to where the training tracks go), rollout (the best free rollout's DTW, "
            "the paper's), step (teacher-forced one-step errors, m) or stepspread (those errors "
            "over the spread of the model's draws). Default: the model's own (its card says).",
            show_default=False,
        ),
    ] = None
    out: Annotated[
        Path | None, typer.Option("--out", help="Report folder (default reports/<time>).")
    ] = None
    cluster: Annotated[
        str,
        typer.Option(
            "--cluster",
            help="Test tracks: a cluster (up, down, other), a route (route-<n>, unrouted) or all.",
        ),
    ] = "other"
    track: Annotated[
        list[int] | None,
        typer.Option("--track", help="Judge these track ids instead (repeatable)."),
    ] = None
    ashore: Annotated[bool, ASHORE] = True
    contamination: Annotated[
        float,
        typer.Option(
            "--contamination",
            help="The default rule: flag scores above each model's calibrated threshold, which "
            "flags this share of its own training tracks; a track's flag does not depend on the "
            "other tracks judged with it.",
        ),
    ] = 0.05
    alerts_per_1000: Annotated[
        float,
        typer.Option(
            "--alerts-per-1000",
            help="The alert budget: the alerts that need no model (position jumps, inconsistent "
            "speed or course, drift, sudden speed change, ashore) are raised at the thresholds "
            "that would have raised this many per 1,000 vessel-days on the models' training "
            "period, so next month's rate lands near it; tracks are flagged by --contamination "
            "and by any alert. Models from before the budget, and --models none, use the "
            "documented defaults. Activity (loitering, gaps) is listed and flags nothing.",
        ),
    ] = ALERTS_PER_1000
    threshold: Annotated[
        float | None,
        typer.Option(
            "--threshold",
            help="The paper's rule instead (Λ, section 6.2: 0.75): flag scores above this share of "
            "the largest score of the tracks judged together, in (0, 1]; depends on the batch.",
            show_default=False,
        ),
    ] = None
    top_percent: Annotated[
        float | None,
        typer.Option(
            "--top-percent",
            help="Flag this percentage of the highest scores of the batch instead.",
            show_default=False,
        ),
    ] = None
    near_km: Annotated[
        float,
        typer.Option(
            "--near-km", help="Test tracks start within this distance of a training start."
        ),
    ] = 10.0
    ports: Annotated[Path | None, PORTS] = None
    workers: Annotated[str, WORKERS] = "1"
    device: Annotated[str, DEVICE] = "cpu"
    labels: Annotated[
        Path | None,
        typer.Option(
            "--labels",
            help="CSV of labels: track_id,label[,kind], mmsi,start,label[,kind] (0/1), or an "
            "incident list mmsi,start,end[,kind] (a track overlapping a window of its vessel is an "
            "anomaly, every other one normal); with kinds, metrics per kind.",
        ),
    ] = None
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON on stdout.")] = (
        False
    )


@dataclass(frozen=True)
class WatchOptions:
    """Watch a live AIS feed (or replay a recording): judge each vessel's recent reports as
    they arrive with the event kinds that need no model, and keep the events opened, extended
    and closed in a database (SQLite, or PostgreSQL), optionally on a live page."""

    source: Annotated[
        str,
        typer.Option(
            "--input",
            "-i",
            help="tcp://HOST:PORT (connect, reconnecting with back-off), udp://:PORT (listen), a "
            "file or folder of NMEA (replayed; as fast as possible unless --speed), or - (stdin).",
            show_default=False,
        ),
    ]
    db: Annotated[
        str,
        typer.Option(
            "--db",
            help="Where the events and vessels go: a SQLite file, or postgresql://USER@HOST/DB. "
            "A restart on the same database resumes its open events.",
        ),
    ] = "aisdati-watch.sqlite"
    serve: Annotated[
        str | None,
        typer.Option(
            "--serve",
            help="Serve the live page (offline coastline, vessels with their course, open and "
            "recent events with filters, the feed's health) at HOST:PORT, e.g. 127.0.0.1:8080; "
            "after a replay it keeps the final state until Ctrl-C.",
            show_default=False,
        ),
    ] = None
    notify: Annotated[
        list[str] | None,
        typer.Option(
            "--notify",
            help="POST each alert as it opens and as it closes, as one JSON object, to this "
            "http(s) URL (a webhook; repeatable). Tried 3 times, never holding up the watch; "
            "failures are counted on stderr.",
            show_default=False,
        ),
    ] = None
    speed: Annotated[
        float | None,
        typer.Option(
            "--speed",
            help="Replay a file at this many times real time by its reports' times (default: as "
            "fast as possible).",
            show_default=False,
        ),
    ] = None
    window: Annotated[
        str,
        typer.Option(
            "--window", help="How much of each vessel's recent reports is judged (e.g. 3h, 90min)."
        ),
    ] = "3h"
    max_vessels: Annotated[
        int,
        typer.Option(
            "--max-vessels",
            help="Vessels kept at most; beyond, the longest silent are forgotten (and counted).",
        ),
    ] = 50_000
    as_json: Annotated[
        bool,
        typer.Option(
            "--json", help="Print each event change as one JSON line on stdout, and nothing else."
        ),
    ] = False
    models_dir: Annotated[
        str | None,
        typer.Option(
            "--models",
            help="Model folder or URL (as `detect --models`): judge with the alert budget "
            "its models calibrated on their training period and the water their traffic "
            "sailed, instead of the defaults.",
            show_default=False,
        ),
    ] = None
    alerts_per_1000: Annotated[
        float,
        typer.Option(
            "--alerts-per-1000",
            help="With --models: the alert budget, as `detect --alerts-per-1000` (the alerts "
            "per 1,000 vessel-days the models' training period would have raised).",
        ),
    ] = ALERTS_PER_1000
    ports: Annotated[Path | None, PORTS] = None
