"""Events as they happen: each judgement of a vessel's window finds its events again, and the
ledger tells which are new (opened), which grew (extended) and which ended (closed).

An event found again is the one it overlaps in time (same vessel and kind). It is open while
its stretch reaches the vessel's latest report (a drift still drifting, a CUSUM stretch still
rising) and closed once a later report is not part of it; an event found already ended (a
loitering, which needs the vessel under way again; a gap, found when the vessel reappears) is
closed at once. A vessel under way that falls silent for longer than the gap kind allows opens
a gap, which closes when the vessel is heard again (or is forgotten).

What only the fleet scan can say comes after (`aisdati.live.loop.Watch._fleet`): a gap's
coverage (`cover`), and the one-vessel events a fleet event explains (`withdraw`), which detect
never raises and the watch takes back."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from aisdati.events.coverage import HEARD
from aisdati.events.fleet import Fleet, Fold, annotated
from aisdati.events.record import event_row
from aisdati.events.rules import EventRules
from aisdati.events.settings import EventSettings
from aisdati.live.judge import Judged, LastReport
from aisdati.tracks.schema import mmsi_of

COMPARED = ("start", "end", "n_reports", "strength", "evidence", "lon", "lat")
"""The fields whose change makes an event's new version (`extended` or `revised`)."""


@dataclass
class LiveEvent:
    """An event with its id and state; `fields` are events.parquet's (`EVENT_COLUMNS`)."""

    event_id: int
    fields: dict[str, Any]
    state: str = "open"

    @property
    def span_s(self) -> tuple[float, float]:
        return self.fields["start"].timestamp(), self.fields["end"].timestamp()

    def overlaps(self, kind: str, start_s: float, end_s: float) -> bool:
        a, b = self.span_s
        return self.fields["kind"] == kind and start_s <= b and end_s >= a


@dataclass(frozen=True)
class Change:
    """What happened to an event: opened, extended, closed, revised (a closed event whose
    stretch a later judgement read differently, or a gap whose coverage a fleet scan told), or
    withdrawn (a one-vessel event a fleet event explains, `into`: that event's id)."""

    what: str
    event: LiveEvent
    into: int | None = None

    @classmethod
    def of(cls, what: str, e: LiveEvent, into: int | None = None) -> Change:
        """The change with the event as it stands now (the ledger's own copy changes on)."""
        return cls(what, LiveEvent(e.event_id, dict(e.fields), e.state), into)


@dataclass
class Ledger:
    settings: EventSettings = field(default_factory=EventSettings)
    known: dict[int, list[LiveEvent]] = field(default_factory=dict)
    new_id: Callable[[], int] = field(default_factory=lambda: itertools.count(1).__next__)
    """Where a new event's id comes from: the watch's database (`Store.new_id`), so that no
    other watch on it and no restart ever gives the same id to another event."""
    folds: dict[int, Fold] = field(default_factory=dict)
    """What the fleet events explain (`Fold`), by the fleet event's id: kept while a window may
    hold what they explain, so that no later judgement raises it again (`withdraw`)."""

    def load(self, events: list[LiveEvent]) -> None:
        """The events a store kept (open ones, and recent closed ones to match again)."""
        for e in events:
            self.known.setdefault(int(e.fields["mmsi"]), []).append(e)

    def update(self, mmsi: int, judged: Judged) -> list[Change]:
        """The changes one judgement of a vessel's window brings."""
        known = self.known.setdefault(mmsi, [])
        changes, matched = [], set()
        for row in judged.events:
            start_s, end_s = row["start"].timestamp(), row["end"].timestamp()
            if self._folding(row["kind"], mmsi, start_s, end_s) is not None:
                continue  # a fleet event explains it: not raised (`withdraw`)
            state = "open" if end_s >= judged.last_s and row["kind"] != "gap" else "closed"
            match = next((e for e in known if e.overlaps(row["kind"], start_s, end_s)), None)
            if match is None:
                match = LiveEvent(self.new_id(), row, state)
                known.append(match)
                changes.append(Change.of("opened" if state == "open" else "closed", match))
            elif change := _changed(match, row, state, judged.first_s):
                changes.append(Change.of(change, match))
            matched.add(match.event_id)
        for e in known:
            if (
                e.state == "open"
                and e.event_id not in matched
                and e.fields["kind"] not in judged.unjudged
            ):
                e.state = "closed"  # its condition ended and nothing in the window says more
                changes.append(Change.of("closed", e))
        self.known[mmsi] = [e for e in known if e.state == "open" or e.span_s[1] >= judged.first_s]
        return changes

    def silent(self, last: LastReport, clock_s: float, who: dict[str, Any]) -> Change | None:
        """A gap opened for a vessel under way silent too long at sea (None: not one; its last
        report ashore is not at sea); `who`: its name and ship type."""
        silence = clock_s - last.time_s
        if last.limit_s is None or not last.limit_s < silence <= self.settings.gap_max_s:
            return None
        known = self.known.setdefault(last.mmsi, [])
        if any(e.overlaps("gap", last.time_s, last.time_s) for e in known):
            return None
        if last.ashore:
            return None
        event = LiveEvent(self.new_id(), _gap_fields(last, silence, clock_s) | who)
        known.append(event)
        return Change.of("opened", event)

    def forget(self, mmsi: int) -> list[Change]:
        """A vessel forgotten: its open events close where they last stood."""
        changes = []
        for e in self.known.pop(mmsi, []):
            if e.state == "open":
                e.state = "closed"
                changes.append(Change.of("closed", e))
        return changes

    def withdraw(self, clock_s: float, kept_s: float) -> list[Change]:
        """The one-vessel events that a fleet event held explains (`aisdati.events.fleet.
        Fold`: detect folds them) withdrawn, and forgotten: detect never raises them. Each
        fleet event's fold is kept until `kept_s` before `clock_s` (a window's span: no window
        holds a report older), so that a later judgement does not raise them again."""
        for events in self.known.values():
            for e in events:
                if (fold := Fold.of(e.fields)) is not None:
                    self.folds[e.event_id] = fold
        self.folds = {i: f for i, f in self.folds.items() if f.end_s >= clock_s - kept_s}
        changes = []
        named = {m for f in self.folds.values() for m in f.named}
        for mmsi in [m for m in self.known if mmsi_of(m) in named]:
            kept = []
            for e in self.known[mmsi]:
                into = self._folding(e.fields["kind"], mmsi, *e.span_s)
                if into is None:
                    kept.append(e)
                else:
                    changes.append(Change.of("withdrawn", e, into))
            self.known[mmsi] = kept
        return changes

    def _folding(self, kind: str, mmsi: int, start_s: float, end_s: float) -> int | None:
        """The id of a fleet event that explains this one-vessel event (None: none does)."""
        return next(
            (i for i, f in self.folds.items() if f.explains(kind, mmsi, start_s, end_s)), None
        )

    def cover(self, fleet: Fleet, rules: EventRules) -> list[Change]:
        """Each held gap's coverage by detect's own rule (`aisdati.events.fleet.annotated`)
        from the windows of a fleet scan (`fleet`), revised where it tells more: from null to
        heard or quiet, from quiet to heard, never back. The windows drop a gap's neighbours'
        reports as they move on (a later scan may know less of its time than an earlier),
        while those after it (what a quiet gap needs) come in later."""
        gaps = [e for events in self.known.values() for e in events
                if e.fields["kind"] == "gap" and e.fields.get("coverage") != HEARD]  # fmt: skip
        if not gaps:
            return []
        told = annotated(fleet, rules, pd.DataFrame([e.fields for e in gaps]))["coverage"]
        changes = []
        for e, coverage in zip(gaps, told.tolist(), strict=True):
            if not isinstance(coverage, str) or coverage == e.fields.get("coverage"):
                continue
            e.fields = {**e.fields, "coverage": coverage}
            changes.append(Change.of("revised", e))
        return changes

    def open_events(self) -> list[LiveEvent]:
        return [e for events in self.known.values() for e in events if e.state == "open"]


def _changed(e: LiveEvent, row: dict[str, Any], state: str, first_s: float) -> str | None:
    """Update `e` from a judgement's `row`; what changed (None: nothing). A start before the
    window is kept: the window no longer holds the event's beginning; and a gap's coverage."""
    if e.fields["start"].timestamp() < first_s:
        row = {**row, "start": e.fields["start"]}
        row["duration_s"] = (row["end"] - row["start"]).total_seconds()
    if row.get("coverage") is None:  # a fleet scan's, which one vessel's judgement cannot say
        row = {**row, "coverage": e.fields.get("coverage")}
    same = all(_same(e.fields[k], row[k]) for k in COMPARED)
    if same and state == e.state:
        return None
    was, e.fields, e.state = e.state, row, state
    if state == "closed":
        return "closed" if was == "open" else "revised"
    return "extended" if was == "open" else "opened"


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (np.isnan(a) and np.isnan(b))
    return bool(a == b)


def _gap_fields(last: LastReport, silence: float, clock_s: float) -> dict:
    """An open gap's fields: from the vessel's last report, to the feed's time it opened."""
    return event_row(
        last.mmsi, "gap", (last.time_s, clock_s), 1, (last.lon, last.lat),
        ([last.lon], [last.lat]), silence / float(last.limit_s),
        f"silent {silence / 60:.0f} min at sea so far (usually every {last.usual_s:.0f} s)",
    )  # fmt: skip
