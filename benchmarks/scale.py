"""aisdati on 1 and 2 Dask workers, from ingest to detect, on an input built from real rows (not
a test).

The input: the real rows of the shipped Kitimat two months and NY Harbor week, copied until
`--rows` rows, each copy its own vessels (MMSI shifted), in its own place (moved by whole
tenths of degrees on a grid, so every copy's lanes are routes of their own) and its own time
(shifted by whole days): realistic tracks, many vessels, many routes. Written once as CSV files
of `--rows-per-file` rows (MarineCadastre's format; the NY copies without SOG/COG, which ingest
derives) under `--work-dir`.

For `--workers 1` and `2`, each command runs in a fresh process with the RSS of its process tree
sampled every 0.2 s:

* ingest of the whole input (`--roi none --min-points 50`): rows/s overall;
* train `--cluster routes` (DATI, `--episodes`, `--max-tracks`) on a separate ingest of the
  first three Kitimat copies (`--min-points 100`: its 3 routes in three places, 9 routes;
  minutes, not days);
* detect `--cluster all` with those models of an ingest of twelve later Kitimat copies in the
  same three places (other vessels, later days): tracks/s.

It prints one markdown table (seconds, rate, peak RSS of the largest process, which is a worker
when there are workers, and of the command's own process, speed-up and scaling efficiency of 2
workers over 1) and a projection of a national year (3e9 reports, 12 M tracks, 2,000 routes)
on 16 and 64 workers, from the 2-worker rates per worker and the measured 2-worker efficiency
held constant: a projection, not a measurement. `--stages ingest` runs the ingest alone.

Usage: python benchmarks/scale.py [--rows 100000000] [--work-dir data/raw/scale]
       [--episodes 2] [--max-tracks 10] [--stages ingest] [--json PATH]
(the tables' rows also go as JSON to benchmarks/results/scale.json)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
from ingest_speed import AISDATI as CONSOLE_SCRIPT
from report import Report, add_json_option

ROOT = Path(__file__).resolve().parents[1]
SEEDS = {
    "kitimat": ROOT / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz",
    "nyharbor": ROOT / "tests" / "data" / "NYHarbor_2020_12_first_week_points.csv.gz",
}
GRID = 10
"""Copies sit on a GRID x GRID grid of places, 0.3 degrees apart (then shift in time)."""
STEP_DEG = 0.3
NATIONAL_YEAR = {"rows": 3e9, "tracks": 12e6, "routes": 2000}
"""MarineCadastre's US coast: 7-10 M reports a day; a month holds about 1 M tracks."""
AISDATI = [sys.executable, "-c", CONSOLE_SCRIPT]


def seed_table(path: Path) -> pa.Table:
    types = {"BaseDateTime": pa.timestamp("s"), "MMSI": pa.int64()}
    table = pcsv.read_csv(path, convert_options=pcsv.ConvertOptions(column_types=types))
    names = ("MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG")
    return table.select([c for c in names if c in table.column_names])


def copy_of(table: pa.Table, k: int) -> pa.Table:
    """Copy k of a seed: other vessels, another place, another time."""
    place, block = k % (GRID * GRID), k // (GRID * GRID)
    dlon, dlat = STEP_DEG * (place % GRID), STEP_DEG * (place // GRID)
    mmsi = table["MMSI"].to_numpy()
    mmsi = (mmsi - 100_000_000 + k * 7_919_003) % 899_999_999 + 100_000_000
    shift = pa.scalar(block * 8 * 86_400, pa.duration("s"))  # whole days
    times = pc.add(table["BaseDateTime"], shift)
    columns = {
        "MMSI": pa.array(mmsi),
        "BaseDateTime": pc.strftime(times, "%Y-%m-%dT%H:%M:%S"),
        "LAT": pc.add(table["LAT"], dlat),
        "LON": pc.add(table["LON"], dlon),
    }
    for name in ("SOG", "COG"):
        if name in table.column_names:
            columns[name] = table[name]
    return pa.table(columns)


TRAIN_COPIES = (0, 1, 2)
"""Kitimat's copies to train on: its lanes in three places, 9 routes (3 per place at
`--min-points 100`): the issue's "training of at least 8 routes"."""
DETECT_COPIES = tuple(GRID * GRID * block + p for block in (1, 2, 3, 4) for p in TRAIN_COPIES)
"""Kitimat's copies to judge: the same two places, four later blocks of days, other vessels."""


def build(rows: int, rows_per_file: int, work: Path) -> tuple[Path, Path, Path, int]:
    """The input folders (all of it, the copies to train on and those to judge), built once."""
    full, small, later = work / f"rows-{rows}", work / "train-input", work / "detect-input"
    done = full / "DONE"
    if done.exists():
        return full, small, later, int(done.read_text())
    for folder in (full, small, later):
        folder.mkdir(parents=True, exist_ok=True)
    seeds = {name: seed_table(path) for name, path in SEEDS.items()}
    for k in TRAIN_COPIES:
        pcsv.write_csv(copy_of(seeds["kitimat"], k), small / f"kitimat-{k}.csv")
    for k in DETECT_COPIES:
        pcsv.write_csv(copy_of(seeds["kitimat"], k), later / f"kitimat-{k}.csv")
    written, k, part, buffer = 0, 0, 0, {name: [] for name in seeds}
    while written < rows:
        for name, table in seeds.items():
            copy = copy_of(table, k)
            buffer[name].append(copy)
            written += copy.num_rows
        k += 1
        for name in seeds:
            if sum(t.num_rows for t in buffer[name]) >= rows_per_file or written >= rows:
                pcsv.write_csv(pa.concat_tables(buffer[name]), full / f"{name}-{part:04d}.csv")
                buffer[name], part = [], part + 1
    done.write_text(str(written))
    return full, small, later, written


def measured(args: list[str], report: bool = True) -> tuple[float, tuple[float, float], dict]:
    """Run `aisdati ARGS --json` in a fresh process (its JSON read where `report`):
    (seconds, peak RSS in MiB of (its largest process, the command's own process), its JSON
    output)."""
    start = time.perf_counter()
    flag = "--json"
    with tempfile.TemporaryFile("w+") as stdout:  # a report can outgrow a pipe's buffer
        proc = subprocess.Popen([*AISDATI, *args, flag], stdout=stdout, text=True)
        root, peak, own = psutil.Process(proc.pid), 0, 0
        while proc.poll() is None:
            try:
                procs = [root, *root.children(recursive=True)]
                peak = max([peak, *(p.memory_info().rss for p in procs if p.is_running())])
                own = max(own, root.memory_info().rss)
            except psutil.Error:
                pass
            time.sleep(0.2)
        seconds = time.perf_counter() - start
        stdout.seek(0)
        out = stdout.read()
    if proc.returncode != 0:
        raise SystemExit(f"aisdati {' '.join(args)} failed ({proc.returncode})")
    last = [line for line in out.splitlines() if line.startswith("{")]
    doc = json.loads(last[-1]) if report and last else {}
    return seconds, (peak / 2**20, own / 2**20), doc


def stages(
    workers: int, inputs: tuple[Path, Path, Path], work: Path, opts: argparse.Namespace
) -> dict:
    full, small, later = inputs
    w = ["--workers", str(workers)]
    out, tout, dout, models = (
        work / f"{x}-{workers}" for x in ("ingest", "train-ingest", "detect-ingest", "models")
    )
    ingest = ["ingest", "--roi", "none", "--min-points", "50", *w]
    s, mem, doc = measured([*ingest, "--input", str(full), "--out", str(out)])
    result = {"ingest": (s, doc["rows_read"] / s, "rows/s", mem)}
    if opts.stages == ["ingest"]:
        return result
    for source, target in ((small, tout), (later, dout)):
        measured(["ingest", "--roi", "none", "--min-points", "100", *w, "--input", str(source),
                  "--out", str(target)])  # fmt: skip
    train = ["train", "--cluster", "routes", "--data", str(tout), "--out", str(models),
             "--episodes", str(opts.episodes), "--max-tracks", str(opts.max_tracks),
             *w]  # fmt: skip
    s, mem, _ = measured(train, report=False)
    routes = len(list(models.glob("route-*.pt")))
    result["train"] = (s, routes / s * 3600, "routes/h", mem)
    detect = ["detect", "--cluster", "all", "--data", str(dout), "--models", str(models),
              "--out", str(work / f"detect-{workers}"), *w]  # fmt: skip
    s, mem, doc = measured(detect)
    result["detect"] = (s, doc["test_tracks"] / s, "tracks/s", mem)
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000_000)
    ap.add_argument("--rows-per-file", type=int, default=5_000_000)
    ap.add_argument("--work-dir", type=Path, default=ROOT / "data" / "raw" / "scale")
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--max-tracks", type=int, default=10)
    ap.add_argument("--stages", default="ingest,train,detect",
                    help="ingest alone (its memory at scale) or all three")  # fmt: skip
    add_json_option(ap, "scale")
    opts = ap.parse_args()
    opts.stages = opts.stages.split(",")
    if opts.stages not in (["ingest"], ["ingest", "train", "detect"]):
        raise SystemExit("--stages: ingest, or ingest,train,detect")
    with Report.from_args("scale", opts) as report:
        run(opts, report)


def run(opts: argparse.Namespace, report: Report) -> None:
    """Build the input, run the stages on 1 and 2 workers, print the tables."""
    *inputs, rows = build(opts.rows, opts.rows_per_file, opts.work_dir)
    files = len(list(inputs[0].glob("*.csv")))
    report.say(f"input: {rows:,} rows in {files} files under {inputs[0]}")
    runs = {w: stages(w, tuple(inputs), opts.work_dir, opts) for w in (1, 2)}
    report.say()
    columns = ["stage", "workers", "seconds", "rate", "peak RSS of one process",
               "of the command's process", "speed-up", "efficiency"]  # fmt: skip
    table = report.table(columns, title="1 and 2 Dask workers")
    for stage in opts.stages:
        for w in (1, 2):
            s, rate, unit, (mem, own) = runs[w][stage]
            up = runs[1][stage][0] / s
            table.row(
                [stage, w, f"{s:.1f}", f"{rate:,.1f} {unit}", f"{mem:,.0f} MiB",
                 f"{own:,.0f} MiB", f"{up:.2f}x", f"{up / w:.0%}"],
                {"stage": stage, "workers": w, "seconds": s, "rate": rate, "unit": unit,
                 "peak_rss_mib": mem, "command_rss_mib": own, "speed_up": up,
                 "efficiency": up / w, "rows": rows},
            )  # fmt: skip
    if opts.stages == ["ingest"]:
        return
    report.say("\nProjection of a national year (3e9 reports, 12 M tracks, 2,000 routes), at the "
               "2-worker rate per worker (its efficiency held):\n")  # fmt: skip
    table = report.table(["stage", "16 workers", "64 workers"], title="National year (projected)")
    need = {"ingest": NATIONAL_YEAR["rows"], "train": NATIONAL_YEAR["routes"],
            "detect": NATIONAL_YEAR["tracks"]}  # fmt: skip
    for stage, amount in need.items():
        _, rate2, unit, _ = runs[2][stage]
        per_worker = rate2 / 2 / (3600 if unit == "routes/h" else 1)  # per second
        hours = [amount / (per_worker * n) / 3600 for n in (16, 64)]
        table.row(
            [stage, f"{hours[0]:,.1f} h", f"{hours[1]:,.1f} h"],
            {"stage": stage, "amount": amount, "hours_16_workers": hours[0],
             "hours_64_workers": hours[1]},
        )  # fmt: skip


if __name__ == "__main__":
    main()
