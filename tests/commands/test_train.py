"""Hardening (issue 13): real signals sent to real `aisdati` processes, the sweep of what killed
runs leave behind (item 15), and Ctrl-C in the first training episode (item 17)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aisdati.outdir import hold_lock

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).parent / "data"
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


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


# --------------------------------------------------------------------------------- item 15
@pytest.mark.parametrize(
    "sig, rc, word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")]
)
def test_sigterm_and_sigint_during_ingest_leave_nothing(tmp_path, sig, rc, word):
    out = tmp_path / "out"
    proc = start_big_ingest(out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == rc, err
    assert word in err and "Traceback" not in err
    assert temporaries(out) == []
    assert not (out / "points.parquet").exists()


def test_the_next_run_sweeps_what_sigkill_left(cli, tmp_path):
    out = tmp_path / "out"
    proc = start_big_ingest(out)
    proc.kill()
    proc.wait(timeout=60)
    left = temporaries(out)
    assert any(n.startswith(f".ingest-{proc.pid}-") for n in left), left  # what the kill left
    result = cli(
        "ingest", "--input", DATA / "NYHarbor_2020_06_30_first_hour.csv",
        "--roi", "none", "--min-points", "20", "--out", out,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert temporaries(out) == []
    assert (out / "points.parquet").is_dir()  # a Parquet dataset


def test_the_sweep_removes_only_stale_temporaries_of_ours(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    dead = dead_pid()
    stale = [f".ingest-{dead}-abc123", ".ingest-x1y2z3", f".points.parquet.{dead}.tmp"]
    stale.append(".down.json.ab12cd34.tmp")  # an atomic write's, from before this run
    for name in stale[:2]:
        (out / name).mkdir()
        (out / name / "part-0000.arrow").write_bytes(b"x")
    (out / stale[0] / ".lock").write_bytes(b"")  # its lock: free, its owner is gone
    for name in stale[2:]:
        (out / name).write_bytes(b"x")
    live = [f".ingest-{dead}-live01", f".points.parquet.{os.getpid()}.tmp", "notes.tmp", ".hidden"]
    (out / live[0]).mkdir()
    for name in live[1:]:
        (out / name).write_bytes(b"keep")
    past = time.time() - 3600
    for name in stale + live:
        if name != live[1]:  # a live writer's file is younger than the writer
            os.utime(out / name, (past, past))
    with hold_lock(out / live[0]):  # a run in progress (in this process) holds its folder
        proc = aisdati(
            "ingest", "--input", DATA / "NYHarbor_2020_06_30_first_hour.csv",
            "--roi", "none", "--min-points", "20", "--out", out,
        )  # fmt: skip
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    names = {p.name for p in out.iterdir()}
    assert not names & set(stale), names & set(stale)
    assert set(live) <= names
    assert {"points.parquet", "tracks.parquet", "ingest_report.json"} <= names


# --------------------------------------------------------------------------------- item 17
@pytest.fixture(scope="module")
def long_track(tmp_path_factory):
    """One real Kitimat track of 493 reports: a first training episode takes many seconds."""
    from typer.testing import CliRunner

    from aisdati.cli import app

    out = tmp_path_factory.mktemp("kitimat")
    args = ["ingest", "--input", str(DATA / "AIS_2018_07-08_Kitimat.csv.gz"), "--roi", "none"]
    args += ["--dwell-time", "0"]  # keep the 493 reports in one
    result = CliRunner().invoke(app, [*args, "--min-points", "300", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize(
    "sig, rc, word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]
)
def test_stopping_the_first_training_episode_says_no_model_was_saved(
    long_track, tmp_path, sig, rc, word
):
    models = tmp_path / "models"
    proc = aisdati(
        "train", "--cluster", "other", "--data", long_track, "--out", models,
        "--episodes", "1", "--max-tracks", "1",
    )  # fmt: skip
    wait_for(models.is_dir, proc)  # the output folder is prepared just before training
    time.sleep(1.0)
    assert not (models / "other.pt").exists()  # still in the first episode
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == rc, err
    message = " ".join(err.split())
    assert f"{word}: stopped during the first episode, before any model was saved" in message
    assert "best episode so far" not in message and "Traceback" not in err
    assert sorted(p.name for p in models.iterdir()) == []


def _interrupt_inside_a_c_callback() -> None:
    """Ctrl-C arriving while C code calls back into Python (as numba's JIT does): the
    KeyboardInterrupt is raised in the callback, printed as "Exception ignored" and lost."""
    import ctypes

    libc = ctypes.CDLL(None)
    compare = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)

    def cmp(a, b):
        os.kill(os.getpid(), signal.SIGINT)
        return 0

    values = (ctypes.c_int * 2)(2, 1)
    libc.qsort(values, 2, ctypes.sizeof(ctypes.c_int), compare(cmp))


def test_a_ctrl_c_swallowed_by_a_c_callback_still_stops_the_outputs(tmp_path, capfd):
    from aisdati.interrupts import handle_termination, raise_if_interrupted
    from aisdati.outdir import atomic_write_bytes

    # a test run started in the background may inherit an ignored SIGINT: give it the default
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with handle_termination():
            _interrupt_inside_a_c_callback()  # returns: the exception did not propagate
            with pytest.raises(KeyboardInterrupt):
                atomic_write_bytes(tmp_path / "model.json", b"{}")
            with pytest.raises(KeyboardInterrupt):
                raise_if_interrupted()
        assert list(tmp_path.iterdir()) == []  # nothing committed, no temporary left
        assert "Traceback" not in capfd.readouterr().err  # not printed: it was remembered
        raise_if_interrupted()  # outside the block the memory is cleared
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, inherited)
