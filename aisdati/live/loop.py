"""The watch itself: each chunk of lines decoded, its vessels judged once each, the events'
changes stored, printed and shown; silences and forgotten vessels checked as the feed's clock
moves; counters kept for the page and the progress line."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import pandas as pd

from aisdati.events.fleet import FLEET_FINDERS, Fleet, fleet_events
from aisdati.events.kinds import FLEET, KINDS
from aisdati.events.rules import EventRules
from aisdati.live.area import AreaJudge
from aisdati.live.decode import Decoder
from aisdati.live.judge import Judged, LastReport, Verdict, clean_together, judge
from aisdati.live.ledger import Change, Ledger
from aisdati.live.sources import Pacer
from aisdati.live.store import Store
from aisdati.live.vessels import Recent, Vessels
from aisdati.preprocess.settings import IngestSettings

SCAN_S = 60.0
"""Feed seconds between two looks for silent vessels and vessels to forget."""
FLEET_SCAN_S = 1800.0
"""Feed seconds between two looks for the fleet kinds over every window (`Watch._fleet`): a scan
costs about as much as judging every vessel once, and an encounter lasts hours (at 10,000
vessels, every 10 minutes held the watch near 1,000 msg/s)."""
OFF_TRAFFIC = "off-traffic"
"""The learned kind: looked for only when the area models judge a vessel's window."""
FLEET_KINDS = frozenset(FLEET) - {"identity-conflict", "identity-change"}
"""The kinds found across vessels: looked for every `FLEET_SCAN_S` over all windows (`_fleet`),
never by one vessel's judgement; but for the identity kinds, which are a vessel's own and are
looked for in its window (`aisdati.live.judge.identity_events`)."""
ONE_VESSEL_UNJUDGED = FLEET_KINDS | {OFF_TRAFFIC}
FLEET_UNJUDGED = frozenset(KINDS) - FLEET_KINDS
"""What a fleet scan leaves as it is: every kind but the fleet's."""
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
    fleet_scanned_s: float = 0.0
    area: AreaJudge | None = None
    """The area models judging each vessel's window every `area.EVERY` reports (None: none)."""

    def __post_init__(self) -> None:
        self.ledger = Ledger(self.rules.settings, new_id=self.store.new_id)

    def resume(self) -> int:
        """Pick up where the database left off: its open and recent events, and the vessels'
        windows kept when the watch stopped. The number of open events resumed."""
        self.ledger.load(self.store.resume())
        for mmsi, (cols, identity) in self.store.windows().items():
            self.vessels.recent[mmsi] = Recent.of(cols, identity)
            if len(cols["time_us"]):
                self.vessels.recent[mmsi].heard_us = int(cols["time_us"].max())
                self.vessels.clock_us = max(self.vessels.clock_us, int(cols["time_us"].max()))
        return len(self.ledger.open_events())

    def step(self, lines: list[bytes]) -> list[Change]:
        """One chunk of lines through; the event changes it brought (already stored)."""
        reports = self.decoder.reports(lines, self.vessels.clock_us)
        self.vessels.identify(self.decoder.identities())
        dirty = sorted(self.vessels.add(reports))
        if self.pacer is not None and reports.num_rows:
            self.pacer.wait(self.vessels.clock_us / 1e6)
        changes = self._judge(dirty)
        changes += self._scan()
        self.store.write(changes, self._positions(dirty))
        self.counters.count(len(lines), reports.num_rows, len(changes))
        if changes:
            self.emit(changes)
        return changes

    def _judge(self, dirty: list[int]) -> list[Change]:
        """The vessels with new reports judged together (`judge.judge`), their changes in MMSI
        order: a vessel the screen cleared has no event now, which changes only the events the
        ledger holds of it (an open one closes), so it goes to the ledger only if it has some
        there."""
        recent = self.vessels.recent
        new = {m: recent[m].new for m in dirty}
        for m in dirty:
            recent[m].new = 0
        windows = {m: (recent[m].rows, recent[m].identity) for m in dirty}
        verdict = judge(windows, self.rules, self.ingest)
        self.last.update(verdict.last)
        judged = verdict.judged
        learned = self._learned(verdict, {m: new[m] for m in verdict.last})
        held = {m for m in verdict.last if self.ledger.known.get(m)}  # its events looked at again
        changes = []
        for mmsi in sorted(judged.keys() | learned.keys() | held):
            one = judged.get(mmsi) or verdict.quiet(mmsi)
            if mmsi in learned:
                one = replace(one, events=one.events + learned[mmsi], unjudged=FLEET_KINDS)
            else:
                one = replace(one, unjudged=ONE_VESSEL_UNJUDGED)
            changes += self.ledger.update(mmsi, one)
        return changes

    def _learned(self, verdict: Verdict, new: dict[int, int]) -> dict[int, list[dict]]:
        """The off-traffic events of the vessels the area models judge this chunk (all scored
        together), by MMSI; a vessel left out was not judged by them."""
        if self.area is None:
            return {}
        due = self.area.due(new)
        who = {m: self.vessels.recent[m].identity for m in due}
        return self.area.judge({m: verdict.reports_of(m) for m in due}, who)

    def _scan(self) -> list[Change]:
        """Every `SCAN_S` of the feed's clock: gaps opened for vessels silent at sea, and the
        vessels to forget (their open events closed)."""
        clock_s = self.vessels.clock_us / 1e6
        if clock_s - self.scanned_s < SCAN_S:
            return []
        self.scanned_s = clock_s
        changes = self._fleet()
        for mmsi, last in self.last.items():
            if last.limit_s is None or clock_s - last.time_s <= last.limit_s:
                continue  # (`Ledger.silent` says so too: most vessels end here, cheaply)
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

    def _fleet(self, now: bool = False) -> list[Change]:
        """The fleet kinds (`aisdati.events.fleet.fleet_events`) over every vessel's window,
        every `FLEET_SCAN_S` of the feed's clock (`now`: at once), their events through the
        ledger as the others' (each under the vessel it is of; a vessel's open fleet event not
        found again closes); then what only this scan can tell of the other events: each gap's
        coverage (`Ledger.cover`), and the one-vessel events a fleet event explains withdrawn
        (`Ledger.withdraw`), as detect folds them. Nothing to do while no fleet finder is
        registered."""
        clock_s = self.vessels.clock_us / 1e6
        if not FLEET_FINDERS or (not now and clock_s - self.fleet_scanned_s < FLEET_SCAN_S):
            return []
        self.fleet_scanned_s = clock_s
        recent = self.vessels.recent
        mmsi = [m for m, one in recent.items() if len(one.rows)]
        together = clean_together(mmsi, [recent[m].rows for m in mmsi], self.ingest)
        reports = {m: together.of(k) for k, m in enumerate(together.mmsi) if together.sizes[k]}
        who = {m: recent[m].identity for m in reports}  # (`asdict` copied each history too)
        identity = {m: {"name": i.name, "ship_type": i.ship_type, "length_m": i.length_m}
                    for m, i in who.items()}  # fmt: skip
        fleet = Fleet(reports, identity)
        found = fleet_events(fleet, self.rules, pd.DataFrame(), FLEET_KINDS)
        rows: dict[int, list[dict]] = {}
        for row in found.to_dict("records"):
            rows.setdefault(int(row["mmsi"]), []).append(row)
        held = {m for m in reports if any(e.state == "open" and e.fields["kind"] in FLEET_KINDS
                                          for e in self.ledger.known.get(m, ()))}  # fmt: skip
        changes = []
        for m in sorted(rows.keys() | held):
            v = reports[m]
            judged = Judged(rows.get(m, []), float(v.time_s[0]), float(v.time_s[-1]), v,
                            FLEET_UNJUDGED)  # fmt: skip
            changes += self.ledger.update(m, judged)
        changes += self.ledger.cover(fleet, self.rules)
        return changes + self.ledger.withdraw(clock_s, self.vessels.window_s)

    def end(self) -> list[Change]:
        """The feed ended (a replay, stdin closed): the fleet kinds looked for once more, so
        that its last stretch is judged as detect judges it (already stored)."""
        changes = self._fleet(now=True)
        self.store.write(changes, [])
        if changes:
            self.emit(changes)
        return changes

    def _positions(self, dirty: list[int]) -> list[tuple]:
        """The vessels table's rows of the vessels with new reports and a report judged: who
        each is and its last report (`store.VESSEL_FIELDS` less `recent`, times in
        microseconds)."""
        out = []
        for mmsi in dirty:
            if mmsi not in self.last:
                continue
            one = self.vessels.recent[mmsi]
            t, lon, lat, sog, cog, heading, status = one.rows[-1].tolist()
            who = one.identity
            out.append((mmsi, who.name, who.ship_type, who.length_m, int(t), lon, lat, sog, cog,
                        heading, None if status < 0 else int(status)))  # fmt: skip
        return out

    def stop(self) -> int:
        """Keep what a restart resumes from: the windows, and the open events marked stopped.
        The number of events left open."""
        windows = {m: self.vessels.window(m) for m in list(self.vessels.recent)}
        return self.store.stop({m: w for m, w in windows.items() if len(w["time_us"])})
