"""What the watch's tests share: a real TCP feed on 127.0.0.1 that streams NMEA lines (and can
pause, be killed and restarted), `aisdati watch` in a process of its own with its output in
files, polling with a deadline, and the events a SQLite database holds."""

from __future__ import annotations

import os
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
EVENTS = ROOT / "tests" / "data" / "events"
FRIO = EVENTS / "538004030_drift_1.ais"


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def poll(condition: Callable[[], object], timeout: float = 30.0, what: str = "") -> object:
    """`condition()`'s first true value, polled until `timeout` seconds have passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if value := condition():
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what or condition}")


class Feed:
    """A TCP server streaming `lines` to each client from where the last one stopped, up to
    `until` lines (raise it to let more through); `stop` kills it (clients dropped)."""

    def __init__(self, lines: list[bytes], port: int | None = None, until: int | None = None):
        self.lines, self.sent, self.until = lines, 0, len(lines) if until is None else until
        self.port = port or free_port()
        self.server = socket.create_server(("127.0.0.1", self.port))
        self.running = True
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.server.settimeout(0.05)
        while self.running:
            try:
                conn, _ = self.server.accept()
            except (TimeoutError, OSError):
                continue
            with conn:
                self._stream(conn)

    def _stream(self, conn: socket.socket) -> None:
        while self.running:
            if self.sent >= self.until:
                if _closed(conn):  # else the next lines would go to a dead client, lost
                    return
                time.sleep(0.02)
                continue
            batch = self.lines[self.sent : min(self.until, self.sent + 200)]
            try:
                conn.sendall(b"\r\n".join(batch) + b"\r\n")
            except OSError:
                return
            self.sent += len(batch)

    def stop(self) -> None:
        self.running = False
        self.thread.join(timeout=5)
        self.server.close()


def _closed(conn: socket.socket) -> bool:
    """Whether the client has gone (its end closed), without waiting."""
    try:
        return conn.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True


def watch(*args: object, out: Path) -> subprocess.Popen:
    """`aisdati watch ARGS` in its own process; its stdout in out/stdout, stderr in out/stderr."""
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = "from aisdati.cli import app; app()"
    return subprocess.Popen(
        [sys.executable, "-c", code, "watch", *[str(a) for a in args]],
        stdout=(out / "stdout").open("w"),
        stderr=(out / "stderr").open("w"),
        env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def stopped(proc: subprocess.Popen, sig: int = signal.SIGTERM, timeout: float = 30.0) -> int:
    """Send `sig` and wait for the process to end; its exit code."""
    proc.send_signal(sig)
    return proc.wait(timeout=timeout)


def events(db: Path) -> pd.DataFrame:
    """The events table of a watch's SQLite database (empty before it has one)."""
    if not db.exists():
        return pd.DataFrame(columns=["kind", "state"])
    with sqlite3.connect(db) as conn:
        try:
            return pd.read_sql("SELECT * FROM events ORDER BY event_id", conn)
        except pd.errors.DatabaseError:
            return pd.DataFrame(columns=["kind", "state"])
