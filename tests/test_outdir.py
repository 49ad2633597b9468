"""The output folders (`aisdati.outdir`), hardened (issue 27; issue 13, items 8 and 15): every
command's outputs land as one set or not at all, one writer per folder, no earlier run's
leftovers, an output folder that is a file (or under one) one line, and one temporary-name scheme
whose leftovers the next run sweeps. Real data (the New York Harbor hour, Kitimat) through the
real command line; signals are real signals sent by the process to itself at a chosen moment.
Numbers in comments are the issue's items."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from aisdati.outdir import hold_lock
from tests.helpers.cli import one_line_error, run
from tests.helpers.ingest import ingest, leftovers
from tests.helpers.models import INGEST, detect_args, detect_dati, evaluate_args, train_ny_nearest
from tests.helpers.processes import aisdati, start_big_ingest, temporaries

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).parent / "data"
NY_HOUR = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"
DETECT_RESULTS = ("scores.parquet", "profiles.parquet", "anomalies.geojson", "report.json")
EVALUATE_RESULTS = ("evaluation.json", "scores.parquet", "roc_pr.png", "examples.png")

HOOK = r"""
import os, signal, sys, time
mode, name, action = sys.argv[1:4]

def act():
    if action == "pause":
        time.sleep(8)
    else:
        os.kill(os.getpid(), getattr(signal, action))
        time.sleep(5)  # the signal lands here (or, where it is held, after the sleep)

if mode in ("replace", "land"):  # just after a file of that name is renamed into place
    real_replace = os.replace  # (land: only into the output folder itself, not a staging one)

    def replace(src, dst, *args, **kwargs):
        real_replace(src, dst, *args, **kwargs)
        if os.path.basename(os.fspath(dst)) == name and (
            mode == "replace" or ".staging-" not in os.fspath(dst)
        ):
            act()

    os.replace = replace
else:  # just after the first figure was saved (sizing it for a tight box raises inside)
    import functools

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    real_png = FigureCanvasAgg.print_png
    calls = []

    @functools.wraps(real_png)
    def print_png(self, *args, **kwargs):
        real_png(self, *args, **kwargs)
        calls.append(1)
        if len(calls) == 1:
            act()

    FigureCanvasAgg.print_png = print_png
sys.argv = ["aisdati", *sys.argv[4:]]
from aisdati.cli import app

app()
"""


def hooked(mode: str, name: str, action: str, *args) -> subprocess.Popen:
    """The real command line in its own process, which does `action` (a signal's name, or
    pause) right after `mode` happens to `name` (see HOOK)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-c", HOOK, mode, name, action, *[str(a) for a in args]],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def finish(proc: subprocess.Popen, rc: int, word: str = "") -> str:
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == rc, err
    assert "Traceback" not in err and word in err
    return err


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` (hidden ones too), by relative path."""
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """The NY hour ingested (tracks of >= 30 reports) and a `nearest` model of its `down`."""
    return train_ny_nearest(tmp_path_factory.mktemp("outputs"))


@pytest.fixture
def earlier(world, tmp_path) -> tuple[Path, dict[str, bytes]]:
    """A folder holding a complete earlier detection (half the tracks flagged), and its files."""
    out = tmp_path / "report"
    r = run(*detect_args(world, out, "--top-percent", 50))
    assert r.exit_code == 0, r.output
    assert (out / "evidence").is_dir() and (out / "map.png").is_file()
    return out, snapshot(out)


# ---------------------------------------------------------------------------------- item 1
@pytest.mark.parametrize("sig, rc", [("SIGTERM", 143), ("SIGINT", 130)])
def test_a_signal_after_scores_land_leaves_the_earlier_detection_whole(world, earlier, sig, rc):
    out, before = earlier
    proc = hooked("replace", "scores.parquet", sig, *detect_args(world, out, "--top-percent", 25))
    finish(proc, rc, "terminated" if sig == "SIGTERM" else "interrupted")
    assert snapshot(out) == before  # not one file of the earlier run changed, nothing added


def test_a_signal_while_the_set_lands_waits_for_the_whole_set(world, earlier):
    out, _ = earlier
    proc = hooked(
        "land", "scores.parquet", "SIGTERM", *detect_args(world, out, "--top-percent", 25)
    )
    finish(proc, 143, "terminated")
    report = json.loads((out / "report.json").read_text())
    scores = pq.read_table(out / "scores.parquet").to_pandas()
    assert report["settings"]["top_percent"] == 25  # the new set, whole
    assert report["flagged"] == int(scores["flagged"].sum())
    evidence = sorted(p.name for p in (out / "evidence").iterdir())
    assert evidence == sorted(f"track-{t}.png" for t in scores.loc[scores["flagged"], "track_id"])
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_a_signal_after_scores_land_in_a_fresh_folder_leaves_no_scores(world, tmp_path):
    out = tmp_path / "fresh"
    proc = hooked("replace", "scores.parquet", "SIGTERM", *detect_args(world, out))
    finish(proc, 143, "terminated")
    assert snapshot(out) == {}


def test_a_failed_figure_write_leaves_the_earlier_detection_whole(world, earlier, monkeypatch):
    from aisdati.detection import maps

    out, before = earlier

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(out / "evidence"))

    monkeypatch.setattr(maps, "plot_track_evidence", full_disk)
    result = run(*detect_args(world, out, "--top-percent", 25))
    assert result.exit_code == 1 and "Traceback" not in result.output, result.output
    errors = [line for line in result.stderr.splitlines() if not line.startswith("warning:")]
    assert len(errors) == 1 and "No space left on device" in errors[0], result.stderr
    assert snapshot(out) == before


def test_sigterm_during_evaluate_leaves_no_results_without_figures(kitimat, tmp_path):
    out = tmp_path / "evaluation"
    proc = hooked("replace", "scores.parquet", "SIGTERM", *evaluate_args(kitimat, out))
    finish(proc, 143, "terminated")
    assert not [name for name in EVALUATE_RESULTS if (out / name).exists()]
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]


def test_sigterm_during_ingest_commit_keeps_one_runs_set(tmp_path):
    out = tmp_path / "processed"
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 20, "--out", out)
    assert r.exit_code == 0, r.output
    before = snapshot(out)
    args = ["ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 40, "--out", out]
    finish(hooked("replace", "points.parquet", "SIGTERM", *args), 143, "terminated")
    report = json.loads((out / "ingest_report.json").read_text())
    assert pq.read_table(out / "points.parquet").num_rows == report["kept_points"]
    assert pq.read_metadata(out / "tracks.parquet").num_rows == report["tracks"]["total"]
    assert snapshot(out) == before


def test_a_killed_runs_staging_folder_is_swept(world, tmp_path):
    out = tmp_path / "report"
    dead = out / f".staging-{dead_pid()}-abc123"
    (dead / "evidence").mkdir(parents=True)
    (dead / "scores.parquet").write_bytes(b"half")
    (dead / "evidence" / "track-1.png").write_bytes(b"half")
    live = out / f".staging-{os.getpid()}-live01"  # a run in progress (this process)
    live.mkdir()
    result = run(*detect_args(world, out))
    assert result.exit_code == 0, result.output
    assert not dead.exists() and live.is_dir()
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [live.name]


# ---------------------------------------------------------------------------------- item 2
def test_a_second_detect_into_a_folder_in_use_is_refused(world, tmp_path):
    out = tmp_path / "report"
    first = hooked(
        "replace", "scores.parquet", "pause", *detect_args(world, out, "--top-percent", 25)
    )
    deadline = time.monotonic() + 120
    while not list(out.rglob("scores.parquet")):  # the first run is writing its outputs
        assert first.poll() is None and time.monotonic() < deadline, first.stderr.read()
        time.sleep(0.05)
    second = run(*detect_args(world, out, "--top-percent", 50))
    one_line_error(second, "another aisdati run is writing to it")
    finish(first, 0)
    report = json.loads((out / "report.json").read_text())
    scores = pq.read_table(out / "scores.parquet").to_pandas()
    assert report["settings"]["top_percent"] == 25
    assert report["flagged"] == int(scores["flagged"].sum())


def test_detect_and_evaluate_refuse_a_folder_another_run_holds(world, kitimat, tmp_path):
    out = tmp_path / "busy"
    out.mkdir()
    with hold_lock(out):
        one_line_error(run(*detect_args(world, out)), "another aisdati run is writing to it")
        one_line_error(run(*evaluate_args(kitimat, out)), "another aisdati run is writing to it")
    assert list(out.iterdir()) == []


# ---------------------------------------------------------------------------------- item 3
def test_a_rerun_removes_what_the_earlier_run_wrote_and_this_one_does_not(world, tmp_path):
    out = tmp_path / "report"
    r = run(*detect_args(world, out, "--top-percent", 50))
    assert r.exit_code == 0, r.output
    ids = pq.read_table(out / "scores.parquet").column("track_id").to_pylist()
    labels = tmp_path / "labels.csv"
    labels.write_text("track_id,label\n" + "".join(f"{t},{i % 2}\n" for i, t in enumerate(ids)))
    r = run(*detect_args(world, out, "--top-percent", 50, "--labels", labels))
    assert r.exit_code == 0, r.output
    assert (out / "metrics.json").is_file() and list((out / "evidence").glob("track-*.png"))
    (out / "notes.txt").write_text("mine")
    (out / "evidence" / "mine.txt").write_text("mine too")
    r = run(*detect_args(world, out, "--threshold", 1, "--json"))  # flags fewer, no labels
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["flagged"] < len(ids) // 2 and doc["metrics"] is None
    assert not (out / "metrics.json").exists()
    flagged = pq.read_table(out / "scores.parquet").to_pandas().query("flagged")["track_id"]
    figures = sorted(f"track-{t}.png" for t in flagged)  # the flagged tracks' evidence only
    assert sorted(p.name for p in (out / "evidence").iterdir()) == ["mine.txt", *figures]
    assert (out / "notes.txt").read_text() == "mine"
    written = sorted(str(Path(f).relative_to(out)) for f in doc["files"])
    assert sorted(set(snapshot(out)) - {"notes.txt", "evidence/mine.txt"}) == written


# --------------------------------------------------------------------------------- item 17
def test_ctrl_c_while_routes_png_is_saved_leaves_nothing(tmp_path):
    out = tmp_path / "processed"
    args = ["ingest", "--input", NY_HOUR, *INGEST, "--out", out]
    finish(hooked("png", "", "SIGINT", *args), 130, "interrupted")
    assert not out.exists()  # the folder the run made is removed again, empty


def test_every_temporary_name_carries_the_pid_and_is_swept(tmp_path):
    from aisdati.outdir import STARTED, sweep_stale_temporaries, temporary_path

    out = tmp_path / "out"
    (out / "evidence").mkdir(parents=True)
    ours = temporary_path(out / "evidence" / "track-3.png")
    assert ours.parent == out / "evidence" and f".{os.getpid()}-" in ours.name
    assert temporary_path(out / "map.png").name.startswith(f".map.png.{os.getpid()}-")
    ours.write_bytes(b"x")
    dead = dead_pid()
    theirs = out / ours.name.replace(str(os.getpid()), str(dead))
    theirs.write_bytes(b"x")
    legacy = [out / ".map.tmp.png", out / "..routes.png.1.tmp.tmp.png", out / ".map.tmp.html"]
    for path in legacy:
        path.write_bytes(b"x")
        os.utime(path, (STARTED - 60, STARTED - 60))
    mine = out / "notes.tmp.png"
    mine.write_bytes(b"x")
    removed = sweep_stale_temporaries(out) + sweep_stale_temporaries(out / "evidence")
    assert sorted(removed) == sorted([theirs, *legacy])
    assert ours.is_file() and mine.is_file()


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


# ------------------------------------------------------------------------ 8: output folder
def test_out_is_a_file_or_under_a_file(cli, data, tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("not a folder")
    result, _ = ingest(cli, a_file, data / NY_HOUR)
    one_line_error(
        result, "cannot write to output folder .*file.txt \\(--out\\): it is a file, not a folder"
    )
    # Under a regular file: what a folder without write permission gives a non-root user (the
    # tests run as root, whom permissions do not stop), through the same check.
    result, _ = ingest(cli, a_file / "sub", data / NY_HOUR)
    one_line_error(
        result,
        r"cannot write to output folder .* \(--out\): cannot create it, a part of the path is a "
        "file",
    )
    assert a_file.read_text() == "not a folder"


def test_an_output_name_taken_by_a_folder_leaves_nothing_behind(cli, data, tmp_path):
    out = tmp_path / "out"
    (out / "tracks.parquet").mkdir(parents=True)  # points.parquet is a folder (of parts) itself
    result, _ = ingest(cli, out, data / NY_HOUR)
    one_line_error(result, "tracks.parquet there is a folder")
    assert leftovers(out) == [] and sorted(p.name for p in out.iterdir()) == ["tracks.parquet"]


# ---------------------------------------------------------------------------------- item 8
def test_train_and_detect_outputs_under_a_file_or_on_a_folder(ny_dati, tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    result = run("train", "--cluster", "down", "--data", ny_dati["proc"], "--out", a_file / "m")
    one_line_error(
        result,
        r"cannot write to output folder .* \(--out\): cannot create it, a part of the path is a "
        "file",
    )
    result = detect_dati(ny_dati, ny_dati["models"], a_file)
    one_line_error(
        result, "cannot write to output folder .*file.txt \\(--out\\): it is a file, not a folder"
    )
    report = tmp_path / "report"
    (report / "scores.parquet").mkdir(parents=True)
    result = detect_dati(ny_dati, ny_dati["models"], report)
    one_line_error(result, "scores.parquet there is a folder")
    models = tmp_path / "models"
    (models / "down.json").mkdir(parents=True)
    result = run("train", "--cluster", "down", "--data", ny_dati["proc"], "--out", models)
    one_line_error(result, "down.json there is a folder")
