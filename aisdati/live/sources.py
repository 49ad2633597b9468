"""Where the sentences come from: a TCP server (connected to, and reconnected with back-off when
it drops or refuses), UDP datagrams (listened for), a file or folder of NMEA (replayed, each
file plain or compressed as ingest reads it: `.gz`, `.zst`, a `.zip` of NMEA files), or stdin.
Each source yields chunks of lines; an empty chunk when nothing came for `IDLE_S`, so that the
watch keeps its clock, its page and its counters going on a quiet feed."""

from __future__ import annotations

import contextlib
import os
import select
import socket
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from urllib.parse import urlsplit

from aisdati.errors import UserError
from aisdati.preprocess.inputs import (
    NMEA_SUFFIXES,
    Archive,
    Source,
    archive_members,
    describe_read_error,
)
from aisdati.preprocess.nmea import MAX_LINE_BYTES, read_lines
from aisdati.preprocess.streams import READ_ERRORS

IDLE_S = 0.2
"""The longest a source blocks before it yields an empty chunk."""
BACKOFF_S = (0.5, 30.0)
"""The first wait before reconnecting, and the longest: each failed try doubles it."""
REPLAY_LINES = 2000
"""Lines per chunk of a file replayed as fast as possible (one judgement of the vessels each)."""
PACED_LINES = 20
"""Lines per chunk of a file replayed at --speed: a report's wait is at most this many lines."""
PLAIN_NMEA = tuple(s for s in NMEA_SUFFIXES if s.count(".") == 1)
"""The names of a zip archive's members that are replayed (ingest's NMEA files, uncompressed)."""
Say = Callable[[str], None]


class Lines:
    """Bytes in, whole lines out: the carry of a line cut between two reads, bounded (a line
    longer than any sentence comes out cut, for the decoder to count as no sentence)."""

    def __init__(self) -> None:
        self.carry = b""

    def split(self, data: bytes) -> list[bytes]:
        lines = (self.carry + data).replace(b"\r", b"\n").split(b"\n")
        self.carry = lines.pop()
        if len(self.carry) > MAX_LINE_BYTES:
            lines.append(self.carry[: MAX_LINE_BYTES + 1])
            self.carry = b""
        return [line for line in lines if line]

    def rest(self) -> list[bytes]:
        rest, self.carry = self.carry, b""
        return [rest] if rest else []


def idle(seconds: float) -> Iterator[list[bytes]]:
    """Empty chunks for `seconds`: a wait that keeps the watch ticking."""
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        time.sleep(min(IDLE_S, left))
        yield []


def tcp(host: str, port: int, say: Say) -> Iterator[list[bytes]]:
    """A TCP server's lines, forever: a refused or dropped connection is said in one line and
    tried again after a back-off that doubles up to `BACKOFF_S[1]`."""
    wait = BACKOFF_S[0]
    while True:
        try:
            conn = socket.create_connection((host, port), timeout=5.0)
        except OSError as exc:
            say(f"tcp://{host}:{port}: {exc.strerror or exc}; reconnecting in {wait:g} s")
            yield from idle(wait)
            wait = min(2 * wait, BACKOFF_S[1])
            continue
        say(f"tcp://{host}:{port}: connected")
        got = yield from _received(conn)
        wait = BACKOFF_S[0] if got else min(2 * wait, BACKOFF_S[1])
        say(f"tcp://{host}:{port}: connection dropped; reconnecting in {wait:g} s")
        yield from idle(wait)


def _received(conn: socket.socket) -> Iterator[list[bytes]]:
    """The lines of one connection until it closes; returns whether any came."""
    lines, got = Lines(), False
    conn.settimeout(IDLE_S)
    with conn:
        while True:
            try:
                data = conn.recv(1 << 16)
            except TimeoutError:
                yield []
                continue
            except OSError:
                break
            if not data:
                break
            got = True
            yield lines.split(data)
    yield lines.rest()
    return got


def udp(host: str, port: int, say: Say) -> Iterator[list[bytes]]:
    """The lines of the datagrams sent to `host:port` (each datagram holds whole sentences)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise UserError(f"udp://{host}:{port}: {exc.strerror or exc}") from None
    say(f"udp://{host or '*'}:{port}: listening")
    sock.settimeout(IDLE_S)
    with sock:
        while True:
            try:
                data = sock.recv(1 << 16)
            except TimeoutError:
                yield []
                continue
            yield Lines().split(data + b"\n")


def replay(sources: list[Source], chunk_lines: int) -> Iterator[list[bytes]]:
    """The lines of recordings, in order, `chunk_lines` at a time, decompressed as ingest
    reads them; a corrupt or truncated one is one line."""
    for source in sources:
        chunk: list[bytes] = []
        try:
            stream, _ = source.open()
            with contextlib.closing(stream):
                for line in read_lines(stream):
                    chunk.append(line)
                    if len(chunk) >= chunk_lines:
                        yield chunk
                        chunk = []
        except READ_ERRORS as exc:
            raise describe_read_error(source, exc) from None
        yield chunk


def stdin() -> Iterator[list[bytes]]:
    """The lines piped in, until the pipe closes."""
    fd, lines = sys.stdin.buffer.fileno(), Lines()
    while True:
        ready, _, _ = select.select([fd], [], [], IDLE_S)
        if not ready:
            yield []
            continue
        data = os.read(fd, 1 << 16)
        if not data:
            yield lines.rest()
            return
        yield lines.split(data)


def recordings(path: Path) -> list[Source]:
    """What a file or folder to replay holds, in name order: plain, `.gz` and `.zst` files, and
    the NMEA members of a `.zip` archive (ingest's readers of each)."""
    found: list[Source] = []
    for file in files_of(path):
        found += zip_members(file) if file.name.lower().endswith(".zip") else [Source(file)]
    return found


def zip_members(path: Path) -> list[Source]:
    """The NMEA members of a zip archive (`.nmea`, `.ais`, `.txt`), in name order."""
    archive = Archive(path)
    members = sorted(archive_members(path, archive, PLAIN_NMEA), key=lambda i: i.filename)
    return [Source(path, info.filename, archive) for info in members]


def files_of(path: Path) -> list[Path]:
    """A file, or a folder's files in name order."""
    if path.is_dir():
        found = sorted(p for p in path.iterdir() if p.is_file() and not p.name.startswith("."))
        if not found:
            raise UserError(f"{path}: no file to replay")
        return found
    if not path.is_file():
        raise UserError(f"{path}: not found (a source is tcp://HOST:PORT, udp://:PORT, a file "
                        "or folder of NMEA, or -)")  # fmt: skip
    return [path]


def open_source(spec: str, say: Say, paced: bool = False) -> Iterator[list[bytes]]:
    """The chunks of lines of a source given as `--input` says."""
    if spec == "-":
        return stdin()
    if spec.startswith(("tcp://", "udp://")):
        url = urlsplit(spec)
        try:
            port = url.port
        except ValueError:
            port = None
        if port is None:
            raise UserError(f"{spec}: give the port, as in {url.scheme}://HOST:PORT")
        if url.scheme == "tcp":
            return tcp(url.hostname or "127.0.0.1", port, say)
        return udp(url.hostname or "", port, say)
    return replay(recordings(Path(spec)), PACED_LINES if paced else REPLAY_LINES)


class Pacer:
    """A replay at `speed` times real time by the reports' own times: waits until the wall
    clock has caught up with the feed's."""

    def __init__(self, speed: float) -> None:
        self.speed = speed
        self.start: tuple[float, float] | None = None  # (feed seconds, monotonic seconds)

    def wait(self, feed_s: float) -> None:
        if self.start is None:
            self.start = (feed_s, time.monotonic())
            return
        due = self.start[1] + (feed_s - self.start[0]) / self.speed
        if (left := due - time.monotonic()) > 0:
            time.sleep(left)
