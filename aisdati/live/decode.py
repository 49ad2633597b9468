"""Lines to reports, as ingest reads them: pyais decoding with tag blocks, `$PGHP` times,
multi-sentence messages and another receiver's copy counted once (`aisdati.preprocess.nmea`),
then ingest's row checks (`convert.to_canonical`, `clean.check_values`). What gives no report
is counted by reason, never fatal; a report far ahead of the feed's clock is held and counted as
`future` (`aisdati.live.future`)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.live.future import FutureGuard
from aisdati.preprocess.clean import check_values
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.nmea import COLUMNS, NmeaDecoder, RecentMessages, static_times_us
from aisdati.preprocess.report import CODE
from aisdati.preprocess.vessels import PADDING, length_of, ship_type_of

REASON_OF = {code: reason for reason, code in CODE.items()}
QUIET = frozenset({"not_position", "duplicate_reception"})
"""Reasons that are no fault of the feed (static messages, another receiver's copy): counted,
but not among the rejected sentences the page shows."""


Seen = tuple[str | None, str | None, float, int, int, int]
"""An identity a vessel's static messages gave: (name, ship type, length, first and last time
in microseconds since the epoch, messages), as a row of identities.parquet holds it."""


@dataclass(frozen=True)
class Identity:
    """Who a vessel says it is (its latest static message), and every identity its static
    messages gave (`history`, as ingest's identities.parquet keeps it: each message's own
    fields, a message in two parts two identities)."""

    name: str | None = None
    ship_type: str | None = None
    length_m: float = np.nan
    history: tuple[Seen, ...] = ()

    def heard(self, said: tuple[str | None, str | None, float], time_us: int) -> Identity:
        """The history with one more static message (its own name, type and length)."""
        rows, same = list(self.history), None
        for k, (name, kind, length, *_) in enumerate(rows):
            if (name, kind) == said[:2] and (
                length == said[2] or (np.isnan(length) and np.isnan(said[2]))
            ):
                same = k
                break
        if same is None:
            rows.append((*said, time_us, time_us, 1))
        else:
            name, kind, length, first, last, n = rows[same]
            rows[same] = (name, kind, length, min(first, time_us), max(last, time_us), n + 1)
        return replace(self, history=tuple(rows))

    def history_table(self) -> pd.DataFrame | None:
        """The history as rows of identities.parquet (`IDENTITY_SCHEMA`), None where empty."""
        if not self.history:
            return None
        frame = pd.DataFrame(
            self.history, columns=["name", "ship_type", "length_m", "first", "last", "reports"]
        )
        for key in ("first", "last"):
            frame[key] = pd.to_datetime(frame[key], unit="us", utc=True)
        return frame


class Decoder:
    """Lines in; reports (rows of `convert.PARTITION_SCHEMA` that passed the row checks) and
    identities out; `skipped` counts every line or row that gave no report, by reason."""

    def __init__(self) -> None:
        self.skipped: Counter[str] = Counter()
        self.decoder = NmeaDecoder(self._skip, RecentMessages())
        self.future = FutureGuard()

    def _skip(self, reason: str, line: bytes) -> None:
        self.skipped[reason] += 1

    @property
    def rejected(self) -> int:
        """Sentences and rows refused for a fault (bad checksum, truncated, bad values...)."""
        return sum(n for reason, n in self.skipped.items() if reason not in QUIET)

    def reports(self, lines: list[bytes], clock_us: int = 0) -> pa.Table:
        """The reports of these lines that pass ingest's row checks and are not far ahead of
        the feed's clock `clock_us` (0: none yet), with those held before and confirmed since
        (`future.FutureGuard`)."""
        self.decoder.feed_lines(lines)
        table, codes = to_canonical(self.decoder.take(), COLUMNS, 0)
        table = check_values(table, codes)
        for code, n in zip(*np.unique(codes[codes > 0], return_counts=True), strict=True):
            self.skipped[REASON_OF[int(code)]] += int(n)
        table = self.future.admit(table.filter(pa.array(codes == 0)), clock_us)
        if self.future.set_aside or "future" in self.skipped:  # (held ones may come in later)
            self.skipped["future"] = self.future.set_aside
        return table

    def identities(self) -> dict[int, list[tuple[tuple[str | None, str | None, float], int]]]:
        """The static messages since the last call, by vessel, in order: each one's own name,
        ship type and length (read as ingest reads them; a message that gives none is left
        out) and its time (microseconds; the int64 minimum where its line gave none)."""
        out: dict[int, list] = {}
        statics = self.decoder.take_statics()
        times = static_times_us([s.time for s in statics]) if statics else []
        for (mmsi, name, kind, length, _), time_us in zip(statics, times, strict=True):
            name = (name or "").strip(PADDING) or None
            ship_type = None if kind is None else ship_type_of(str(kind))
            size = None if length is None else length_of(str(length))
            if name is None and ship_type is None and size is None:
                continue
            said = (name, ship_type, np.nan if size is None else float(size))
            out.setdefault(mmsi, []).append((said, int(time_us)))
        return out
