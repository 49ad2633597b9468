"""The sources: a real TCP server on 127.0.0.1 streaming the shipped NMEA, killed and started
again (the source reconnects and says so), a UDP sender, and the line splitting they share."""

from __future__ import annotations

import socket
import time

from aisdati.live.sources import Lines, Pacer, open_source, tcp, udp
from aisdati.preprocess.nmea import MAX_LINE_BYTES
from tests.helpers.live import FRIO, Feed, free_port, poll


def take(chunks, n: int, said: list[str] | None = None, timeout: float = 20.0) -> list[bytes]:
    """Lines from a source's chunks until `n` came (or the deadline)."""
    got: list[bytes] = []
    poll(lambda: got.extend(next(chunks)) or len(got) >= n, timeout, f"{n} lines ({said})")
    return got


def test_tcp_reconnects_after_the_server_is_killed_and_restarted():
    lines = FRIO.read_bytes().splitlines()
    feed = Feed(lines, until=500)
    said: list[str] = []
    chunks = tcp("127.0.0.1", feed.port, said.append)
    first = take(chunks, 500, said)
    assert first == lines[:500]
    feed.stop()  # killed: the connection drops, and the next tries are refused
    poll(lambda: next(chunks) is not None and any("dropped" in s for s in said), 10, "drop")
    poll(lambda: next(chunks) is not None and any("refused" in s.lower() for s in said), 10)
    assert any("reconnecting in" in s for s in said)
    again = Feed(lines[500:], port=feed.port, until=300)
    try:
        rest = take(chunks, 300, said)
    finally:
        again.stop()
    assert rest == lines[500:800]  # no line lost or doubled across the restart
    assert sum("connected" in s and "dropped" not in s for s in said) == 2


def test_udp_datagrams_become_lines():
    port = free_port(socket.SOCK_DGRAM)
    said: list[str] = []
    chunks = udp("127.0.0.1", port, said.append)
    assert next(chunks) == []  # bound and listening, nothing yet
    lines = FRIO.read_bytes().splitlines()[:100]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for k in range(0, 100, 10):
            s.sendto(b"\r\n".join(lines[k : k + 10]), ("127.0.0.1", port))
    assert take(chunks, 100, said) == lines
    assert "listening" in said[0]


def test_a_line_cut_between_reads_is_joined_and_an_endless_one_is_cut():
    split = Lines()
    assert split.split(b"!AIVDM,1,1,,A,13aEOK") == []
    assert split.split(b"?P00PD2wVMdMeGUnwP00H0,0*0B\r\n\r\nnext") == [
        b"!AIVDM,1,1,,A,13aEOK?P00PD2wVMdMeGUnwP00H0,0*0B"
    ]
    assert split.rest() == [b"next"]
    cut = split.split(b"x" * (MAX_LINE_BYTES + 10))
    assert len(cut) == 1 and len(cut[0]) == MAX_LINE_BYTES + 1


def test_a_file_replays_in_order_and_ends():
    got = [line for chunk in open_source(str(FRIO), print) for line in chunk]
    assert got == FRIO.read_bytes().splitlines()


def test_the_pacer_waits_for_the_feed_time():
    pacer = Pacer(speed=10.0)
    pacer.wait(1000.0)
    start = time.monotonic()
    pacer.wait(1002.0)  # 2 feed seconds at 10x: 0.2 wall seconds
    assert 0.19 <= time.monotonic() - start < 1.0
