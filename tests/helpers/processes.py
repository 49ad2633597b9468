"""The real command line in a process of its own, for the tests that send it real signals or
kill it: starting it, waiting for a moment inside its run, and what a run leaves behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parents[1] / "data"
BIG_INPUTS = (
    "AIS_2018_07-08_Kitimat.csv.gz",
    "NYHarbor_2020_12_first_week_points.csv.gz",
    "AIS_2022_01_03_head.zip",
)


def aisdati(*args) -> subprocess.Popen:
    """The real command line in its own process (stdout/stderr captured)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "from aisdati.cli import app; app()"
    return subprocess.Popen(
        [sys.executable, "-c", code, *[str(a) for a in args]],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        # a test run started in the background inherits an ignored SIGINT (as nohup does);
        # give the command the default disposition an analyst's terminal gives it
        preexec_fn=_default_sigint,
    )


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wait_for(condition, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            pytest.fail(f"the process ended first (rc {proc.returncode}): {proc.stderr.read()}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail("timed out waiting for the process")
        time.sleep(0.005)


def temporaries(folder: Path) -> list[str]:
    names = [p.name for p in folder.iterdir()] if folder.is_dir() else []
    return sorted(n for n in names if ".tmp" in n or n.startswith(".ingest-"))


def start_big_ingest(out: Path) -> subprocess.Popen:
    inputs = [a for name in BIG_INPUTS for a in ("--input", DATA / name)]
    proc = aisdati("ingest", *inputs, "--roi", "none", "--min-points", "20", "--out", out)
    wait_for(lambda: any(n.startswith(".ingest-") for n in temporaries(out)), proc)
    time.sleep(0.3)  # well inside the run (it takes seconds)
    return proc
