"""Speed and memory of `aisdati watch` (`aisdati.live`) on one core, not a test.

The feed is built from the shipped data: Kitimat's reports of July-August 2018
(tests/data/AIS_2018_07-08_Kitimat.csv.gz) encoded as NMEA sentences (type 1, pyais) each after
a tag block with its time, as a receiver logs them. Three measurements:

* throughput: the whole feed as fast as possible through `Watch.step` (decode, ingest's
  checks, every vessel judged once per chunk of `sources.REPLAY_LINES` lines by the model-free
  kinds, with `--models DIR` its area model's judgement every `area.EVERY` reports too, events
  into SQLite), and decoding alone beside it;
* latency at rising rates: lines arrive on a schedule of N per second; each pass of the loop
  takes every line arrived by then (as a socket's read does); a line's latency is from its
  arrival to its chunk's changes committed: percentiles over the lines;
* memory: 20,000 vessels each with a full window of reports (3 hours every 30 s), held by
  `Vessels`; its bytes and the process's peak RSS.

Run: python benchmarks/watch_speed.py [--rates 1000,5000,20000] [--seconds 8] [--models DIR]
[--json PATH]
"""

from __future__ import annotations

import argparse
import functools
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
from pyais.encode import encode_dict
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.detectors import load_detectors
from aisdati.live.area import AreaJudge
from aisdati.live.decode import Decoder
from aisdati.live.loop import Watch
from aisdati.live.sources import REPLAY_LINES
from aisdati.live.store import open_store
from aisdati.live.vessels import Vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA

KITIMAT = Path(__file__).resolve().parents[1] / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz"


def checksum(text: str) -> str:
    return f"{functools.reduce(lambda a, c: a ^ ord(c), text, 0):02X}"


def feed() -> list[bytes]:
    """Kitimat's reports as tag-blocked NMEA lines, in time order."""
    frame = pd.read_csv(KITIMAT, usecols=["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG",
                                          "Heading"]).sort_values("BaseDateTime")  # fmt: skip
    epoch = pd.Timestamp(0, tz="UTC")
    seconds = (pd.to_datetime(frame["BaseDateTime"], utc=True) - epoch) // pd.Timedelta(seconds=1)
    lines = []
    for row, t in zip(frame.itertuples(index=False), seconds, strict=True):
        report = {"type": 1, "mmsi": int(row.MMSI), "lat": row.LAT, "lon": row.LON,
                  "speed": min(row.SOG, 102.2), "course": row.COG % 360,
                  "heading": int(row.Heading) if 0 <= row.Heading < 360 else 511}  # fmt: skip
        tag = f"c:{t}"
        lines.append(f"\\{tag}*{checksum(tag)}\\{encode_dict(report, talker_id='AI')[0]}".encode())
    return lines


def throughput(lines: list[bytes], folder: Path, area: AreaJudge | None = None) -> dict:
    watch = Watch(open_store(str(folder / "fast.sqlite")), area=area)
    t0 = time.perf_counter()
    for k in range(0, len(lines), REPLAY_LINES):
        watch.step(lines[k : k + REPLAY_LINES])
    judged = time.perf_counter() - t0
    t0 = time.perf_counter()
    Decoder().reports(lines)
    decoded = time.perf_counter() - t0
    return {"messages": len(lines), "vessels": len(watch.vessels.recent),
            "judged_per_s": len(lines) / judged, "decoded_per_s": len(lines) / decoded,
            "changes": watch.counters.changes}  # fmt: skip


def latency(lines: list[bytes], rate: float, folder: Path) -> dict:
    """Lines arriving at `rate` a second; each loop pass takes all arrived by then."""
    watch = Watch(open_store(str(folder / f"rate-{rate:g}.sqlite")))
    arrival = np.arange(len(lines)) / rate
    waits, k, start = [], 0, time.monotonic()
    while k < len(lines):
        now = time.monotonic() - start
        if arrival[k] > now:
            time.sleep(arrival[k] - now)
            now = arrival[k]
        j = int(np.searchsorted(arrival, now, side="right"))
        watch.step(lines[k:j])
        done = time.monotonic() - start
        waits.append(done - arrival[k:j])
        k = j
    lag = np.concatenate(waits)
    took = time.monotonic() - start
    return {"rate": rate, "messages": len(lines), "achieved_per_s": len(lines) / took,
            **{f"p{q}_s": float(np.percentile(lag, q)) for q in (50, 95, 99)},
            "max_s": float(lag.max())}  # fmt: skip


def memory(n_vessels: int = 20_000, per_vessel: int = 360) -> dict:
    """`n_vessels` full windows (3 h every 30 s) held by `Vessels`."""
    vessels = Vessels()
    t = (np.arange(per_vessel) * 30.0 * 1e6).astype(np.int64)
    for first in range(0, n_vessels, 1000):
        mmsi = np.repeat(np.arange(first, first + 1000, dtype=np.int64) + 200_000_000, per_vessel)
        n = len(mmsi)
        vessels.add(pa.table(
            [mmsi, pa.array(np.tile(t, 1000)).cast(pa.timestamp("us", "UTC")),
             np.random.uniform(-130, -128, n), np.random.uniform(53, 54, n), np.full(n, 10.0),
             np.full(n, 90.0), np.full(n, 90.0, np.float32), pa.nulls(n, pa.int16()),
             np.zeros(n, np.int32)],
            schema=PARTITION_SCHEMA,
        ))  # fmt: skip
    for m in list(vessels.recent):
        vessels.window(m)
    return {"vessels": len(vessels.recent), "reports_each": per_vessel,
            "window_mb": vessels.nbytes() / 2**20,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="1000,5000,20000")
    ap.add_argument("--seconds", type=float, default=8.0, help="wall seconds of each rate")
    ap.add_argument("--models", type=Path, help="a folder with an area model: judged with it")
    add_json_option(ap, "watch_speed")
    args = ap.parse_args()
    lines = feed()
    with Report.from_args("watch_speed", args) as report, tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        area = AreaJudge.of(load_detectors(args.models, [])) if args.models else None
        fast = throughput(lines, folder, area)
        table = report.table(["measure", "value"], title="watch: throughput (one core)")
        table.row(
            ["messages (vessels held at the end)", f"{fast['messages']:,} ({fast['vessels']})"],
            fast,
        )
        judged = "decoded and judged" + (" (area model too)" if area else "")
        table.row([judged, f"{fast['judged_per_s']:,.0f} msg/s"])
        table.row(["decoded only", f"{fast['decoded_per_s']:,.0f} msg/s"])
        columns = ["rate msg/s", "achieved", "p50 s", "p95 s", "p99 s", "max s"]
        table = report.table(columns, title="watch: latency, arrival to committed")
        for rate in (float(r) for r in args.rates.split(",")):
            got = latency(lines[: int(rate * args.seconds)], rate, folder)
            table.row([f"{rate:,.0f}", f"{got['achieved_per_s']:,.0f}", f"{got['p50_s']:.3f}",
                       f"{got['p95_s']:.3f}", f"{got['p99_s']:.3f}", f"{got['max_s']:.3f}"],
                      got)  # fmt: skip
        mem = memory()
        table = report.table(["vessels", "reports each", "windows MB", "peak RSS MB"],
                             title="watch: memory")  # fmt: skip
        table.row([f"{mem['vessels']:,}", mem["reports_each"], f"{mem['window_mb']:.0f}",
                   f"{mem['peak_rss_mb']:.0f}"], mem)  # fmt: skip


if __name__ == "__main__":
    main()
