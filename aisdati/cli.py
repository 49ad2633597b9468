"""Command line of aisdati: thin wrappers that parse options, call one function per stage and
print with rich. Every user mistake surfaces as a `UserError` and is shown as one red line."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer
from rich.console import Console

from aisdati.errors import UserError

app = typer.Typer(
    help="aisdati: find abnormal vessel tracks in AIS data with DATI (domain-adaptive trajectory "
    "imitation).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)


def user_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Turn `UserError` (and Ctrl-C) into a one-line message and a non-zero exit code."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except UserError as exc:
            err_console.print(f"[bold red]error:[/] {exc}", highlight=False)
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/]")
            raise typer.Exit(130) from None

    return wrapper


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
    keep_rejects: bool = typer.Option(
        False, "--keep-rejects", help="Write every rejected row with its reason to rejects.parquet."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars or table."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON on stdout."),
) -> None:
    """Read MarineCadastre AIS files (downloaded or local), then filter, clean, segment and
    cluster them into points.parquet, tracks.parquet and ingest_report.json."""
    import json

    from rich.progress import (
        BarColumn,
        DownloadColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    from aisdati.preprocess.download import download, marinecadastre_files
    from aisdati.preprocess.pipeline import ingest as run_ingest
    from aisdati.preprocess.read import expand_inputs
    from aisdati.preprocess.report import summary_table
    from aisdati.preprocess.roi import load_roi
    from aisdati.preprocess.settings import IngestSettings, parse_duration

    if not inputs and year is None:
        raise UserError("nothing to ingest: give --input FILES or --year (with --months/--zone)")
    settings = IngestSettings(
        min_sog_kn=min_sog,
        max_speed_kn=max_speed,
        stop_gap_s=parse_duration(stop_gap),
        min_points=min_points,
        keep_rejects=keep_rejects,
    )
    area = load_roi(roi)
    remote = marinecadastre_files(year, months, days, zone) if year is not None else []
    local = expand_inputs(inputs) if inputs else []
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
        console.print(f"wrote {', '.join(result.outputs.values())}", highlight=False)
