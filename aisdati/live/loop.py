"""The watch itself: each chunk of lines decoded, its vessels judged once each, the events'
changes stored, printed and shown; silences and forgotten vessels checked as the feed's clock
moves; counters kept for the page and the progress line."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import pandas as pd

from aisdati.events.rules import EventRules
from aisdati.live.area import AreaJudge
from aisdati.live.decode import Decoder
from aisdati.live.judge import Judged, LastReport, judge
from aisdati.live.ledger import Change, Ledger
from aisdati.live.sources import Pacer
from aisdati.live.store import Store
from aisdati.live.vessels import Recent, Vessels
from aisdati.preprocess.settings import IngestSettings

SCAN_S = 60.0
"""Feed seconds between two looks for silent vessels and vessels to forget."""
OFF_TRAFFIC = "off-traffic"
"""The learned kind: looked for only when the area models judge a vessel's window."""
RATE_S = 5.0
"""Wall seconds over which messages/s is measured."""


@dataclass
class Counters:
    """The feed's summary, for the page and the progress line."""

    lines: int = 0
    reports: int = 0
    changes: int = 0
    recent: deque = field(default_factory=deque)  # (monotonic s, lines) of the last RATE_S
    begun: float = field(default_factory=time.monotonic)

    def count(self, lines: int, reports: int, changes: int) -> None:
        now = time.monotonic()
        self.lines += lines
        self.reports += reports
        self.changes += changes
        self.recent.append((now, lines))
        while self.recent and self.recent[0][0] < now - RATE_S:
            self.recent.popleft()

    def rate(self) -> float:
        """Lines per second over the last `RATE_S`, or since counting began when that is
        sooner (the first chunk's lines count: they came in that time)."""
        now = time.monotonic()
        since = max(self.begun, now - RATE_S)
        return sum(n for t, n in self.recent if t >= since) / max(now - since, 1e-3)


@dataclass
class Watch:
    store: Store
    vessels: Vessels = field(default_factory=Vessels)
    rules: EventRules = field(default_factory=EventRules)
    ingest: IngestSettings = field(default_factory=IngestSettings)
    pacer: Pacer | None = None
    emit: Callable[[list[Change]], None] = lambda changes: None
    decoder: Decoder = field(default_factory=Decoder)
    counters: Counters = field(default_factory=Counters)
    ledger: Ledger = field(init=False)
    last: dict[int, LastReport] = field(default_factory=dict)
    scanned_s: float = 0.0
    area: AreaJudge | None = None
    """The area models judging each vessel's window every `area.EVERY` reports (None: none)."""

    def __post_init__(self) -> None:
        self.ledger = Ledger(self.rules.settings, new_id=self.store.new_id)

    def resume(self) -> int:
        """Pick up where the database left off: its open and recent events, and the vessels'
        windows kept when the watch stopped. The number of open events resumed."""
        self.ledger.load(self.store.resume())
        for mmsi, (cols, identity) in self.store.windows().items():
            self.vessels.recent[mmsi] = Recent(cols, identity)
            if len(cols["time_us"]):
                self.vessels.recent[mmsi].heard_us = int(cols["time_us"].max())
                self.vessels.clock_us = max(self.vessels.clock_us, int(cols["time_us"].max()))
        return len(self.ledger.open_events())

    def step(self, lines: list[bytes]) -> list[Change]:
        """One chunk of lines through; the event changes it brought (already stored)."""
        reports = self.decoder.reports(lines, self.vessels.clock_us)
        self.vessels.identify(self.decoder.identities())
        dirty = self.vessels.add(reports)
        if self.pacer is not None and reports.num_rows:
            self.pacer.wait(self.vessels.clock_us / 1e6)
        changes = self._judge(sorted(dirty))
        changes += self._scan()
        self.store.write(changes, [self._position(m) for m in sorted(dirty) if m in self.last])
        self.counters.count(len(lines), reports.num_rows, len(changes))
        if changes:
            self.emit(changes)
        return changes

    def _judge(self, dirty: list[int]) -> list[Change]:
        """The vessels with new reports judged together, their changes in MMSI order."""
        new = {m: self.vessels.recent[m].new for m in dirty}
        windows = {m: (self.vessels.window(m), self.vessels.recent[m].identity) for m in dirty}
        judged = judge(windows, self.rules, self.ingest)
        learned = self._learned(judged, new)
        changes = []
        for mmsi, one in judged.items():
            self.last[mmsi] = one.last
            if mmsi in learned:
                one = replace(one, events=one.events + learned[mmsi])
            else:
                one = replace(one, unjudged=frozenset({OFF_TRAFFIC}))
            changes += self.ledger.update(mmsi, one)
        return changes

    def _learned(self, judged: dict[int, Judged], new: dict[int, int]) -> dict[int, list[dict]]:
        """The off-traffic events of the vessels the area models judge this chunk (all scored
        together), by MMSI; a vessel left out was not judged by them."""
        if self.area is None:
            return {}
        due = [m for m in self.area.due({m: new[m] for m in judged}) if m in judged]
        who = {m: self.vessels.recent[m].identity for m in due}
        return self.area.judge({m: judged[m].reports for m in due}, who)

    def _scan(self) -> list[Change]:
        """Every `SCAN_S` of the feed's clock: gaps opened for vessels silent at sea, and the
        vessels to forget (their open events closed)."""
        clock_s = self.vessels.clock_us / 1e6
        if clock_s - self.scanned_s < SCAN_S:
            return []
        self.scanned_s = clock_s
        changes = []
        for mmsi, last in self.last.items():
            identity = self.vessels.recent[mmsi].identity
            who = {"name": identity.name, "ship_type": identity.ship_type}
            if change := self.ledger.silent(last, clock_s, who):
                changes.append(change)
        for mmsi in self.vessels.forget():
            self.last.pop(mmsi, None)
            if self.area is not None:
                self.area.forget(mmsi)
            changes += self.ledger.forget(mmsi)
        return changes

    def _position(self, mmsi: int) -> dict[str, Any]:
        """A vessel's row of the vessels table: who it is and its last report."""
        one = self.vessels.recent[mmsi]
        last = {k: v[-1] for k, v in one.columns.items()}
        return {
            "mmsi": mmsi,
            "name": one.identity.name,
            "ship_type": one.identity.ship_type,
            "length_m": one.identity.length_m,
            "time": pd.Timestamp(int(last["time_us"]), unit="us", tz="UTC"),
            **{k: float(last[k]) for k in ("lon", "lat", "sog", "cog", "heading")},
            "status": None if last["status"] < 0 else int(last["status"]),
        }

    def stop(self) -> int:
        """Keep what a restart resumes from: the windows, and the open events marked stopped.
        The number of events left open."""
        windows = {m: self.vessels.window(m) for m in list(self.vessels.recent)}
        return self.store.stop({m: w for m, w in windows.items() if len(w["time_us"])})
