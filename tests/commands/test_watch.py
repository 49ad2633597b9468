"""`aisdati watch` end to end: a recording replayed gives the batch's events (ingest + detect
--models none), a window shorter than an event is where live must differ, a watch killed and
restarted on a real TCP feed neither loses nor doubles its open drift, bad input is counted
and never fatal, and option mistakes are one line."""

from __future__ import annotations

import json
import re
import signal
import sqlite3
import subprocess
import sys

import pandas as pd

from aisdati.commands import watch as watch_command
from aisdati.detection.events import event_rules
from aisdati.detectors import load_detectors
from aisdati.events.budget import Thresholds
from aisdati.live.decode import Decoder
from aisdati.live.loop import Watch
from tests.helpers.cli import one_line_error, run
from tests.helpers.live import EVENTS, FRIO, ROOT, Feed, events, poll, stopped, watch
from tests.helpers.models import train_ny_nearest

FIELDS = ["kind", "start", "end", "n_reports", "strength", "evidence"]


def replayed(tmp_path, *args) -> pd.DataFrame:
    tmp_path.mkdir(exist_ok=True)
    got = run("watch", "--input", *args, "--db", tmp_path / "w.sqlite", "--json")
    assert got.exit_code == 0, got.output
    records = [json.loads(line) for line in got.stdout.splitlines()]
    last = {r["event_id"]: r for r in records}  # each event's latest change
    frame = pd.DataFrame(list(last.values()), columns=["state", *FIELDS])
    for key in ("start", "end"):
        frame[key] = pd.to_datetime(frame[key], utc=True)
    return frame


def test_a_replay_gives_the_batch_events(tmp_path):
    data, out = tmp_path / "data", tmp_path / "batch"
    assert run("ingest", "--input", FRIO, "--roi", "none", "--min-points", "5", "--out",
               data).exit_code == 0  # fmt: skip
    assert run("detect", "--data", data, "--models", "none", "--out", out).exit_code == 0
    batch = pd.read_parquet(out / "events.parquet")[FIELDS]
    live = replayed(tmp_path, FRIO)
    assert list(live["kind"]) == ["drift"] and list(live["state"]) == ["closed"]
    pd.testing.assert_frame_equal(live[FIELDS], batch, check_dtype=False)


def test_a_loitering_longer_than_the_window_is_not_seen_live(tmp_path):
    """STOC MARCIA loiters 12.5 h; `detect` finds it over the whole recording (start
    2014-10-02 16:56:45.783, end 2014-10-03 05:26:46.878). A 3-hour window never holds the
    vessel under way on both sides of it, so live cannot; a day's window finds the batch's."""
    stoc = EVENTS / "212123000_drift_1.ais"
    assert "loitering" not in set(replayed(tmp_path / "3h", stoc)["kind"])
    day = replayed(tmp_path / "1d", stoc, "--window", "1d")
    (loiter,) = day[day["kind"] == "loitering"].itertuples()
    assert loiter.start == pd.Timestamp("2014-10-02 16:56:45.783", tz="UTC")
    assert loiter.end == pd.Timestamp("2014-10-03 05:26:46.878", tz="UTC")


def mid_drift(lines: list[bytes]) -> int:
    """The first line stamped 16:52 (FRIO drifts 16:37:54-16:57:24): open by then. A feed
    does not resend what a killed watch had received but not read, so the test stops the
    watch once it has read all that was sent."""
    return next(k for k, line in enumerate(lines) if line.startswith(b"$PGHP,1,2014,9,28,16,52"))


def last_report(lines: list[bytes]) -> str:
    """The time of the last report of these lines, as the vessels table holds it."""
    times = Decoder().reports(lines).column("time").to_pandas()
    return times.max().isoformat()


def heard(db) -> str | None:
    """The last report time of the vessel in a watch's database (what it has read)."""
    with sqlite3.connect(db) as conn:
        try:
            return conn.execute("SELECT max(time) FROM vessels").fetchone()[0]
        except sqlite3.OperationalError:
            return None


def test_a_killed_and_restarted_watch_keeps_its_open_drift(tmp_path):
    lines = FRIO.read_bytes().splitlines()
    feed, db = Feed(lines, until=mid_drift(lines)), tmp_path / "w.sqlite"
    try:
        proc = watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", db, "--json",
                     out=tmp_path / "first")  # fmt: skip
        poll(lambda: "open" in set(events(db)["state"]), 60, "the drift to open")
        poll(lambda: heard(db) == last_report(lines[: feed.until]), 30, "all lines sent read")
        assert stopped(proc) == 143
        (row,) = events(db).itertuples()
        assert row.state == "open" and row.stopped_at  # left open, marked as stopped
        proc = watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", db, "--json",
                     out=tmp_path / "second")  # fmt: skip
        feed.until = len(lines)
        poll(lambda: "closed" in set(events(db)["state"]), 60, "the drift to close")
        assert stopped(proc, signal.SIGINT) == 130
    finally:
        feed.stop()
    assert "resumed 1 open event" in (tmp_path / "second" / "stderr").read_text()
    (row,) = events(db).itertuples()  # one drift: not doubled by the restart
    assert (row.kind, row.state, row.stopped_at) == ("drift", "closed", None)
    assert (row.start_time, row.end_time, row.n_reports) == (
        "2014-09-28T16:37:54.051000+00:00",
        "2014-09-28T16:57:24.744000+00:00",
        119,
    )  # the batch's (test_a_replay_gives_the_batch_events): no report lost


def test_bad_input_is_counted_never_fatal(tmp_path):
    good = (EVENTS / "219165000_ssc_1.ais").read_bytes()
    bad = b"garbage\n!AIVDM,1,1,,A,13aEOK?P00PD2wVMdMeGUnwP00H0,0*00\n!AIVDM,2,1,7,A,55\n\xff\xfe\n"
    code = "from aisdati.cli import app; app()"
    got = subprocess.run(
        [sys.executable, "-c", code, "watch", "--input", "-", "--db", tmp_path / "w.sqlite",
         "--json"], input=bad + good + bad, capture_output=True, timeout=120, cwd=ROOT,
    )  # fmt: skip
    assert got.returncode == 0, got.stderr
    records = [json.loads(line) for line in got.stdout.splitlines()]
    assert [r["kind"] for r in records] == ["sudden-speed-change"]  # LOTUS's, as AisAbnormal's
    ended = re.search(rb"feed ended: .* ([\d,]+) rejected", got.stderr)
    assert ended and int(ended[1].replace(b",", b"")) >= 8


def test_option_mistakes_are_one_line(tmp_path):
    db = tmp_path / "w.sqlite"
    one_line_error(run("watch", "--input", FRIO, "--speed", "0", "--db", db), "--speed")
    one_line_error(run("watch", "--input", "tcp://x:1", "--speed", "2", "--db", db), "replays")
    one_line_error(run("watch", "--input", "tcp://127.0.0.1", "--db", db), "port")
    one_line_error(run("watch", "--input", tmp_path / "none.ais", "--db", db), "not found")
    one_line_error(run("watch", "--input", FRIO, "--serve", "nope", "--db", db), "HOST:PORT")
    one_line_error(run("watch", "--input", FRIO, "--window", "x", "--db", db), "--window")
    one_line_error(
        run("watch", "--input", FRIO, "--alerts-per-1000", "0", "--db", db), "--alerts-per-1000"
    )


def test_models_give_the_thresholds_they_calibrated(tmp_path, monkeypatch):
    """`--models`: the watch judges by the alert thresholds the NY hour's nearest model
    calibrated on its training period (as `detect` judges with it), not the defaults; FRIO's
    drift, at its floor (AisAbnormal's definition) either way, is the same; a folder without
    models is one line."""
    world = train_ny_nearest(tmp_path)
    calibrated = event_rules(load_detectors(world["models"], [])).thresholds
    assert calibrated != Thresholds() and calibrated.vessel_days
    used = []
    monkeypatch.setattr(
        watch_command, "Watch", lambda *a, **k: used.append(k["rules"].thresholds) or Watch(*a, **k)
    )
    live = replayed(tmp_path / "models", FRIO, "--models", world["models"])
    assert used == [calibrated]
    used.clear()  # a budget a hundred times larger lowers (never raises) every threshold
    replayed(tmp_path / "loose", FRIO, "--models", world["models"], "--alerts-per-1000", "1000")
    assert all(used[0].of(k) <= calibrated.of(k) for k in calibrated.minimum)
    pd.testing.assert_frame_equal(live, replayed(tmp_path / "defaults", FRIO))
    got = run("watch", "--input", FRIO, "--models", world["models"], "--db", tmp_path / "w.db")
    assert "event thresholds of 1 model(s)" in " ".join(got.stderr.split())
    one_line_error(
        run("watch", "--input", FRIO, "--models", tmp_path, "--db", tmp_path / "x.db"), "no models"
    )
