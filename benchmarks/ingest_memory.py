"""Memory and per-member cost of `aisdati ingest` on hostile archives (issue 27; not a test).

Two inputs, both built from the real rows of tests/data/NYHarbor_2020_06_30_first_hour.csv:

* a zip bomb of one vessel: the busiest vessel under way sailing its real track forth and back,
  at its real times between reports, until the CSV is `--bomb-mb` MB, deflated at level 9; all
  of it lands in one vessel partition, which must be split by time to stay bounded;
* the whole hour cut into `--members` zip members, against the same rows in one member.

Each ingest runs in a fresh subprocess (`ingest_speed.measure`), so its peak RSS is its own.

Usage: python benchmarks/ingest_memory.py [--bomb-mb 590] [--members 3000] [--work-dir DIR]
[--json PATH]
Prints a markdown table, its rows as JSON in benchmarks/results/ingest_memory.json.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
import zipfile
from collections import Counter
from operator import itemgetter
from pathlib import Path

import numpy as np
from ingest_speed import AISDATI, measure
from report import Report, add_json_option

ROOT = Path(__file__).resolve().parents[1]
SEED = ROOT / "tests" / "data" / "NYHarbor_2020_06_30_first_hour.csv"


def build_bomb(path: Path, megabytes: int) -> int:
    """The one-vessel zip bomb; returns its rows. The busiest vessel under way sails its real
    track forth and back, with its real times between reports, and no gap long enough to split
    its history safely: the split must cut it at times."""
    with SEED.open(newline="") as f:
        header, *body = list(csv.reader(f))
    mmsi, when, sog = (header.index(c) for c in ("MMSI", "BaseDateTime", "SOG"))
    moving = [r for r in body if float(r[sog] or 0) > 3]
    counts = Counter(r[mmsi] for r in moving)
    busiest = counts.most_common(1)[0][0]
    track = sorted((r for r in moving if r[mmsi] == busiest), key=itemgetter(when))
    times = np.array([r[when] for r in track], dtype="datetime64[s]").astype(np.int64)
    steps = np.maximum(np.diff(times), 1)
    cycle = track + track[::-1]
    cycle_steps = np.r_[steps, 1, steps[::-1], 1]
    pieces = []
    for row in cycle:
        text = io.StringIO()
        csv.writer(text, lineterminator="\n").writerow([*row[:when], "\0", *row[when + 1 :]])
        pieces.append(text.getvalue().split("\0"))
    n, now = 0, int(times[0])
    with (
        zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf,
        zf.open("bomb.csv", "w", force_zip64=True) as member,
    ):
        member.write((",".join(header) + "\n").encode())
        written = 0
        while written < megabytes * 10**6:
            reps = 50
            stamps = now + np.r_[0, np.cumsum(np.tile(cycle_steps, reps))[:-1]]
            now = int(stamps[-1] + cycle_steps[-1])
            iso = np.datetime_as_string(stamps.astype("datetime64[s]"))
            rows = zip(pieces * reps, iso, strict=True)
            lines = [f"{left}{t}{right}" for (left, right), t in rows]
            chunk = "".join(lines).encode()
            member.write(chunk)
            written += len(chunk)
            n += len(lines)
    return n


def build_members(path: Path, members: int) -> int:
    """The NY hour cut into `members` zip members (one member when `members` is 1)."""
    header, *lines = SEED.read_bytes().splitlines(keepends=True)
    per = -(-len(lines) // members)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for k in range(members):
            zf.writestr(f"part-{k:05d}.csv", header + b"".join(lines[k * per : (k + 1) * per]))
    return len(lines)


def ingest(archive: Path, out: Path) -> tuple[float, float, dict]:
    cmd = [sys.executable, "-c", AISDATI, "ingest", "--input", str(archive), "--out", str(out)]
    cmd += ["--roi", "none", "--min-points", "20", "--json"]
    seconds, rss, stdout = measure(cmd)
    return seconds, rss, json.loads(stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bomb-mb", type=int, default=590)
    parser.add_argument("--members", type=int, default=3000)
    parser.add_argument("--work-dir", type=Path, default=ROOT / "data" / "raw" / "bench-hostile")
    add_json_option(parser, "ingest_memory")
    args = parser.parse_args()
    work = args.work_dir
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    bomb = work / f"bomb-{args.bomb_mb}MB.zip"
    if not bomb.exists():
        build_bomb(bomb, args.bomb_mb)
    with zipfile.ZipFile(bomb) as zf:
        csv_mb = zf.getinfo("bomb.csv").file_size / 1e6
    seconds, rss, report = ingest(bomb, work / "out-bomb")
    rows.append((f"zip bomb, one vessel ({csv_mb:.0f} MB of CSV)", bomb, report, seconds, rss))
    for members in (1, args.members):
        archive = work / f"members-{members}.zip"
        build_members(archive, members)
        seconds, rss, report = ingest(archive, work / f"out-members-{members}")
        rows.append((f"NY hour in {members:,} zip member(s)", archive, report, seconds, rss))
    with Report.from_args("ingest_memory", args) as out:
        columns = ["input", "zip MB", "rows read", "kept points", "wall s", "peak RSS MiB"]
        table = out.table(columns, title="aisdati ingest on hostile archives")
        for name, archive, report, seconds, rss in rows:
            zip_mb = archive.stat().st_size / 1e6
            table.row(
                [name, f"{zip_mb:.1f}", f"{report['rows_read']:,}", f"{report['kept_points']:,}",
                 f"{seconds:.1f}", f"{rss:.0f}"],
                {"input": name, "zip_mb": zip_mb, "rows_read": report["rows_read"],
                 "kept_points": report["kept_points"], "seconds": seconds, "peak_rss_mib": rss},
            )  # fmt: skip
        one, many = rows[-2][3], rows[-1][3]
        out.say(f"\n{args.members:,} members take {many / one:.2f}x the time of one member")


if __name__ == "__main__":
    main()
