"""The feed's counters: the progress line's rate counts the lines of the first chunk (a replay's
first 2,000 lines, judged while numba compiles, were shown as "2,000 lines (0/s)")."""

from __future__ import annotations

import time

from aisdati.live.loop import RATE_S, Counters


def test_the_first_chunk_counts_in_the_rate():
    counters = Counters()
    time.sleep(0.2)
    counters.count(2000, 900, 0)
    assert 2000 / (0.2 + 1.0) < counters.rate() <= 2000 / 0.2


def test_the_rate_is_of_the_last_seconds():
    counters = Counters(begun=time.monotonic() - 60)
    counters.recent.append((time.monotonic() - RATE_S - 1, 10**6))  # too old to count
    counters.count(500, 0, 0)
    assert counters.rate() == 500 / RATE_S
