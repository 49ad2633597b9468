"""Speed and memory of `aisdati watch` (`aisdati.live`) on one core, not a test.

Feeds built from the shipped real positions, each report a type 1 NMEA sentence (pyais) after a
tag block with its time, as a receiver logs them:

* `kitimat`: Kitimat's 134,758 reports of July-August 2018 in time order
  (tests/data/AIS_2018_07-08_Kitimat.csv.gz; 29 vessels at once at most): the old feed;
* `NxR`: N vessels at once, each R consecutive real reports of one vessel at their own real
  intervals: the US day's vessels first (tests/data/AIS_2022_01_03_head.zip: 10,631 vessels,
  a report every ~70 s), then Kitimat's; every vessel starts within `SPREAD_S` of the others,
  so all N are in the watch together; past the real vessels' stretches one is used again under
  another MMSI (the same positions at another time); `NxR-kitimat`: Kitimat's alone, in a
  Kitimat area model's region. Built once and kept in `--cache`.

For each feed, in a process of its own (its peak RSS its own): messages/s through `Watch.step`
(decode, ingest's checks, each chunk of `sources.REPLAY_LINES` lines' vessels screened and
judged, events into SQLite), with `--models DIR` its area model's judgement too, and decoding
alone beside it. The feed goes through twice, each time into a new watch and database: a
first pass over its first `WARM_LINES` lines loads the coastline of the feed's area (once per
process: ~7 s for the US coast) and compiles what numba compiles; the second, over the whole
feed, is the watch running (the figure); the peak RSS is the process's. With `--reference
SRC`, the same on the first `--reference-lines` lines by the code at SRC (e.g. `git archive
main | tar -x -C SRC`), beside the same lines by this code.

Latency at offered rates on the `--latency-feed`: lines arrive on a schedule of N per second;
each pass of the loop takes every line arrived by then (as a socket's read does); a line's
latency is from its arrival to its chunk's changes committed (the coastline of the feed's area
loaded before, as in a watch running). The machine's load is printed before and after each row.

Run: python benchmarks/watch_speed.py [--feeds kitimat,1000x120,10000x12,50000x12]
[--rates 1000,5000,20000] [--seconds 8] [--models DIR] [--reference SRC] [--json PATH]
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
KITIMAT = DATA / "AIS_2018_07-08_Kitimat.csv.gz"
US_DAY = DATA / "AIS_2022_01_03_head.zip"
COLUMNS = ["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG", "Heading"]
SPREAD_S = 600
"""The vessels of an `N x R` feed start within this many seconds of each other."""
MAX_STEP_S = 1800
"""A vessel's stretch of R reports is used only if no two of them lie further apart (a
stretch across days would move the feed's clock past the other vessels' reports)."""
FIRST_MMSI = 201_000_000
WARM_LINES = 20_000
"""The first pass (module docstring) goes through this many lines of the feed."""
TARGETS = {"10000x12": 20_000, "50000x12": 10_000, "10000x32-kitimat": 5_000}
"""msg/s the issue asks of the watch on one core, by feed (the last with an area model)."""


def checksum(text: str) -> str:
    return f"{functools.reduce(lambda a, c: a ^ ord(c), text, 0):02X}"


def sentences(frame: pd.DataFrame) -> list[bytes]:
    """Reports (mmsi, t, lat, lon, sog, cog, heading) as tag-blocked type 1 sentences."""
    from pyais.encode import encode_dict

    lines = []
    for row in frame.itertuples(index=False):
        report = {"type": 1, "mmsi": int(row.mmsi), "lat": row.lat, "lon": row.lon,
                  "speed": min(row.sog, 102.2), "course": row.cog % 360,
                  "heading": int(row.heading) if 0 <= row.heading < 360 else 511}  # fmt: skip
        tag = f"c:{int(row.t)}"
        lines.append(f"\\{tag}*{checksum(tag)}\\{encode_dict(report, talker_id='AI')[0]}".encode())
    return lines


def real(path: Path) -> pd.DataFrame:
    """A MarineCadastre file's reports, by vessel then time (t: seconds since the epoch)."""
    f = pd.read_csv(path, usecols=COLUMNS)
    t = pd.to_datetime(f["BaseDateTime"], utc=True) - pd.Timestamp(0, tz="UTC")
    return pd.DataFrame({
        "mmsi": f["MMSI"], "t": t // pd.Timedelta(seconds=1), "lat": f["LAT"], "lon": f["LON"],
        "sog": f["SOG"], "cog": f["COG"], "heading": f["Heading"],
    }).sort_values(["mmsi", "t"], kind="stable", ignore_index=True)  # fmt: skip


def stretches(frame: pd.DataFrame, per: int) -> list[pd.DataFrame]:
    """Each vessel's reports cut into stretches of `per` consecutive ones (the rest dropped),
    those with no step over `MAX_STEP_S`."""
    rank = frame.groupby("mmsi").cumcount().to_numpy()
    key = frame["mmsi"].to_numpy() * 100_000 + rank // per
    whole = pd.Series(key).map(pd.Series(key).value_counts()).to_numpy() == per
    out = []
    for _, g in frame[whole].groupby(key[whole], sort=False):
        if np.diff(g["t"].to_numpy()).max(initial=0) <= MAX_STEP_S:
            out.append(g)
    return out


def concurrent(n: int, per: int, sources: list[Path], seed: int = 0) -> list[bytes]:
    """`n` vessels at once, `per` real reports each of `sources` in turn (module docstring),
    in time order."""
    rng = np.random.default_rng(seed)
    pool = [g for source in sources for g in stretches(real(source), per)]
    start = 1_700_000_000 + rng.integers(0, SPREAD_S, n)
    parts = []
    for i in range(n):
        g = pool[i % len(pool)]
        t = g["t"].to_numpy()
        parts.append(g.assign(mmsi=FIRST_MMSI + i, t=t - t[0] + start[i]))
    return sentences(pd.concat(parts).sort_values("t", kind="stable"))


def kitimat() -> list[bytes]:
    """The old feed: Kitimat's reports in time order."""
    return sentences(real(KITIMAT).sort_values("t", kind="stable"))


def feed(name: str, cache: Path) -> Path:
    """The feed `name` as a file of lines, built once into `cache`: `kitimat`, `NxR` (the US
    day's vessels, then Kitimat's) or `NxR-kitimat` (Kitimat's alone: in a Kitimat model's
    region)."""
    path = cache / f"{name}.nmea"
    if not path.exists():
        cache.mkdir(parents=True, exist_ok=True)
        size, _, only = name.partition("-")
        n, _, per = size.partition("x")
        sources = [KITIMAT] if only == "kitimat" else [US_DAY, KITIMAT]
        lines = kitimat() if name == "kitimat" else concurrent(int(n), int(per), sources)
        tmp = path.with_suffix(".tmp")
        tmp.write_bytes(b"\n".join(lines) + b"\n")
        tmp.rename(path)
    return path


# --------------------------------------------------------------- measured in a process of its own
def throughput(path: Path, lines: int | None, models: Path | None) -> dict:
    """Messages/s through the watch and through the decoder alone, vessels held at the end,
    changes, and the process's peak RSS."""
    from aisdati.live.decode import Decoder
    from aisdati.live.loop import Watch
    from aisdati.live.sources import REPLAY_LINES
    from aisdati.live.store import open_store

    feed_lines = path.read_bytes().splitlines()[:lines]
    area = None
    if models is not None:
        from aisdati.detectors import load_detectors
        from aisdati.live.area import AreaJudge

        area = AreaJudge.of(load_detectors(models, []))
    took = []
    for run in (feed_lines[:WARM_LINES], feed_lines):
        with tempfile.TemporaryDirectory() as tmp:
            watch = Watch(open_store(str(Path(tmp) / "w.sqlite")), area=area)
            t0 = time.perf_counter()
            most = 0
            for k in range(0, len(run), REPLAY_LINES):
                watch.step(run[k : k + REPLAY_LINES])
                most = max(most, len(watch.vessels.recent))
            took.append((time.perf_counter() - t0) / len(run))
            watch.store.close()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    Decoder().reports(feed_lines)
    decoded = time.perf_counter() - t0
    return {"messages": len(feed_lines), "vessels": len(watch.vessels.recent),
            "most_vessels": most,
            "judged_per_s": 1 / took[1], "cold_per_s": 1 / took[0],
            "decoded_per_s": len(feed_lines) / decoded, "changes": watch.counters.changes,
            "area_model": area is not None, "peak_rss_mb": rss}  # fmt: skip


def latency(path: Path, rate: float, seconds: float) -> dict:
    """Lines arriving at `rate` a second for `seconds`; each loop pass takes all arrived."""
    from aisdati.live.loop import Watch
    from aisdati.live.store import open_store

    lines = path.read_bytes().splitlines()[: int(rate * seconds)]
    with tempfile.TemporaryDirectory() as tmp:  # the coastline of the feed's area loaded first
        for k in range(0, len(lines), 2000):
            Watch(open_store(str(Path(tmp) / "warm.sqlite"))).step(lines[k : k + 2000])
        watch = Watch(open_store(str(Path(tmp) / "rate.sqlite")))
        arrival = np.arange(len(lines)) / rate
        waits, k, start = [], 0, time.monotonic()
        while k < len(lines):
            now = time.monotonic() - start
            if arrival[k] > now:
                time.sleep(arrival[k] - now)
                now = arrival[k]
            j = int(np.searchsorted(arrival, now, side="right"))
            watch.step(lines[k:j])
            waits.append(time.monotonic() - start - arrival[k:j])
            k = j
        took = time.monotonic() - start
    lag = np.concatenate(waits)
    return {"rate": rate, "messages": len(lines), "achieved_per_s": len(lines) / took,
            **{f"p{q}_s": float(np.percentile(lag, q)) for q in (50, 95, 99)},
            "max_s": float(lag.max())}  # fmt: skip


def measured(src: Path, what: dict) -> dict:
    """`what` measured by the code at `src` in a process of its own (one core's worth)."""
    env = {**os.environ, "PYTHONPATH": str(src), "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    got = subprocess.run(
        [sys.executable, __file__, "--measure", json.dumps(what)],
        env=env, cwd=src, capture_output=True, text=True, check=False,
    )  # fmt: skip
    if got.returncode:
        raise SystemExit(f"measuring {what} failed:\n{got.stderr[-3000:]}")
    return json.loads(got.stdout.splitlines()[-1])


def measure(what: dict) -> dict:
    path = Path(what["path"])
    if what["kind"] == "latency":
        return latency(path, what["rate"], what["seconds"])
    models = Path(what["models"]) if what.get("models") else None
    return throughput(path, what.get("lines"), models)


def load() -> str:
    return "/".join(f"{x:.1f}" for x in os.getloadavg())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--feeds", default="kitimat,1000x120,10000x12,50000x12")
    ap.add_argument("--rates", default="1000,5000,20000")
    ap.add_argument("--seconds", type=float, default=8.0, help="wall seconds of each rate")
    ap.add_argument("--latency-feed", default="10000x12")
    ap.add_argument("--models", type=Path, help="a folder with an area model: judged with it")
    ap.add_argument("--model-feeds", default="10000x32-kitimat",
                    help="the feeds judged with --models (in its region; a vessel is judged "
                         "by it once its window holds 30 reports, and every 20 after)")  # fmt: skip
    ap.add_argument("--reference", type=Path, help="another checkout's root: its code measured")
    ap.add_argument("--reference-lines", type=int, default=10_000)
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "aisdati-feeds")
    ap.add_argument("--measure", help=argparse.SUPPRESS)
    add_json_option(ap, "watch_speed")
    args = ap.parse_args()
    if args.measure:
        print(json.dumps(measure(json.loads(args.measure))))
        return
    feeds = {name: feed(name, args.cache) for name in args.feeds.split(",")}
    with Report.from_args("watch_speed", args) as report:
        report.note(f"one process per row, one core's work; load (1/5/15 min) at start {load()}")
        columns = ["feed", "code", "lines", "vessels at once", "msg/s", "target",
                   "first pass msg/s", "decode only", "peak RSS MB",
                   "load before/after"]  # fmt: skip
        table = report.table(columns, title="watch: throughput, model-free unless said")
        rows = [(name, None) for name in feeds]
        if args.models:
            rows += [(name, args.models) for name in args.model_feeds.split(",")]
            feeds |= {name: feed(name, args.cache) for name in args.model_feeds.split(",")}
        for name, models in rows:
            runs = [("this", ROOT, None)]
            if args.reference and models is None:
                lines = args.reference_lines
                runs += [("this", ROOT, lines), ("reference", args.reference, lines)]
            for code, src, lines in runs:
                before = load()
                got = measured(src, {"kind": "throughput", "path": str(feeds[name]),
                                     "lines": lines, "models": str(models or "")})  # fmt: skip
                target = TARGETS.get(name) if lines is None else None
                table.row(
                    [name + (" + area model" if models else ""), code, f"{got['messages']:,}",
                     f"{got['most_vessels']:,}", f"{got['judged_per_s']:,.0f}",
                     f"{target:,}" if target else "", f"{got['cold_per_s']:,.0f}",
                     f"{got['decoded_per_s']:,.0f}",
                     f"{got['peak_rss_mb']:.0f}", f"{before} / {load()}"],
                    {**got, "feed": name, "code": code, "target": target},
                )  # fmt: skip
        columns = ["rate msg/s", "achieved", "p50 s", "p95 s", "p99 s", "max s", "load"]
        title = f"watch: latency on {args.latency_feed}, arrival to committed (target p99 1 s)"
        table = report.table(columns, title=title)
        for rate in (float(r) for r in args.rates.split(",")):
            path = str(feed(args.latency_feed, args.cache))
            got = measured(ROOT, {"kind": "latency", "path": path, "rate": rate,
                                  "seconds": args.seconds})  # fmt: skip
            table.row([f"{rate:,.0f}", f"{got['achieved_per_s']:,.0f}", f"{got['p50_s']:.3f}",
                       f"{got['p95_s']:.3f}", f"{got['p99_s']:.3f}", f"{got['max_s']:.3f}",
                       load()], got)  # fmt: skip


if __name__ == "__main__":
    main()
