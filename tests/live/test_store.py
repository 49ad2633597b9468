"""The database: SQLite always, and a real PostgreSQL server the test starts itself (a
throwaway cluster on a free port; skipped, saying why, where none can be started). A watch
stopped in the middle of FRIO's drift leaves it open and marked; a new watch on the same
database resumes it, and the whole replay gives one drift, the same as one uninterrupted run."""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest

from aisdati.live.loop import Watch
from aisdati.live.sources import recordings, replay
from aisdati.live.store import open_store
from tests.helpers.cli import one_line_error, run
from tests.helpers.live import FRIO, free_port

CHUNK_LINES = 200
"""Lines per step: about two minutes of FRIO, so the watch can stop in the middle of the drift."""


def pg_tool(name: str) -> str | None:
    """A PostgreSQL server program: on the PATH, or where Debian's package puts it."""
    found = sorted(Path("/usr/lib/postgresql").glob(f"*/bin/{name}"))
    return shutil.which(name) or (str(found[-1]) if found else None)


def as_postgres(cmd: list[str]) -> list[str]:
    """Run as the `postgres` user when root (the server refuses to run as root)."""
    return ["runuser", "-u", "postgres", "--", *cmd] if os.geteuid() == 0 else cmd


@pytest.fixture(scope="module")
def postgres() -> Iterator[str]:
    initdb, pg_ctl = pg_tool("initdb"), pg_tool("pg_ctl")
    if not (initdb and pg_ctl):
        pytest.skip("no PostgreSQL server here (make postgres installs Debian's postgresql)")
    folder = Path(tempfile.mkdtemp(prefix="aisdati-pg-"))
    if os.geteuid() == 0:
        shutil.chown(folder, "postgres", "postgres")
    port = free_port()
    data = folder / "data"
    try:
        options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1"
        for cmd in (
            [initdb, "-D", str(data), "-A", "trust", "-U", "postgres"],
            [pg_ctl, "-D", str(data), "-w", "-l", str(folder / "log"), "-o", options, "start"],
        ):
            subprocess.run(as_postgres(cmd), check=True, capture_output=True, timeout=120)
    except (subprocess.SubprocessError, OSError) as exc:
        shutil.rmtree(folder, ignore_errors=True)
        pytest.skip(f"PostgreSQL could not be started here: {exc}")
    try:
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run(as_postgres([pg_ctl, "-D", str(data), "-m", "immediate", "stop"]),
                       capture_output=True, timeout=60)  # fmt: skip
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request, tmp_path: Path) -> str:
    if request.param == "sqlite":
        return str(tmp_path / "watch.sqlite")
    return request.getfixturevalue("postgres")


def rows(url: str) -> list[tuple]:
    store = open_store(url)
    try:
        cur = store.conn.execute(
            "SELECT kind, state, stopped_at, start_time, end_time, n_reports FROM events "
            "ORDER BY event_id"
        )
        return [tuple(_text(x) for x in r) for r in cur.fetchall()]
    finally:
        store.close()


def _text(x: object) -> str | None:
    """A value as text, a time as ISO 8601 whichever database gave it."""
    if x is None:
        return None
    return x.isoformat() if hasattr(x, "isoformat") else str(x)


def test_a_stopped_watch_resumes_its_open_drift(db, tmp_path):
    chunks = replay(recordings(FRIO), CHUNK_LINES)
    first = Watch(open_store(db))
    while not first.ledger.open_events():
        first.step(next(chunks))
    assert first.stop() == 1
    first.store.close()
    ((kind, state, stopped_at, *_),) = rows(db)
    assert (kind, state) == ("drift", "open") and stopped_at is not None  # marked as stopped
    second = Watch(open_store(db))
    assert second.resume() == 1
    for chunk in chunks:
        second.step(chunk)
    second.stop()
    second.store.close()
    once = str(tmp_path / "once.sqlite")  # the same replay, never stopped
    whole = Watch(open_store(once))
    for chunk in replay(recordings(FRIO), CHUNK_LINES):
        whole.step(chunk)
    whole.store.close()
    resumed = rows(db)
    assert [r[1:3] for r in resumed] == [("closed", None)]
    assert [r[3:] for r in resumed] == [r[3:] for r in rows(once)]  # nothing lost or doubled


def test_the_postgresql_password_is_never_printed(postgres):
    """Neither the connection's error nor the watch's lines ("stopped; 0 open event(s) kept
    open in postgresql://...") show the URL's password (the test server trusts any)."""
    with psycopg.connect(postgres, autocommit=True) as conn:
        conn.execute("DROP DATABASE IF EXISTS secret")
        conn.execute("CREATE DATABASE secret")
    url = postgres.replace("postgres@", "postgres:S3CRET@").rsplit("/", 1)[0] + "/secret"
    got = run("watch", "--input", FRIO, "--db", url)
    assert got.exit_code == 0, got.output
    assert "postgres:***@" in got.stderr and "S3CRET" not in got.output
    unreachable = f"postgresql://ais:S3CRET@127.0.0.1:{free_port()}/ais"
    got = run("watch", "--input", FRIO, "--db", unreachable)
    one_line_error(got, r"postgresql://ais:\*\*\*@127")
    assert "S3CRET" not in got.output


def test_the_database_keeps_each_events_class(db):
    """Both databases keep FRIO's drift as an alert (events.parquet's `class`)."""
    watch = Watch(open_store(db))
    for chunk in replay(recordings(FRIO), CHUNK_LINES):
        watch.step(chunk)
    watch.stop()
    watch.store.close()
    store = open_store(db)
    try:
        got = store.conn.execute("SELECT kind, class FROM events").fetchall()
    finally:
        store.close()
    assert ("drift", "alert") in [tuple(r) for r in got]


def test_an_events_table_from_before_the_class_gains_it(tmp_path):
    path = tmp_path / "old.sqlite"
    with sqlite3.connect(path) as conn:
        conn.execute(
            "CREATE TABLE events (event_id BIGINT PRIMARY KEY, mmsi BIGINT NOT NULL, name TEXT, "
            "ship_type TEXT, kind TEXT NOT NULL, start_time TEXT NOT NULL, end_time TEXT NOT NULL, "
            "duration_s REAL, n_reports BIGINT, lon REAL, lat REAL, strength REAL, "
            "evidence TEXT, model TEXT, state TEXT NOT NULL, stopped_at TEXT, "
            "updated_at TEXT NOT NULL, stretch TEXT)"
        )
    watch = Watch(open_store(str(path)))
    for chunk in replay(recordings(FRIO), CHUNK_LINES):
        watch.step(chunk)
    watch.stop()
    watch.store.close()
    with sqlite3.connect(path) as conn:
        got = conn.execute("SELECT kind, class, rarity_days FROM events").fetchall()
    assert ("drift", "alert", None) in got
