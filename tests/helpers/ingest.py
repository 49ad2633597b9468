"""The clean New York Harbor hour through `aisdati ingest` (`--json`), and what the tests that
damage a copy of it compare with: its rows, its lines, its points."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq

DATA = Path(__file__).resolve().parents[1] / "data"
NY_HOUR = "NYHarbor_2020_06_30_first_hour.csv"
NY_ROWS = 8689
SETTINGS = ("--roi", "none", "--min-points", "20")


def ingest(cli, out: Path, *inputs, extra=SETTINGS):
    args = ["ingest", *[a for i in inputs for a in ("--input", i)], "--out", out, *extra]
    result = cli(*args, "--json")
    return result, (json.loads(result.stdout) if result.exit_code == 0 else None)


def leftovers(folder: Path) -> list[str]:
    names = [p.name for p in folder.iterdir()] if folder.exists() else []
    return sorted(n for n in names if ".tmp" in n or n.startswith(".ingest-"))


def ingest_ny_hour(out: Path) -> dict:
    """The clean NY hour ingested into `out`: its report."""
    from typer.testing import CliRunner

    from aisdati.cli import app

    src = DATA / NY_HOUR
    args = ["ingest", "--input", str(src), "--out", str(out), *SETTINGS, "--json"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["rows_read"] == NY_ROWS and report["tracks"]["total"] > 20
    return report


def ny_lines(data: Path) -> list[bytes]:
    return (data / NY_HOUR).read_bytes().splitlines(keepends=True)


def ny_table(data: Path) -> pd.DataFrame:
    """The NY hour as text, exactly as written (blanks stay blank)."""
    return pd.read_csv(data / NY_HOUR, dtype=str, keep_default_na=False)


def points(out: Path) -> pd.DataFrame:
    return pq.read_table(out / "points.parquet").to_pandas()
