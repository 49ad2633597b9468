"""Events from reports: every model-free finder run over one vessel's reports at its floor,
the alerts kept where they reach their kind's threshold (`aisdati.events.budget.Thresholds`),
each kind's overlapping events merged into one and each bounded (`aisdati.events.kinds`), and
the events placed (times, where, the track, class, rarity) as the rows of events.parquet.

An event is a function of the vessel's reports alone (the hours around it), so the same
reports give the same events alone, in any batch and live."""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from typing import Any

import numpy as np
import pandas as pd

from aisdati.events.behaviour import (
    ashore,
    drift,
    gaps,
    land_mask,
    loitering,
    sudden_speed_change,
)
from aisdati.events.budget import Thresholds
from aisdati.events.kinds import KINDS, READ_REPORTED_MOTION
from aisdati.events.motion import course_inconsistent, position_jumps, speed_inconsistent
from aisdati.events.record import EVENT_COLUMNS, event_row
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found, merged

Finder = Callable[[VesselReports, EventSettings, float, "np.ndarray | None"], list[Found]]
FINDERS: dict[str, Finder] = {
    "position-jump": lambda v, s, length, land: position_jumps(v, s),
    "speed-inconsistent": lambda v, s, length, land: speed_inconsistent(v, s),
    "course-inconsistent": lambda v, s, length, land: course_inconsistent(v, s),
    "drift": lambda v, s, length, land: drift(v, s, length),
    "sudden-speed-change": lambda v, s, length, land: sudden_speed_change(v, s),
    "ashore": lambda v, s, length, land: ashore(v, land),
    "loitering": lambda v, s, length, land: loitering(v, s),
    "gap": lambda v, s, length, land: gaps(v, s, land),
}
"""Each model-free kind's finder: (reports, settings, the vessel's length if known, which of
its reports are ashore: `land_mask`, computed once per vessel) -> its events at the floor."""


def finders(reported_motion: bool = True) -> dict[str, Finder]:
    """The finders to run: all, or where SOG and COG were derived from positions, those that
    do not judge the reported motion (`READ_REPORTED_MOTION`)."""
    return {k: f for k, f in FINDERS.items() if reported_motion or k not in READ_REPORTED_MOTION}


def found_at_floor(
    v: VesselReports,
    settings: EventSettings = EventSettings(),
    length_m: float = np.nan,
    seen: np.ndarray | None = None,
    reported_motion: bool = True,
) -> list[Found]:
    """Every model-free event of one vessel at its kind's floor, each kind's overlaps merged:
    what the alert budget counts on a training period (`aisdati.events.budget`)."""
    found, land = finders(reported_motion).values(), land_mask(v.positions(), seen)
    return [e for find in found for e in merged(find(v, settings, length_m, land))]


def find_events(
    v: VesselReports,
    thresholds: Thresholds = Thresholds(),
    settings: EventSettings = EventSettings(),
    length_m: float = np.nan,
    seen: np.ndarray | None = None,
    reported_motion: bool = True,
    kinds: Collection[str] | None = None,
    land: np.ndarray | None = None,
) -> list[Found]:
    """Every model-free event of one vessel (`aisdati.events.kinds.MODEL_FREE`) that reaches
    its threshold, each kind's overlaps merged, each bounded, in time order; `length_m`: the
    vessel's length if known; `seen`: where its area's training traffic reported ashore
    (`aisdati.tracks.ashore`); `reported_motion`: False where SOG/COG were derived from
    positions; `kinds`: only these are looked for (None: all; the live watch looks only for
    those its screen says may be found); `land`: which reports are ashore when already known
    (`land_mask`, which finds it otherwise). A kept event's strength is over its threshold (1 =
    at it)."""
    out = []
    if land is None:
        land = land_mask(v.positions(), seen)
    for kind, find in finders(reported_motion).items():
        if kinds is not None and kind not in kinds:
            continue
        kept = [thresholds.over(e) for e in find(v, settings, length_m, land)]
        out += [bounded(v, e) for e in merged([e for e in kept if e is not None])]
    return sorted(out, key=lambda e: (e.start, e.kind))


def bounded(v: VesselReports, e: Found) -> Found:
    """`e` cut to its kind's longest (`EventKind.max_s`) around its strongest report."""
    bound = KINDS[e.kind].max_s
    if bound is None or v.time_s[e.end] - v.time_s[e.start] <= bound:
        return e
    t = v.time_s
    start = max(e.start, int(np.searchsorted(t, t[e.peak] - bound / 2)))
    end = int(np.searchsorted(t, t[start] + bound, side="right")) - 1
    return Found(e.kind, start, max(min(end, e.end), e.peak), e.peak, e.strength, e.evidence)


def placed(
    v: VesselReports,
    found: Sequence[Found],
    identity: dict | None = None,
    thresholds: Thresholds = Thresholds(),
) -> pd.DataFrame:
    """The events of one vessel as rows of `EVENT_COLUMNS` (`placed_rows`), as a table."""
    return pd.DataFrame(placed_rows(v, found, identity, thresholds), columns=list(EVENT_COLUMNS))


def placed_rows(
    v: VesselReports,
    found: Sequence[Found],
    identity: dict | None = None,
    thresholds: Thresholds = Thresholds(),
) -> list[dict[str, Any]]:
    """The events of one vessel as records (`aisdati.events.record.event_row`): times, the
    report where each is strongest (its place), the track of that report, its rarity
    (`thresholds`), the stretch's positions, and the vessel's name and type (`identity`: name,
    ship_type) when known. Records, not a table: the live watch places events thousands of
    times a second, and a table costs about as much as finding them."""
    rows = []
    for e in found:
        track = int(v.track_id[e.peak])
        rows.append(
            event_row(
                v.mmsi, e.kind, (v.time_s[e.start], v.time_s[e.end]), e.end - e.start + 1,
                (v.lon[e.peak], v.lat[e.peak]),
                (v.lon[e.start : e.end + 1].tolist(), v.lat[e.start : e.end + 1].tolist()),
                e.strength, e.evidence, identity=identity,
                track_id=track if track >= 0 else None, rarity_days=thresholds.rarity_days(e),
            )
        )  # fmt: skip
    return rows
