"""Events across vessels (`aisdati.events.kinds.FLEET`): what no vessel's reports show alone.

A fleet finder reads the reports of every vessel judged together (`Fleet`) and returns its
events as records of `aisdati.events.record.EVENT_COLUMNS`, each naming its other vessels in
`others`. `fleet_events` runs them all after the one-vessel kinds and folds into each fleet
event the one-vessel events it explains (`EventKind.folds`): a jammed area is one event, not
a position jump per vessel. detect, evaluate and watch all call it, so the same reports give
the same fleet events in each. To add a kind: its line in `aisdati.events.kinds` (fleet=True),
its finder in `FLEET_FINDERS`."""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import pandas as pd

from aisdati.events.anchorages import Anchorages, learn
from aisdati.events.coverage import gap_coverage
from aisdati.events.encounters import encounters
from aisdati.events.heard import Heard
from aisdati.events.identity import find_changes, find_conflicts
from aisdati.events.interference import gnss_interference
from aisdati.events.kinds import KINDS
from aisdati.events.port_visits import port_visits
from aisdati.events.record import EVENT_COLUMNS
from aisdati.events.reports import VesselReports, concatenated, heard_as_one
from aisdati.events.rules import EventRules
from aisdati.tracks.schema import mmsi_of


@dataclass(frozen=True)
class Fleet:
    """The vessels judged together: each one's reports (cleaned, as the one-vessel finders read
    them), identity (vessels.parquet's row as a dict: name, ship_type, length_m, ...) and the
    history of the identities each reported (identities.parquet's rows, `aisdati.tracks.schema.
    IDENTITY_SCHEMA`; None where unknown)."""

    vessels: dict[int, VesselReports]
    identity: dict[int, dict[str, Any]] = field(default_factory=dict)
    history: pd.DataFrame | None = None

    def who(self, mmsi: int) -> dict[str, Any]:
        """The vessel's identity as an event names it (mmsi, name, ship_type)."""
        known = self.identity.get(mmsi, {})
        return {"mmsi": int(mmsi), "name": known.get("name"), "ship_type": known.get("ship_type")}

    def anchorages(self, rules: EventRules) -> Anchorages:
        """Where the fleet's vessels are not at sea: the rules' ports, or where none are given,
        the anchorages of the fleet's own stopped reports (`aisdati.events.anchorages.learn`)."""
        if rules.ports is not None:
            return rules.ports
        s, every = rules.settings, self.joined
        stopped = every.reports.sog < s.stopped_kn
        mmsi = every.mmsi[every.vessel][stopped]
        return learn(mmsi, every.reports.lon[stopped], every.reports.lat[stopped], s)

    @cached_property
    def joined(self) -> Joined:
        """Every vessel's reports in one set of arrays (made once, when first asked)."""
        vs = list(self.vessels.values())
        reports = concatenated(vs, -1)
        bounds = np.r_[0, np.cumsum([len(v) for v in vs], dtype=np.int64)]
        return Joined(reports, bounds, np.array([v.mmsi for v in vs], np.int64))

    @cached_property
    def as_heard(self) -> Fleet:
        """The fleet as a receiver heard it: each MMSI's two transmitters one vessel again
        (`aisdati.events.reports.heard_as_one`); itself where no MMSI was split."""
        by_mmsi: dict[int, list[VesselReports]] = {}
        for vessel, reports in self.vessels.items():
            by_mmsi.setdefault(mmsi_of(vessel), []).append(reports)
        if len(by_mmsi) == len(self.vessels):
            return self
        vessels = {mmsi: heard_as_one(parts, mmsi) for mmsi, parts in by_mmsi.items()}
        return replace(self, vessels=vessels)

    @cached_property
    def heard(self) -> Heard:
        """Every vessel's reports in time order (made once, when first asked: the fleet is
        complete by then)."""
        return Heard.of(self.vessels.values())


@dataclass(frozen=True)
class Joined:
    """The fleet's reports in one `VesselReports`, vessel after vessel in the fleet's order
    (vessel k, MMSI `mmsi[k]`: `bounds[k]:bounds[k + 1]`): what a finder computes of every
    report or step at once, to look one by one only at the vessels that may give an event
    (10,000 vessels one by one cost seconds). A step from one vessel's last report to the
    next one's first means nothing: `any_step` leaves it out."""

    reports: VesselReports
    bounds: np.ndarray
    mmsi: np.ndarray

    @cached_property
    def vessel(self) -> np.ndarray:
        """[n] the vessel (its index) each report is of."""
        return np.repeat(np.arange(len(self.mmsi)), np.diff(self.bounds))

    def any_step(self, steps: np.ndarray) -> np.ndarray:
        """[vessels] whether some step of each vessel is True in `steps` ([n - 1])."""
        vessel = self.vessel
        own = steps & (vessel[:-1] == vessel[1:])
        return np.bincount(vessel[:-1][own], minlength=len(self.mmsi)) > 0

    def any_report(self, reports: np.ndarray) -> np.ndarray:
        """[vessels] whether some report of each vessel is True in `reports` ([n])."""
        return np.bincount(self.vessel[reports], minlength=len(self.mmsi)) > 0


FleetFinder = Callable[[Fleet, EventRules], list[dict[str, Any]]]
FLEET_FINDERS: dict[str, FleetFinder] = {
    "encounter": encounters,
    "port-visit": port_visits,
    "identity-conflict": find_conflicts,
    "identity-change": find_changes,
    "gnss-interference": gnss_interference,
}
"""Each fleet kind's finder: (the fleet, the rules) -> its events, records of EVENT_COLUMNS."""


def fleet_events(
    fleet: Fleet, rules: EventRules, own: pd.DataFrame, kinds: Collection[str] | None = None
) -> pd.DataFrame:
    """`own` (the one-vessel events of the fleet's vessels) with what the fleet says of them
    (`annotated`), every fleet kind's events (`kinds`: only those) added and the one-vessel
    events they fold removed."""
    own = annotated(fleet, rules, own)
    if rules.ports is None:  # learned once for every finder that asks (`Fleet.anchorages`)
        rules = replace(rules, ports=fleet.anchorages(rules))
    finders = [f for k, f in FLEET_FINDERS.items() if kinds is None or k in kinds]
    found = [row for find in finders for row in find(fleet, rules)]
    if not found:
        return own
    fleet_rows = pd.DataFrame(found, columns=list(EVENT_COLUMNS))
    return folded(pd.concat([own, fleet_rows], ignore_index=True), fleet_rows)


def annotated(fleet: Fleet, rules: EventRules, own: pd.DataFrame) -> pd.DataFrame:
    """The one-vessel events with what only the other vessels can say of them: the one place
    for such annotations. Today each gap's `coverage` (`aisdati.events.coverage`: whether
    others near it kept being heard during it)."""
    gaps = np.flatnonzero((own["kind"] == "gap").to_numpy()) if len(own) else []
    if not len(gaps):
        return own
    out = own.copy()
    start, end = _seconds(own["start"]), _seconds(own["end"])
    radius = rules.settings.gap_coverage_m
    column = out.columns.get_loc("coverage")
    for i in gaps:
        e = own.iloc[i]
        ends = np.column_stack([e["lons"], e["lats"]])[[0, -1]]
        out.iloc[i, column] = gap_coverage(
            fleet.heard, int(e["mmsi"]), (start[i], end[i]), ends, radius
        )
    return out


@dataclass(frozen=True)
class Fold:
    """What one fleet event explains (`EventKind.folds`): the events of `kinds`, of a vessel it
    names (either transmitter of its MMSI), overlapping its time span (seconds). detect drops
    them (`folded`); the watch withdraws them (`aisdati.live.ledger.Ledger.withdraw`)."""

    kinds: tuple[str, ...]
    named: frozenset[int]
    start_s: float
    end_s: float

    @classmethod
    def of(cls, event: Mapping[str, Any]) -> Fold | None:
        """The fold of a fleet event (a record of EVENT_COLUMNS); None: its kind folds none."""
        kinds = KINDS[event["kind"]].folds
        if not kinds:
            return None
        start, end = pd.Timestamp(event["start"]), pd.Timestamp(event["end"])
        return cls(kinds, frozenset(named(event)), start.timestamp(), end.timestamp())

    def explains(self, kind: str, mmsi: int, start_s: float, end_s: float) -> bool:
        return (
            kind in self.kinds
            and mmsi_of(mmsi) in self.named
            and start_s <= self.end_s
            and end_s >= self.start_s
        )


def named(event: Mapping[str, Any]) -> set[int]:
    """The vessels an event names: its own and its others' (`others`: JSON; null: NaN or
    None)."""
    others = json.loads(event["others"]) if isinstance(event["others"], str) else []
    return {int(event["mmsi"])} | {int(o["mmsi"]) for o in others}


def folded(own: pd.DataFrame, fleet_rows: pd.DataFrame) -> pd.DataFrame:
    """`own` less the events a fleet event explains (`Fold`; a fleet event among them too, as
    an interference explains the identity conflict its displaced reports look like)."""
    if not len(own):
        return own
    drop = pd.Series(False, index=own.index)
    start, end = _seconds(own["start"]), _seconds(own["end"])
    for row in fleet_rows.to_dict("records"):
        if (fold := Fold.of(row)) is None:
            continue
        drop |= (
            own["kind"].isin(fold.kinds)
            & own["mmsi"].map(mmsi_of).isin(fold.named)
            & (start <= fold.end_s)
            & (end >= fold.start_s)
        )
    return own[~drop]


def _seconds(times: pd.Series) -> np.ndarray:
    """Times as seconds since the epoch."""
    return (
        (pd.to_datetime(times, utc=True) - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy()
    )
