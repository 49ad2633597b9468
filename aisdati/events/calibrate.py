"""Thresholds of the consistency kinds and of the gap, calibrated on an area's training
tracks: what is unusual for a vessel depends on how the area's traffic reports (its receivers'
coverage holes, how much its courses wander between reports), so a model records each training
track's largest statistic of each kind beside its scores (`ModelCard.calibration`, keys
`event:<kind>`), and detection sets each threshold to their (1 - `EVENT_RATE`) quantile.
Without a model the defaults of `EventSettings` hold."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from aisdati.events.behaviour import gaps
from aisdati.events.motion import course_inconsistent, position_jumps, speed_inconsistent
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found
from aisdati.tracks.ashore import AshoreCheck

EVENT_RATE = 0.01
"""The share of training tracks each calibrated kind would raise an event on."""
KEY = "event:"
Finder = Callable[[VesselReports, EventSettings], list[Found]]
CALIBRATED: dict[str, tuple[str, float, Finder]] = {
    "position-jump": ("jump_z", 5.0, position_jumps),
    "speed-inconsistent": ("speed_limit", 50.0, speed_inconsistent),
    "course-inconsistent": ("course_limit", 50.0, course_inconsistent),
    "gap": ("gap_min_s", 600.0, lambda v, s: gaps(v, s, AshoreCheck())),
}
"""Kind -> (the setting that is its threshold, the lowest it may be calibrated to, its
finder). The floors keep a model of very regular traffic from raising events on noise no
analyst would look at."""


def largest(kind: str, v: VesselReports, s: EventSettings = EventSettings()) -> float:
    """The largest statistic of `kind` on these reports, in the unit of its threshold; 0 where
    none reaches the kind's floor (below it, no threshold is set anyway)."""
    name, floor, finder = CALIBRATED[kind]
    found = finder(v, replace(s, **{name: floor}))
    if kind == "gap":  # its strength is the silence over max(gap_min_s, factor x interval)
        return max((float(v.dt_s[e.start]) for e in found), default=0.0)
    return max((e.strength * floor for e in found), default=0.0)


def calibration(tracks: Sequence[VesselReports], s: EventSettings = EventSettings()) -> dict:
    """What a model's card records: each calibrated kind's largest statistic on each of its
    training tracks (`largest`), under `event:<kind>`."""
    return {KEY + kind: [round(largest(kind, v, s), 6) for v in tracks] for kind in CALIBRATED}


def calibrated(
    recorded: Mapping[str, Sequence[float]], s: EventSettings = EventSettings()
) -> EventSettings:
    """`s` with each threshold the models recorded (`calibration`, pooled over models) set to
    the (1 - `EVENT_RATE`) quantile of its statistics, no lower than its floor; thresholds of
    kinds not recorded keep their defaults."""
    changed = {}
    for kind, (name, floor, _) in CALIBRATED.items():
        values = recorded.get(KEY + kind)
        if values:
            changed[name] = max(floor, float(np.quantile(values, 1.0 - EVENT_RATE)))
    return replace(s, **changed)
