"""Reports as a receiver logs them, for `aisdati watch` (and ingest) to read: a type 1 position
report per row and type 5 static messages, each line stamped by an NMEA 4.0 tag block; and the
one run the watch's tests compare: a feed through ingest + `detect --models none` and through
`watch`, the events each ends with."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from pyais.encode import encode_dict

from tests.helpers.cli import run
from tests.helpers.live import events


def stamped(seconds: float, sentence: str) -> str:
    """`sentence` with the tag block that dates it (whole seconds, as receivers stamp)."""
    return f"\\c:{int(seconds)}*00\\{sentence}"


def position(mmsi: int, seconds: float, lon: float, lat: float, sog: float, cog: float,
             heading: float = np.nan, status: float = np.nan) -> str:  # fmt: skip
    """A type 1 report (heading 511 and status 15: not given)."""
    report = {
        "type": 1, "mmsi": int(mmsi), "lon": float(lon), "lat": float(lat), "speed": float(sog),
        "course": float(cog) % 360, "heading": 511 if np.isnan(heading) else int(heading) % 360,
        "status": 15 if np.isnan(status) else int(status),
    }  # fmt: skip
    return stamped(seconds, encode_dict(report, talker_id="AI")[0])


def static(
    mmsi: int, seconds: float, name: str, ship_type: int = 0, length_m: int = 0
) -> list[str]:
    """A type 5 message (two sentences): the vessel's name, type code and length."""
    message = {"type": 5, "mmsi": int(mmsi), "shipname": name, "ship_type": ship_type,
               "to_bow": int(length_m), "to_stern": 0}  # fmt: skip
    return [stamped(seconds, s) for s in encode_dict(message, talker_id="AI")]


def as_nmea(reports: pd.DataFrame, identity: pd.DataFrame, path: Path) -> Path:
    """`reports` (reports.parquet's rows) in time order as NMEA, each vessel's name and length
    (`identity`: vessels.parquet's rows by MMSI) said before its first report."""
    lines, said = [], set()
    r = reports.sort_values("time", kind="stable")
    seconds = (r["time"] - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy()
    columns = ("mmsi", "lon", "lat", "sog", "cog", "heading", "status")
    cols = [r[c].to_numpy(np.float64).tolist() for c in columns]
    rows = zip(seconds.tolist(), *cols, strict=True)
    for t, mmsi, lon, lat, sog, cog, heading, status in rows:
        mmsi = int(mmsi)
        if mmsi not in said and mmsi in identity.index:
            said.add(mmsi)
            who = identity.loc[mmsi]
            length = 0 if pd.isna(who["length_m"]) else round(who["length_m"])
            lines += static(mmsi, t, "" if pd.isna(who["name"]) else who["name"], length_m=length)
        lines.append(position(mmsi, t, lon, lat, sog, cog, heading, status))
    path.write_text("\n".join(lines) + "\n")
    return path


def detected_and_watched(
    nmea: Path, folder: Path, *paced: str, ports: Path | None = None
) -> tuple[pd.DataFrame, pd.DataFrame, list[dict]]:
    """The events of `nmea` by ingest + `detect --models none`; those `watch` ends with (its
    database's events table, `start_time`/`end_time` as `start`/`end`); and the changes the
    watch printed (`--json`), in order. Times as UTC timestamps. `paced`: `--speed X` (its
    chunks of a few lines), else the file is read as fast as it goes (its chunks of 2,000), and
    any other option of the watch's; `ports`: `--ports` to both."""
    data, out, db = folder / "data", folder / "detect", folder / "watch.sqlite"
    got = run("ingest", "--input", nmea, "--roi", "none", "--min-points", "5", "--out", data)
    assert got.exit_code == 0, got.output
    given = ["--ports", ports] if ports is not None else []
    got = run("detect", "--data", data, "--models", "none", *given, "--out", out)
    assert got.exit_code == 0, got.output
    batch = pd.read_parquet(out / "events.parquet")
    got = run("watch", "--input", nmea, *paced, *given, "--db", db, "--json")
    assert got.exit_code == 0, got.output
    live = events(db).rename(columns={"start_time": "start", "end_time": "end"})
    for frame in (batch, live):
        for column in ("start", "end"):
            frame[column] = pd.to_datetime(frame[column], utc=True)
    return batch, live, [json.loads(line) for line in got.stdout.splitlines()]
