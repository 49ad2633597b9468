"""Where `aisdati ingest`'s time goes, stage by stage (not a test): the CPU seconds of each piece
of the read stage and of the per-vessel stages, each run alone on one thread, on the big CSV of
`ingest_speed.py` (built there, or here with the same rows).

The CPU time of a piece run alone is what it costs whatever else the machine runs (a wall
clock on 2 shared cores is not); the command itself spreads the read over three threads and the
vessel tasks over two, so its wall time is less than the sum.

Usage: python benchmarks/ingest_stages.py [--rows 2000000] [--work-dir data/raw/bench-stages]
[--json PATH]
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from ingest_speed import build
from report import Report, add_json_option

from aisdati.preprocess.clean import check_values, filter_area_speed, filter_period
from aisdati.preprocess.convert import PARTITION_SCHEMA, to_canonical
from aisdati.preprocess.fastcsv import ColumnSlots, parse_block, typed_batch
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.layouts import resolve_columns
from aisdati.preprocess.lineguard import BLOCK_SIZE, LineGuard
from aisdati.preprocess.partition import VesselPartitions, write_split
from aisdati.preprocess.read import SourceReader
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.tasks import (
    ReadTask,
    ReportsTask,
    VesselTask,
    read_source,
    report_stages,
    vessel_stages,
)

ROOT = Path(__file__).resolve().parents[1]


def cpu(fn: Callable[[], object]) -> tuple[float, object]:
    """CPU seconds of this process (all its threads) while `fn` runs, and what it returned."""
    start = time.process_time()
    out = fn()
    return time.process_time() - start, out


def blocks_of(csv: Path) -> tuple[list[bytes], list[str]]:
    """The CSV's blocks as the line guard hands them on, and its header's names."""
    with csv.open("rb") as f:
        names = f.readline().decode().strip().split(",")
        f.seek(0)
        guard = LineGuard(f, lambda _: None, 1)
        blocks = []
        while len(block := guard.read(BLOCK_SIZE)):
            blocks.append(bytes(block))
    return blocks, names


def read_pieces(csv: Path, spill: Path, settings: IngestSettings) -> list[tuple[str, float]]:
    """CPU seconds of each piece of the read stage, one after the other on this thread."""
    rows = []
    seconds, (blocks, names) = cpu(lambda: blocks_of(csv))
    rows.append(("read + line guard (header search, UTF-8 and quote checks)", seconds))
    columns = resolve_columns(names, csv.name)
    slots = ColumnSlots.of(names, columns)
    seconds, parsed = cpu(lambda: [parse_block(b, slots) for b in blocks])
    rows.append(("scan: the compiled parse of every field read (fast path)", seconds))
    seconds, tables = cpu(
        lambda: [to_canonical(typed_batch(p, slots, columns), columns, 0) for p in parsed]
    )
    rows.append(("typing the parsed columns (`to_canonical`)", seconds))
    seconds, _ = cpu(lambda: [p.static_tally() for p in parsed])
    rows.append(("vessel tallies: the static hashes counted per block", seconds))

    def check() -> list:
        for table, codes in tables:
            table = check_values(table, codes)
            filter_period(table, codes, settings)
            filter_area_speed(table, codes, None, settings)
        return tables

    seconds, _ = cpu(check)
    rows.append(("clean + filter: sentinels, ranges, period, SOG", seconds))
    shutil.rmtree(spill, ignore_errors=True)
    spill.mkdir(parents=True)
    parts = [VesselPartitions(spill, 6, PARTITION_SCHEMA, prefix=p) for p in ("part", "slow")]

    def write() -> None:
        for table, codes in tables:
            which = np.where(codes == 0, 0, np.where(codes == CODE["slow"], 1, -1))
            write_split(table, which, parts)
        for p in parts:
            p.close()

    seconds, _ = cpu(write)
    rows.append(("spill: moving and slow reports into vessel partitions", seconds))
    return rows


def vessel_pieces(csv: Path, spill: Path, settings: IngestSettings) -> list[tuple[str, float]]:
    """CPU seconds of the whole read task, then of the per-vessel tasks on its spill files."""
    shutil.rmtree(spill, ignore_errors=True)
    spill.mkdir(parents=True)
    task = ReadTask(Source(csv), 0, spill / "src", 6, settings, None)
    read_s, read = cpu(lambda: read_source(task))
    tracks_s = reports_s = 0.0
    for part in range(len(read.spills)):
        moving = (read.spills[part],) if read.rows[part] else ()
        slow = (read.slow_spills[part],) if read.slow_rows[part] else ()
        points = spill / f"points-{part:05d}.arrow"
        rows = int(read.rows[part])
        vessel = VesselTask(part, moving, rows, points, settings, (csv.name,))
        seconds, _ = cpu(lambda t=vessel: vessel_stages(t))
        tracks_s += seconds
        out = spill / f"reports-{part:05d}.arrow"
        every = ReportsTask(part, moving + slow, rows + int(read.slow_rows[part]), out, settings)
        seconds, _ = cpu(lambda t=every: report_stages(t))
        reports_s += seconds
    return [
        ("the read task whole (all of the above, on its threads)", read_s),
        ("tracks: moving reports cleaned per vessel, segmented, made tracks", tracks_s),
        ("reports: every report cleaned per vessel (reports.parquet's rows)", reports_s),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=2_000_000)
    parser.add_argument("--work-dir", type=Path, default=ROOT / "data" / "raw" / "bench-stages")
    add_json_option(parser, "ingest_stages")
    args = parser.parse_args()
    _, csv, n = build(args.rows, args.work_dir)
    settings = IngestSettings(min_points=5)
    SourceReader(Source(csv))  # (the header read; numba's caches loaded below, once)
    read_pieces(csv, args.work_dir / "warm", settings)
    pieces = read_pieces(csv, args.work_dir / "spill", settings)
    pieces += vessel_pieces(csv, args.work_dir / "spill", settings)
    with Report.from_args("ingest_stages", args) as out:
        out.say(f"{n:,} rows of {csv}; load average {os.getloadavg()[0]:.2f}")
        table = out.table(["stage", "CPU s", "per 10 M rows"], title="Where ingest's CPU goes")
        for name, seconds in pieces:
            per = seconds * 1e7 / n
            table.row(
                [name, f"{seconds:.3f}", f"{per:.2f} s"],
                {"stage": name, "rows": n, "cpu_s": seconds, "cpu_s_per_10m": per},
            )


if __name__ == "__main__":
    main()
