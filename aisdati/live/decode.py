"""Lines to reports, as ingest reads them: pyais decoding with tag blocks, `$PGHP` times,
multi-sentence messages and another receiver's copy counted once (`aisdati.preprocess.nmea`),
then ingest's row checks (`convert.to_canonical`, `clean.check_values`). What gives no report
is counted by reason, never fatal; a report far ahead of the feed's clock is held and counted as
`future` (`aisdati.live.future`)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from aisdati.live.future import FutureGuard
from aisdati.preprocess.clean import check_values
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.nmea import COLUMNS, NmeaDecoder, RecentMessages
from aisdati.preprocess.report import CODE
from aisdati.preprocess.vessels import PADDING, length_of, ship_type_of

REASON_OF = {code: reason for reason, code in CODE.items()}
QUIET = frozenset({"not_position", "duplicate_reception"})
"""Reasons that are no fault of the feed (static messages, another receiver's copy): counted,
but not among the rejected sentences the page shows."""


@dataclass(frozen=True)
class Identity:
    """Who a vessel says it is (its latest static message)."""

    name: str | None = None
    ship_type: str | None = None
    length_m: float = np.nan


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
        for line in lines:
            self.decoder.feed(line)
        table, codes = to_canonical(self.decoder.take(), COLUMNS, 0)
        table = check_values(table, codes)
        for code, n in zip(*np.unique(codes[codes > 0], return_counts=True), strict=True):
            self.skipped[REASON_OF[int(code)]] += int(n)
        table = self.future.admit(table.filter(pa.array(codes == 0)), clock_us)
        if self.future.set_aside or "future" in self.skipped:  # (held ones may come in later)
            self.skipped["future"] = self.future.set_aside
        return table

    def identities(self) -> dict[int, Identity]:
        """The vessels named by static messages since the last call (the latest of each)."""
        out = {}
        for mmsi, name, kind, length in self.decoder.take_statics():
            name = (name or "").strip(PADDING) or None
            ship_type = None if kind is None else ship_type_of(str(kind))
            size = None if length is None else length_of(str(length))
            old = out.get(mmsi, Identity())
            out[mmsi] = Identity(
                name or old.name,
                ship_type or old.ship_type,
                size if size is not None else old.length_m,
            )
        return out
