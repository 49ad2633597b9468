"""`aisdati ingest`: download or find the AIS files, run the preprocessing pipeline, print its
summary (or JSON)."""

from __future__ import annotations

import json

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn
from shapely.geometry import MultiPolygon, Polygon

from aisdati.commands.common import console, shows_progress, warn
from aisdati.commands.options import IngestOptions
from aisdati.commands.tables import routes_table, summary_table
from aisdati.errors import UserError
from aisdati.execution.runner import Execution
from aisdati.options import check_options
from aisdati.outdir import prepare_output_dir, removed_if_left_empty
from aisdati.preprocess.download import download as fetch_files
from aisdati.preprocess.download import marinecadastre_files, utm_zones
from aisdati.preprocess.inputs import expand_inputs
from aisdati.preprocess.output import DATASET_NAMES, OUTPUT_NAMES
from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.roi import load_roi
from aisdati.preprocess.settings import IngestSettings, parse_duration, parse_since_until


def run(o: IngestOptions) -> None:
    """`aisdati ingest` with its options (`aisdati.commands.options.IngestOptions`): its tasks
    on `--workers` local processes, or on the Dask cluster at that address (whose workers must
    see the inputs and --out at the same paths: ingest's spill files and staged outputs live in
    --out)."""
    check_options({"--min-sog": o.min_sog, "--max-speed": o.max_speed})
    execution = Execution.parse(o.workers)
    if not o.inputs and o.download is None:
        raise UserError("nothing to ingest: give --input FILES or --download PERIOD")
    since, until = parse_since_until(o.since, o.until)
    settings = IngestSettings(
        since=since,
        until=until,
        min_sog_kn=o.min_sog,
        max_speed_kn=o.max_speed,
        stop_gap_s=parse_duration(o.stop_gap),
        min_points=o.min_points,
        keep_rejects=o.keep_rejects,
        dwell_radius_m=o.dwell_radius,
        dwell_time_s=parse_duration(o.dwell_time, "--dwell-time", allow_zero=True),
        route_min_tracks=o.route_min_tracks,
        route_eps_km=parse_route_eps(o.route_eps_km),
    )
    check_options(
        {
            "--stop-gap": settings.stop_gap_s,
            "--dwell-time": settings.dwell_time_s,
            "--dwell-radius": settings.dwell_radius_m,
            "--route-eps-km": settings.route_eps_km,
        }
    )
    area = load_roi(o.roi, warn=warn)
    remote = marinecadastre_files(o.download, roi_zones(area)) if o.download is not None else []
    local = expand_inputs(o.inputs) if o.inputs else []
    with removed_if_left_empty(o.out):
        prepare_output_dir(o.out, "--out", OUTPUT_NAMES, DATASET_NAMES)
        if remote:
            prepare_output_dir(o.data_dir, "--data-dir")
        with download_progress(console, shows_progress(o.as_json)) as progress:
            files = fetch_files(remote, o.data_dir, progress=progress) + local
            result = ingest(files, o.out, settings, area, o.roi, progress, execution)
    if not sum(result.counts.tracks.values()):
        warn(
            f"no track kept, so nothing for a model to learn from; reports.parquet holds "
            f"{result.counts.reports_kept:,} reports to judge (`aisdati detect --models none`); "
            "for tracks, loosen --min-points, --min-sog, --stop-gap or --dwell-time"
        )
    if o.as_json:
        print(json.dumps(result.as_dict(), default=str))
    else:
        console.print(summary_table(result.counts))
        if result.routes is not None:
            console.print(routes_table(result.routes))
        console.print(f"wrote {escape(', '.join(result.outputs.values()))}", highlight=False)


def roi_zones(area: Polygon | MultiPolygon | None) -> list[int] | None:
    """The UTM zones the region of interest spans (what the 2015-2017 files are cut by); None
    without a region."""
    if area is None:
        return None
    lon_min, _, lon_max, _ = area.bounds
    return utm_zones(lon_min, lon_max)


def parse_route_eps(text: str) -> float | None:
    """--route-eps-km: a number of km, or None for auto (HDBSCAN picks the scale)."""
    if text.strip().lower() == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise UserError(f"--route-eps-km {text!r}: expected a number of km or auto") from None


def download_progress(where: Console, show: bool) -> Progress:
    """The bars of the downloads and the pipeline's stages (their text names input files:
    printed as it is, not as markup); off unless `show` (`shows_progress`)."""
    return Progress(
        TextColumn("{task.description}", markup=False),
        BarColumn(),
        DownloadColumn(),
        TimeRemainingColumn(),
        console=where,
        disable=not (show and where.is_terminal),
        transient=True,
    )
