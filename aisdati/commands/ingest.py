"""`aisdati ingest`: download or find the AIS files, run the preprocessing pipeline, print its
summary (or JSON)."""

from __future__ import annotations

import json
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn

from aisdati.commands.common import console, err_console, warn
from aisdati.commands.tables import routes_table, summary_table
from aisdati.errors import UserError
from aisdati.execution.runner import Execution
from aisdati.options import check_options
from aisdati.outdir import prepare_output_dir
from aisdati.preprocess.download import download, marinecadastre_files
from aisdati.preprocess.inputs import expand_inputs
from aisdati.preprocess.output import DATASET_NAMES, OUTPUT_NAMES
from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.roi import load_roi
from aisdati.preprocess.settings import IngestSettings, parse_duration


def run(
    inputs: list[str] | None,
    year: int | None,
    months: str,
    days: str | None,
    zone: int | None,
    data_dir: Path,
    base_url: str | None,
    force: bool,
    out: Path,
    roi: str,
    min_sog: float,
    max_speed: float,
    stop_gap: str,
    min_points: int,
    dwell_radius: float,
    dwell_time: str,
    clusters: str,
    route_min_tracks: int,
    route_eps_km: str,
    route_seed: int,
    keep_rejects: bool,
    workers: int,
    scheduler: str | None,
    quiet: bool,
    as_json: bool,
) -> None:
    """`aisdati ingest` with its options (see `aisdati.cli.ingest`): its tasks on `workers`
    local processes, or on the Dask cluster at `scheduler` (whose workers must see the inputs
    and --out at the same paths: ingest's spill files and staged outputs live in --out)."""
    check_options({"--min-sog": min_sog, "--max-speed": max_speed, "--route-seed": route_seed})
    execution = Execution(workers=workers, scheduler=scheduler)
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
        route_eps_km=parse_route_eps(route_eps_km),
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
    prepare_output_dir(out, "--out", OUTPUT_NAMES, DATASET_NAMES)
    if remote:
        prepare_output_dir(data_dir, "--data-dir")
    with download_progress(err_console if as_json else console, quiet) as progress:
        files = download(remote, data_dir, base_url, force, progress=progress) + local
        result = ingest(files, out, settings, area, roi, progress, execution)
    if as_json:
        print(json.dumps(result.as_dict(), default=str))
    elif not quiet:
        console.print(summary_table(result.counts))
        if result.routes is not None:
            console.print(routes_table(result.routes))
        console.print(f"wrote {escape(', '.join(result.outputs.values()))}", highlight=False)


def parse_route_eps(text: str) -> float | None:
    """--route-eps-km: a number of km, or None for auto (HDBSCAN picks the scale)."""
    if text.strip().lower() == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--route-eps-km {text!r}: expected a number of km or auto") from None


def download_progress(where: Console, quiet: bool) -> Progress:
    """The bars of the downloads and the pipeline's stages (their text names input files:
    printed as it is, not as markup); off when quiet or not a terminal."""
    return Progress(
        TextColumn("{task.description}", markup=False),
        BarColumn(),
        DownloadColumn(),
        TimeRemainingColumn(),
        console=where,
        disable=quiet or not where.is_terminal,
        transient=True,
    )
