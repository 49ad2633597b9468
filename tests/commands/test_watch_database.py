"""`aisdati watch` and its SQLite database as a user meets them: two watches on one file keep
both their events, replays in turn never overwrite one (ids come from the database), a locked
or damaged file at start is one line with nothing written, another writer's lock mid-stream is
waited out (and beyond its bound stops the watch as SIGTERM does), and a port in use for
--serve leaves no database behind. (The PostgreSQL password: tests/live/test_store.py.)"""

from __future__ import annotations

import hashlib
import signal
import socket
import sqlite3
import subprocess
import sys
import time

from tests.helpers.cli import one_line_error, run
from tests.helpers.live import EVENTS, FRIO, ROOT, Feed, events, poll, stopped, watch

LOTUS = EVENTS / "219165000_ssc_1.ais"
STOC = EVENTS / "212123000_drift_1.ais"


def test_two_watches_on_one_file_keep_both_events(tmp_path):
    """Both start on an empty database; FRIO's drift is found first, LOTUS's speed change
    second: each watch numbered its first event #1, and the second replaced the first."""
    db = tmp_path / "w.sqlite"
    frio = Feed(FRIO.read_bytes().splitlines(), until=0)
    lotus = Feed(LOTUS.read_bytes().splitlines(), until=0)
    procs = [
        watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", db, out=tmp_path / name)
        for feed, name in ((frio, "frio"), (lotus, "lotus"))
    ]
    try:
        for name in ("frio", "lotus"):
            poll(lambda n=name: "connected" in (tmp_path / n / "stderr").read_text(), 60, name)
        frio.until = len(frio.lines)
        poll(lambda: "closed" in set(events(db)["state"]), 60, "FRIO's drift")
        lotus.until = len(lotus.lines)
        poll(lambda: len(events(db)) == 2, 60, "LOTUS's speed change beside it")
    finally:
        for proc in procs:
            stopped(proc)
        frio.stop()
        lotus.stop()
    table = events(db)
    assert sorted(table["kind"]) == ["drift", "sudden-speed-change"]
    assert table["event_id"].is_unique


def test_replays_in_turn_never_overwrite_an_event(tmp_path):
    """LOTUS (5 October), FRIO (28 September), then STOC MARCIA's loitering (2-3 October):
    the third restart reloaded LOTUS's event alone (within a day of the newest) and numbered
    its loitering after it, over FRIO's drift."""
    runs = [(LOTUS,), (FRIO,), (STOC, "--window", "1d")]
    alone = []
    for k, (recording, *options) in enumerate(runs):
        db = tmp_path / f"alone{k}.sqlite"
        assert run("watch", "--input", recording, *options, "--db", db).exit_code == 0
        alone += sorted(events(db)["kind"])
    db = tmp_path / "w.sqlite"
    for recording, *options in runs:
        got = run("watch", "--input", recording, *options, "--db", db)
        assert got.exit_code == 0, got.output
    table = events(db)
    assert "loitering" in alone and sorted(table["kind"]) == sorted(alone)
    assert table["event_id"].is_unique


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_locked_or_damaged_database_at_start_is_one_line(tmp_path):
    db = tmp_path / "w.sqlite"
    holder = sqlite3.connect(db, isolation_level=None)
    holder.execute("CREATE TABLE other (x)")
    holder.execute("BEGIN EXCLUSIVE")  # another program writing it
    try:
        before = digest(db)
        one_line_error(run("watch", "--input", FRIO, "--db", db), "w.sqlite: database is locked")
        assert digest(db) == before
    finally:
        holder.close()
    damaged = tmp_path / "damaged.sqlite"
    damaged.write_bytes(b"not a database, " * 256)
    one_line_error(run("watch", "--input", FRIO, "--db", damaged), "file is not a database")
    assert damaged.read_bytes() == b"not a database, " * 256


def mid_drift(lines: list[bytes]) -> int:
    """The first line stamped 16:52: FRIO's drift (16:37:54-16:57:24) is open by then."""
    return next(k for k, line in enumerate(lines) if line.startswith(b"$PGHP,1,2014,9,28,16,52"))


def locked(db) -> sqlite3.Connection:
    """Another writer holding the database's write lock (until it closes)."""
    holder = sqlite3.connect(db, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    return holder


def open_drift(tmp_path, feed: Feed, code: str | None = None) -> subprocess.Popen:
    """A watch on `feed` (stopped mid-drift), once the drift is open in its database and every
    line sent is read; `code`: the Python that starts it (a bound of the test's own)."""
    db = tmp_path / "w.sqlite"
    args = ["--input", f"tcp://127.0.0.1:{feed.port}", "--db", db]
    if code is None:
        proc = watch(*args, out=tmp_path / "first")
    else:
        (tmp_path / "first").mkdir()
        proc = subprocess.Popen(
            [sys.executable, "-c", code, "watch", *map(str, args)], cwd=ROOT,
            stdout=(tmp_path / "first" / "stdout").open("w"),
            stderr=(tmp_path / "first" / "stderr").open("w"),
        )  # fmt: skip
    poll(lambda: "open" in set(events(db)["state"]), 60, "the drift to open")
    poll(lambda: feed.sent >= feed.until, 30, "every line sent")
    time.sleep(1.0)  # read and written
    return proc


def test_a_lock_held_mid_stream_is_waited_out(tmp_path):
    """Another writer holds the lock 8 s (the watch died after 5 s, with two tracebacks, its
    drift left open without `stopped_at`): the watch waits, then reads on."""
    lines = FRIO.read_bytes().splitlines()
    feed, db = Feed(lines, until=mid_drift(lines)), tmp_path / "w.sqlite"
    try:
        proc = open_drift(tmp_path, feed)
        holder = locked(db)
        feed.until = len(lines)  # the rest comes while the file is locked
        time.sleep(8.0)
        holder.close()
        poll(lambda: "closed" in set(events(db)["state"]), 60, "the drift to close")
        assert proc.poll() is None  # still watching
        assert stopped(proc) == 143
    finally:
        feed.stop()
    assert "Traceback" not in (tmp_path / "first" / "stderr").read_text()
    (row,) = events(db).itertuples()
    assert (row.kind, row.state, row.n_reports) == ("drift", "closed", 119)  # the batch's


def test_a_lock_held_past_the_bound_stops_the_watch_in_one_line(tmp_path):
    """Past its bound (2 s here, 60 s as shipped) the watch stops as SIGTERM stops it, in one
    line: the drift stays open in the database, and a restart resumes it."""
    lines = FRIO.read_bytes().splitlines()
    feed, db = Feed(lines, until=mid_drift(lines)), tmp_path / "w.sqlite"
    bound = "import aisdati.live.store as s; s.LOCK_WAIT_S = 2\nfrom aisdati.cli import app; app()"
    try:
        proc = open_drift(tmp_path, feed, bound)
        holder = locked(db)
        feed.until += 200  # lines to read and write while locked
        try:
            assert proc.wait(timeout=60) == 2
        finally:
            holder.close()
        said = (tmp_path / "first" / "stderr").read_text()
        assert "Traceback" not in said
        (error,) = [line for line in said.splitlines() if line.startswith("error:")]
        assert "w.sqlite: database is locked" in error
        assert list(events(db)["state"]) == ["open"]
        again = watch("--input", f"tcp://127.0.0.1:{feed.port}", "--db", db, out=tmp_path / "2")
        feed.until = len(lines)
        poll(lambda: "closed" in set(events(db)["state"]), 60, "the drift to close")
        assert stopped(again, signal.SIGINT) == 130
    finally:
        feed.stop()
    assert "resumed 1 open event(s)" in (tmp_path / "2" / "stderr").read_text()
    assert list(events(db)["kind"]) == ["drift"]  # the same drift, not a second one


def test_a_port_in_use_leaves_no_database(tmp_path):
    with socket.create_server(("127.0.0.1", 0)) as busy:
        port = busy.getsockname()[1]
        serve = f"127.0.0.1:{port}"
        got = run("watch", "--input", FRIO, "--serve", serve, "--db", tmp_path / "w.db")
    one_line_error(got, f"--serve 127.0.0.1:{port}: Address already in use")
    assert not (tmp_path / "w.db").exists()
