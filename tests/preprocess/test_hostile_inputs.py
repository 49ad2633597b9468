"""Hostile inputs to `aisdati ingest` (issue 61): a flood of one vessel at one time stays
bounded in memory and is counted (item 17); tracks across the antimeridian are refused in one
line, tracks beside it still ingest (item 8)."""

from __future__ import annotations

import gzip
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from aisdati.errors import UserError
from aisdati.preprocess import pipeline
from aisdati.preprocess.settings import IngestSettings

KITIMAT = "AIS_2018_07-08_Kitimat.csv.gz"
FLOOD = 2_000_000
"""Copies of one report: unbounded, one piece of them all peaked at 652 MiB (347 MiB bounded)."""
BUCKET = 40_000
"""rows_per_bucket in the measured runs: pieces of 10,000 rows, so a small flood shows."""

LAUNCHER = """
import resource, subprocess, sys
proc = subprocess.run(sys.argv[1:], capture_output=True, text=True)
sys.stderr.write(proc.stderr)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, proc.returncode)
"""
"""Runs one command as its only child, so the children's peak RSS is that command's alone."""

AISDATI = f"""
import sys
import aisdati.preprocess.settings as settings
init = settings.IngestSettings.__init__
def smaller_buckets(self, *args, **kwargs):
    kwargs.setdefault("rows_per_bucket", {BUCKET})
    init(self, *args, **kwargs)
settings.IngestSettings.__init__ = smaller_buckets
sys.argv[0] = "aisdati"
from aisdati.cli import app
app()
"""
"""The `aisdati` console script, with buckets small enough that a flood of 2 M rows is large."""


def _ingest_peak_mib(source: Path, out: Path) -> float:
    """Peak RSS (MiB) of `aisdati ingest` of `source` in a fresh subprocess."""
    cmd = [sys.executable, "-c", AISDATI, "ingest", "--input", str(source), "--out", str(out)]
    cmd += ["--roi", "none", "--min-points", "100"]
    proc = subprocess.run(
        [sys.executable, "-c", LAUNCHER, *cmd], capture_output=True, text=True, check=True
    )
    rss_kib, code = proc.stdout.split()
    assert int(code) == 0, proc.stderr
    return int(rss_kib) / 1024


def _zip(path: Path, text: str) -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        zf.writestr(path.stem + ".csv", text)
    return path


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss in KiB on Linux")
def test_a_flood_of_one_vessel_at_one_time_stays_bounded_and_is_counted(data, tmp_path):
    """Kitimat with its first report repeated 2 M times (one MMSI, one time, in a zip of half
    a MB): the peak memory stays within 150 MiB of Kitimat's own (the unbounded piece took
    over 300 MiB more), the same points are kept, and the copies beyond a piece's worth are
    counted as `same_time_flood`."""
    with gzip.open(data / KITIMAT, "rt") as f:
        text = f.read()
    _header, first = text.split("\n", 2)[:2]
    plain = _zip(tmp_path / "plain.zip", text)
    flood = _zip(tmp_path / "flood.zip", text + (first + "\n") * FLOOD)
    base = _ingest_peak_mib(plain, tmp_path / "plain")
    peak = _ingest_peak_mib(flood, tmp_path / "flood")
    report = json.loads((tmp_path / "flood" / "ingest_report.json").read_text())
    plain_report = json.loads((tmp_path / "plain" / "ingest_report.json").read_text())
    assert peak - base < 150, (base, peak)
    assert report["kept_points"] == plain_report["kept_points"]
    piece_rows = BUCKET // 4
    assert report["rejected"]["same_time_flood"] == FLOOD + 1 - piece_rows
    extra = report["rejected"]["duplicate"] - plain_report["rejected"]["duplicate"]
    assert extra == piece_rows - 1  # the cleaner keeps one of those left
    assert report["rows_read"] == report["rejected_total"] + report["kept_points"]


def _shifted_kitimat(data: Path, tmp_path: Path, shift: float) -> Path:
    """Kitimat's reports with `shift` degrees added to their longitudes, wrapped into
    [-180, 180)."""
    frame = pd.read_csv(data / KITIMAT)
    frame["LON"] = np.round((frame["LON"] + shift + 180.0) % 360.0 - 180.0, 5)
    path = tmp_path / "shifted.csv"
    frame.to_csv(path, index=False)
    return path


def test_tracks_across_the_antimeridian_are_refused_in_one_line(data, tmp_path):
    """Kitimat shifted to straddle 180 degrees: one line naming a vessel and what to do, and
    nothing written."""
    source = _shifted_kitimat(data, tmp_path, 180.0 + 128.9)
    out = tmp_path / "out"
    settings = IngestSettings(min_points=100)
    with pytest.raises(UserError) as raised:
        pipeline.ingest([source], out, settings, None, "none")
    message = str(raised.value)
    assert "\n" not in message
    assert "antimeridian" in message and "vessel " in message
    assert "shift the longitudes" in message and "split the data at 180" in message
    assert not out.exists() or not any(
        p.name.endswith((".parquet", ".json")) for p in out.iterdir()
    )


def test_tracks_beside_the_antimeridian_still_ingest(data, tmp_path):
    """Kitimat shifted to lie just west of 180 degrees (177.9 .. 179.4): ingested as usual."""
    source = _shifted_kitimat(data, tmp_path, 180.0 + 127.9)
    result = pipeline.ingest(
        [source], tmp_path / "out", IngestSettings(min_points=100), None, "none"
    )
    assert result.counts.kept_points > 0
    assert (tmp_path / "out" / "points.parquet").exists()


def test_a_flood_at_one_time_is_kept_as_rejects_by_its_reason(data, tmp_path):
    """With --keep-rejects, the copies beyond a piece's worth are in rejects.parquet under
    `same_time_flood`, the rest of the copies under `duplicate` as before."""
    with gzip.open(data / KITIMAT, "rt") as f:
        text = f.read()
    first = text.split("\n", 2)[1]
    source = _zip(tmp_path / "flood.zip", text + (first + "\n") * 30_000)
    settings = IngestSettings(min_points=100, rows_per_bucket=BUCKET, keep_rejects=True)
    result = pipeline.ingest([source], tmp_path / "out", settings, None, "none")
    reasons = pq.read_table(tmp_path / "out" / "rejects.parquet").column("reason").to_pylist()
    flood = result.counts.rejected_by_reason()["same_time_flood"]
    assert flood == 30_001 - BUCKET // 4 == reasons.count("same_time_flood")
    assert reasons.count("duplicate") == result.counts.rejected_by_reason()["duplicate"]
