"""Speed and memory of `aisdati ingest` on a large MarineCadastre-like zip (not a test).

Builds a zip of at least 10 million rows by repeating the real rows of
tests/data/AIS_2022_01_03_head.zip, each copy shifted by whole days (so vessels keep realistic
tracks and the copies do not collide), then measures, each in a fresh subprocess so peak RSS is
its own:

* aisdati ingest (the whole pipeline; rows/s through read+clean+filter and overall),
* a naive pandas.read_csv of the zip + the same row filters,
* DuckDB's CSV reader on the unzipped CSV, when duckdb is installed (`pip install -e
  '.[bench]'`; a near-limit reference, not a dependency of aisdati): its query time is its
  read+filter rate, printed beside aisdati's read+clean+filter rate.

Usage: python benchmarks/ingest_speed.py [--rows 10000000] [--work-dir data/raw/bench] [--workers N]
[--json PATH]
Prints a markdown table, its rows as JSON in benchmarks/results/ingest_speed.json. `--workers N`
runs aisdati's tasks on N local Dask workers; the zip is one member, so one read task: its rate
is that of one worker, the later stages are shared.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import zipfile
from datetime import date, timedelta
from pathlib import Path

from report import Report, add_json_option  # (this folder: run as a script)

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "tests" / "data" / "AIS_2022_01_03_head.zip"

PANDAS = """
import sys, pandas as pd
df = pd.read_csv(sys.argv[1], usecols=["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG"])
df["BaseDateTime"] = pd.to_datetime(df["BaseDateTime"])
ok = (df.SOG > 3) & (df.SOG < 102.3) & (df.COG < 360) & (df.LAT.abs() <= 90) & (df.LON.abs() <= 180)
print(int(ok.sum()))
"""

DUCKDB = """
import sys, time, duckdb
duckdb.sql("SET enable_progress_bar = false")  # it would print its bar on stdout
start = time.perf_counter()
n = duckdb.sql(
    "SELECT count(*) FROM read_csv('" + sys.argv[1] + "', header=true) "
    "WHERE SOG > 3 AND SOG < 102.3 AND COG < 360 AND abs(LAT) <= 90 AND abs(LON) <= 180"
).fetchall()[0][0]
print(n, time.perf_counter() - start)
"""
"""Prints the rows kept and the seconds of the query alone (its read+filter stage)."""


def build(rows: int, work: Path) -> tuple[Path, Path, int]:
    """The big zip (and its CSV, for DuckDB), built once per size and reused: named by the
    number of copies, so that another `--rows` never measures a stale input."""
    work.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(SEED) as zf:
        seed = zf.read("AIS_2022_01_03.csv")
    header, body = seed.split(b"\n", 1)
    n_seed = body.count(b"\n")
    copies = -(-rows // n_seed)
    big_zip, big_csv = work / f"AIS_big_{copies}x.zip", work / f"AIS_big_{copies}x.csv"
    if not big_zip.exists() or not big_csv.exists():
        with open(big_csv, "wb") as out:
            out.write(header + b"\n")
            for k in range(copies):
                day = (date(2022, 1, 3) + timedelta(days=k)).isoformat().encode()
                out.write(body.replace(b"2022-01-03T", day + b"T"))
        tmp = big_zip.with_suffix(".tmp")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            zf.write(big_csv, big_csv.name)
        os.replace(tmp, big_zip)
    return big_zip, big_csv, copies * n_seed


LAUNCHER = """
import resource, subprocess, sys, time
start = time.perf_counter()
proc = subprocess.run(sys.argv[1:], capture_output=True, text=True)
seconds = time.perf_counter() - start
sys.stderr.write(proc.stderr)
print(seconds, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, proc.returncode)
print(proc.stdout, end="")
"""
"""Runs one command as its only child, so the children's peak RSS is that command's alone."""

AISDATI = "import sys; sys.argv[0] = 'aisdati'; from aisdati.cli import app; app()"
"""The `aisdati` console script, run as `python -c` so that it is this interpreter's: argv[0] is
set before the import, so the package starts as the console script does."""


def measure(argv: list[str]) -> tuple[float, float, str]:
    """Wall seconds, peak RSS (MiB) and stdout of a fresh subprocess."""
    proc = subprocess.run([sys.executable, "-c", LAUNCHER, *argv], capture_output=True, text=True)
    first, _, stdout = proc.stdout.partition("\n")
    seconds, rss_kib, code = first.split()
    if int(code):
        sys.exit(f"{argv[:4]} failed:\n{proc.stderr}")
    return float(seconds), int(rss_kib) / 1024, stdout


def _ingest_command() -> list[str]:
    """['ingest'], or [] while Typer collapses a one-command app into that command."""
    import typer

    from aisdati.cli import app

    return ["ingest"] if hasattr(typer.main.get_command(app), "commands") else []


def _ingest(source: Path, out: Path, roi: str, workers: int) -> list[str]:
    cmd = [sys.executable, "-c", AISDATI, *_ingest_command(), "--input", str(source)]
    cmd += ["--out", str(out), "--roi", roi, "--min-points", "5", "--json"]
    return [*cmd, "--workers", str(workers)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000_000)
    parser.add_argument("--work-dir", type=Path, default=ROOT / "data" / "raw" / "bench")
    parser.add_argument("--workers", type=int, default=1, help="aisdati ingest --workers")
    add_json_option(parser, "ingest_speed")
    args = parser.parse_args()
    with Report.from_args("ingest_speed", args) as out:
        run(args, out)


def run(args: argparse.Namespace, out: Report) -> None:
    """Build the input, measure every method, print the table."""
    big_zip, big_csv, n = build(args.rows, args.work_dir)
    out.say(f"input: {big_zip} ({n:,} rows, {big_zip.stat().st_size / 2**20:.0f} MiB zipped)")
    results = []
    measure(_ingest(SEED, args.work_dir / "warm-up", "none", 1))  # numba's caches, once
    runs = [(big_zip, "florida-straits"), (big_zip, "none"), (big_csv, "none")]
    for source, roi in runs:
        folder = args.work_dir / f"out-{roi}-{source.suffix[1:]}"
        seconds, rss, stdout = measure(_ingest(source, folder, roi, args.workers))
        report = json.loads(stdout)
        stage = report["stage_seconds"]["read_clean_filter"]
        results.append(
            (
                f"aisdati ingest --roi {roi} --workers {args.workers} ({source.suffix[1:]})",
                seconds,
                n / stage,
                n / seconds,
                rss,
                report,
            )
        )
    try:
        import duckdb  # noqa: F401

        seconds, rss, stdout = measure([sys.executable, "-c", DUCKDB, str(big_csv)])
        query = float(stdout.split()[1])
        results.append(
            ("DuckDB read_csv + filter (unzipped CSV)", seconds, n / query, n / seconds, rss, None)
        )
    except ImportError:
        out.say("duckdb is not installed (pip install -e '.[bench]'): no DuckDB row")
    seconds, rss, _ = measure([sys.executable, "-c", PANDAS, str(big_zip)])
    results.append(("pandas.read_csv + filter", seconds, None, n / seconds, rss, None))

    out.say(f"\n{os.cpu_count()} CPU cores; {n:,} rows\n")
    columns = ["method", "wall s", "rows/s read+clean+filter", "rows/s overall", "peak RSS MiB"]
    table = out.table(columns, title=f"Ingest of {n:,} rows")
    for name, seconds, stage_rate, rate, rss, _ in results:
        stage_text = f"{stage_rate / 1e6:.2f} M" if stage_rate else "-"
        table.row(
            [name, f"{seconds:.1f}", stage_text, f"{rate / 1e6:.2f} M", f"{rss:.0f}"],
            {"method": name, "rows": n, "seconds": seconds, "stage_rows_per_s": stage_rate,
             "rows_per_s": rate, "peak_rss_mib": rss},
        )  # fmt: skip
    for name, *_, report in results:
        if report:
            out.say(f"\n{name}: kept {report['kept_points']:,} points, tracks {report['tracks']}")


if __name__ == "__main__":
    main()
