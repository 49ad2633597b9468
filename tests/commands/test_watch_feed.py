"""`aisdati watch` on recordings a user has: one report dated 2099 neither moves the feed's clock
(FRIO's drift stays the batch's, no vessel is forgotten) nor puts a paced replay to sleep, and a
recording compressed as ingest reads it (gz, zst, zip) gives the events of the plain file."""

from __future__ import annotations

import gzip
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import zstandard
from pyais.encode import encode_dict

from tests.helpers.cli import run
from tests.helpers.live import FRIO, ROOT, events

KEPT = ["kind", "state", "start_time", "end_time", "n_reports", "strength", "evidence"]
"""An event's columns that must match (not its id, nor when its row was written)."""
YEAR_2099 = 4070908800
"""2099-01-01 00:00:00 UTC in seconds."""


def with_a_report_from_2099(folder: Path) -> Path:
    """FRIO's recording with one of its reports dated 2099 (a tag block's bad time), put in
    the middle of its drift (16:37:54-16:57:24)."""
    lines = FRIO.read_bytes().splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith(b"$PGHP,1,2014,9,28,16,52"))
    report = {"type": 1, "mmsi": 538004030, "lon": 10.61, "lat": 57.63, "speed": 2.0,
              "course": 90.0, "heading": 36, "status": 0}  # fmt: skip
    future = f"\\c:{YEAR_2099}*00\\{encode_dict(report, talker_id='AI')[0]}".encode()
    path = folder / "frio_2099.ais"
    path.write_bytes(b"\n".join([*lines[:at], future, *lines[at:]]) + b"\n")
    return path


def rejected(stderr: str) -> int:
    ended = re.search(r"feed ended: .* ([\d,]+) rejected", " ".join(stderr.split()))
    assert ended, stderr
    return int(ended[1].replace(",", ""))


def test_a_report_from_2099_is_set_aside_not_the_clock(tmp_path):
    clean = run("watch", "--input", FRIO, "--db", tmp_path / "clean.sqlite")
    bad = run("watch", "--input", with_a_report_from_2099(tmp_path), "--db", tmp_path / "b.sqlite")
    assert clean.exit_code == bad.exit_code == 0, bad.output
    drift = events(tmp_path / "b.sqlite")[KEPT]
    assert list(drift["n_reports"]) == [119]  # the batch's drift, not cut short at 115
    assert drift.equals(events(tmp_path / "clean.sqlite")[KEPT])
    assert "(0 forgotten)" in bad.stderr  # the clock did not jump: FRIO is not forgotten
    assert rejected(bad.stderr) == rejected(clean.stderr) + 1  # counted as `future`


def test_a_paced_replay_does_not_sleep_until_2099(tmp_path):
    """At --speed 2000 FRIO's 2.5 hours take 4.5 s; a report from 2099 slept the replay for
    the 85 years between."""
    code = "from aisdati.cli import app; app()"
    got = subprocess.run(
        [sys.executable, "-c", code, "watch", "--input", with_a_report_from_2099(tmp_path),
         "--speed", "2000", "--db", tmp_path / "w.sqlite"],
        capture_output=True, text=True, timeout=120, cwd=ROOT,
    )  # fmt: skip
    assert got.returncode == 0, got.stderr
    assert events(tmp_path / "w.sqlite")[["kind", "state", "n_reports"]].values.tolist() == [
        ["drift", "closed", 119]
    ]


def compressed(path: Path, kind: str) -> Path:
    """FRIO's recording as a user may have it: gzip, zstd, or a member of a zip archive."""
    data = FRIO.read_bytes()
    if kind == "zip":
        with zipfile.ZipFile(path / "frio.zip", "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("README.md", "not a recording")  # not replayed: not an NMEA name
            z.writestr("frio/538004030.ais", data)
        return path / "frio.zip"
    out = path / f"frio.ais.{kind}"
    out.write_bytes(gzip.compress(data) if kind == "gz" else zstandard.compress(data))
    return out


@pytest.mark.parametrize("kind", ["gz", "zst", "zip"])
def test_a_compressed_recording_is_read_as_ingest_reads_it(tmp_path, kind):
    plain = run("watch", "--input", FRIO, "--db", tmp_path / "plain.sqlite")
    got = run("watch", "--input", compressed(tmp_path, kind), "--db", tmp_path / "c.sqlite")
    assert plain.exit_code == got.exit_code == 0, got.output
    assert rejected(got.stderr) == rejected(plain.stderr)
    drift = events(tmp_path / "c.sqlite")[KEPT]
    assert len(drift) == 1 and drift.equals(events(tmp_path / "plain.sqlite")[KEPT])


def test_a_truncated_recording_is_one_line(tmp_path):
    cut = tmp_path / "frio.ais.gz"
    cut.write_bytes(gzip.compress(FRIO.read_bytes())[:5000])
    got = run("watch", "--input", cut, "--db", tmp_path / "w.sqlite")
    assert got.exit_code == 2 and "Traceback" not in got.output
    (line,) = [x for x in got.stderr.splitlines() if x.startswith("error:")]
    assert "frio.ais.gz: corrupt or truncated input" in line
