"""Reports from the future set aside: a report dated far ahead of the feed's clock (one bad
tag block dated 2099) would move the clock there, and with it every vessel would be forgotten,
every open event closed early, and a paced replay would sleep for years. Such a report is held
and counted (`future`) instead; the clock never moves to it.

A feed may also truly jump ahead: after an outage, or a watch restarted a day later. So a report
ahead of the clock is taken in, and the clock moves, once `CONFIRM` reports lie within
`AHEAD_S` from it: three reports agreeing on the new time are the feed, one is a fault."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

AHEAD_S = 3600.0
"""How far ahead of the feed's clock a report may be and still be taken in at once."""
CONFIRM = 3
"""Reports within `AHEAD_S` of each other that move the clock however far ahead they are."""
HELD_MAX = 10_000
"""Reports held at most (the oldest beyond are dropped, still counted)."""


class FutureGuard:
    """The reports held as too far ahead, and how many were set aside (held now, or dropped)."""

    def __init__(self) -> None:
        self.held: pa.Table | None = None
        self.dropped = 0

    @property
    def set_aside(self) -> int:
        return self.dropped + (0 if self.held is None else self.held.num_rows)

    def admit(self, reports: pa.Table, clock_us: int) -> pa.Table:
        """The reports to take in now, given the feed's clock (0: no report yet), held ones
        confirmed since among them; the rest held."""
        limit = clock_us + AHEAD_S * 1e6 if clock_us else -np.inf
        times = _times(reports)
        if clock_us and (not len(times) or times.max() <= limit):
            if self.held is None:
                return reports  # the usual chunk: nothing ahead, nothing held
            now = max(clock_us, int(times.max())) if len(times) else clock_us
            return pa.concat_tables([reports, self._sorted_out(self.held, now)])
        pool = reports if self.held is None else pa.concat_tables([self.held, reports])
        return self._sorted_out(pool, clock_us)

    def _sorted_out(self, pool: pa.Table, clock_us: int) -> pa.Table:
        """The reports of `pool` taken in, in time order from `clock_us`; the others held."""
        times = _times(pool)
        order = np.argsort(times, kind="stable")
        ordered = times[order]
        taken = np.zeros(len(times), bool)
        clock = clock_us or None
        ahead = AHEAD_S * 1e6
        for i, k in enumerate(order):
            t = times[k]
            within = clock is not None and t <= clock + ahead
            if within or np.searchsorted(ordered, t + ahead, "right") - i >= CONFIRM:
                taken[k] = True
                clock = t if clock is None else max(clock, int(t))
        held = pool.filter(pa.array(~taken))
        if held.num_rows > HELD_MAX:
            self.dropped += held.num_rows - HELD_MAX
            held = held.slice(held.num_rows - HELD_MAX)
        self.held = held if held.num_rows else None
        return pool.filter(pa.array(taken))


def _times(table: pa.Table) -> np.ndarray:
    """The reports' times in microseconds."""
    return table.column("time").to_numpy().view(np.int64)
