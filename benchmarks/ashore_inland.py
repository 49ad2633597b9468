"""False `ashore` events on the US days before and after inland water (`aisdati.inland_water`):
the model-free ashore kind (`aisdati.events.behaviour.ashore`, no model and so no `seen` water,
as `detect --models none` and `watch` judge) with the coastline alone, then with the lakes and
rivers. Every vessel of these files is honest traffic, so every ashore event is a false one.

The US days: MarineCadastre's national file of 2022-01-03 (tests/data/AIS_2022_01_03_head.zip,
its first 99,999 rows: 10,631 vessels, mostly the first 25 minutes of the day) and the US coast
day of 2020-06-30 (tests/data/US_coastal_2020_06_30_points.csv.gz: 1,185 vessels, positions).
A vessel-day is one vessel reporting on one UTC day. Also: the share of the land that was
ashore (a point and its margin all land) in the 1-degree tiles the traffic reports in, which
inland water makes no longer ashore (the land where a spoofed position is no longer seen), and
the time of the land test over every report, the tiles cut and again (`aisdati.coastline` keeps
the last 256 tiles: a day over more tiles cuts some of them again). An event is a run of
reports ashore: a vessel whose whole track was ashore (on a lake) had one event before, and may
have several after (the reports at its docks, which Natural Earth's outline leaves ashore).

Run: python benchmarks/ashore_inland.py [--json PATH]
(prints markdown tables, their rows as JSON in benchmarks/results/ashore_inland.json)
"""

from __future__ import annotations

import argparse
import os
import time
import zipfile
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from report import Report, add_json_option  # (this folder: run as a script)

from aisdati.events.behaviour import ashore
from aisdati.events.budget import Thresholds
from aisdati.events.reports import VesselReports
from aisdati.events.stretch import Found, merged
from aisdati.tracks.ashore import AshoreCheck

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
DAYS = {
    "US 2022-01-03 (head)": DATA / "AIS_2022_01_03_head.zip",
    "US coast 2020-06-30": DATA / "US_coastal_2020_06_30_points.csv.gz",
}
LAND_SAMPLES = 20_000
"""Random points per area for the share of land no longer ashore."""


def reports(path: Path) -> pd.DataFrame:
    """mmsi, time, lon, lat of a MarineCadastre CSV (zipped or gzipped), by vessel and time."""
    columns = ["MMSI", "BaseDateTime", "LON", "LAT"]
    if path.suffix == ".zip":
        with zipfile.ZipFile(path) as z:
            frame = pd.read_csv(z.open(z.namelist()[0]), usecols=columns)
    else:
        frame = pd.read_csv(path, usecols=columns)
    frame = frame.rename(columns=dict(zip(columns, ["mmsi", "time", "lon", "lat"], strict=True)))
    frame["time"] = pd.to_datetime(frame["time"], utc=True)
    return frame.sort_values(["mmsi", "time"], kind="stable").reset_index(drop=True)


def vessels(frame: pd.DataFrame) -> list[tuple[int, int]]:
    """(start, end) rows of each vessel in the sorted frame."""
    cut = np.flatnonzero(np.diff(frame["mmsi"].to_numpy())) + 1
    starts = np.concatenate([[0], cut])
    return list(zip(starts, np.concatenate([cut, [len(frame)]]), strict=True))


def events(frame: pd.DataFrame, land: np.ndarray) -> list[tuple[int, Found]]:
    """(first row, event) of every ashore event raised, vessel by vessel (`find_events`'s way:
    the finder, each kind's overlaps merged, the threshold)."""
    limits, out = Thresholds(), []
    t = frame["time"].astype("int64").to_numpy() / 1e9
    lon, lat = frame["lon"].to_numpy(), frame["lat"].to_numpy()
    for a, b in vessels(frame):
        if land[a:b].sum() < 2:
            continue
        nan = np.full(b - a, np.nan)
        v = VesselReports(
            int(frame["mmsi"].iat[a]), t[a:b], lon[a:b], lat[a:b], nan, nan, nan,
            np.full(b - a, -1), np.full(b - a, -1),
        )  # fmt: skip
        kept = [limits.over(e) for e in ashore(v, land[a:b])]
        out += [(a, e) for e in merged([e for e in kept if e is not None])]
    return out


def timed_mask(check: AshoreCheck, points: np.ndarray) -> tuple[np.ndarray, float, float]:
    t0 = time.perf_counter()
    check.reports(points)
    cold = time.perf_counter() - t0
    t0 = time.perf_counter()
    land = check.reports(points)
    return land, cold, time.perf_counter() - t0


def land_no_longer_ashore(points: np.ndarray, seed: int = 0) -> tuple[int, float]:
    """Random points in the 1-degree tiles the reports fall in: how many are ashore on the
    coastline alone, and the share of those that inland water makes no longer ashore."""
    tiles = np.unique(np.floor(points).astype(np.int64), axis=0)
    rng = np.random.default_rng(seed)
    sample = tiles[rng.integers(0, len(tiles), LAND_SAMPLES)] + rng.random((LAND_SAMPLES, 2))
    before = AshoreCheck(inland_water=False).reports(sample)
    after = AshoreCheck().reports(sample)
    return int(before.sum()), float((before & ~after).sum() / max(before.sum(), 1))


def where(frame: pd.DataFrame, found: list[tuple[int, Found]], top: int = 8) -> str:
    """The 1-degree cells (lon, lat of their south-west corner) with the most events."""
    cells = Counter(
        (int(np.floor(frame["lon"].iat[a + e.peak])), int(np.floor(frame["lat"].iat[a + e.peak])))
        for a, e in found
    )
    return ", ".join(f"{x},{y}: {n}" for (x, y), n in cells.most_common(top))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_json_option(ap, "ashore_inland")
    args = ap.parse_args()
    with Report.from_args("ashore_inland", args) as report:
        report.say(f"machine load (1, 5, 15 min): {os.getloadavg()}, {os.cpu_count()} cores")
        columns = ["day", "vessel-days", "vessels with an ashore event: before", "after",
                   "per 1,000 vessel-days: before", "after ", "events: before", "after  ",
                   "reports ashore: before", "after   "]  # fmt: skip
        table = report.table(columns, title="False ashore events, no model")
        speed = report.table(
            ["day", "reports", "1-degree tiles", "coastline alone: cut, again",
             "with inland water: cut, again", "land ashore sampled", "of it no longer ashore"],
            title="Land test: time over every report (tiles cut, then again), land given up",
        )  # fmt: skip
        cells = []
        for day, path in DAYS.items():
            frame = reports(path)
            points = frame[["lon", "lat"]].to_numpy(np.float64)
            days = int(frame.groupby(["mmsi", frame["time"].dt.date]).ngroups)
            plain, p_cold, p_warm = timed_mask(AshoreCheck(inland_water=False), points)
            inland, i_cold, i_warm = timed_mask(AshoreCheck(), points)
            before, after = events(frame, plain), events(frame, inland)
            hit = [len({frame["mmsi"].iat[a] for a, _ in found}) for found in (before, after)]
            table.row(
                [day, f"{days:,}", f"{hit[0]:,}", f"{hit[1]:,}", f"{1000 * hit[0] / days:.0f}",
                 f"{1000 * hit[1] / days:.0f}", f"{len(before):,}", f"{len(after):,}",
                 f"{plain.sum():,}", f"{inland.sum():,}"],
                {"day": day, "vessel_days": days, "vessels_before": hit[0],
                 "vessels_after": hit[1], "events_before": len(before),
                 "events_after": len(after), "reports_before": int(plain.sum()),
                 "reports_after": int(inland.sum())},
            )  # fmt: skip
            sampled, share = land_no_longer_ashore(points)
            tiles = len(np.unique(np.floor(points).astype(np.int64), axis=0))
            speed.row(
                [day, f"{len(points):,}", f"{tiles:,}", f"{p_cold:.1f} s, {p_warm:.1f} s",
                 f"{i_cold:.1f} s, {i_warm:.1f} s", f"{sampled:,}", f"{share:.1%}"],
                {"day": day, "reports": len(points), "tiles": tiles, "plain_cold_s": p_cold,
                 "plain_warm_s": p_warm, "inland_cold_s": i_cold, "inland_warm_s": i_warm,
                 "land_sampled": sampled, "land_given_up": share},
            )  # fmt: skip
            cells.append(f"{day}: before {where(frame, before)}; after {where(frame, after)}")
        report.say("\nWhere the events are (1-degree cells, lon,lat of the south-west corner):")
        for line in cells:
            report.say(f"- {line}")
        report.say(f"machine load after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
