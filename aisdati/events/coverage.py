"""Whether a gap's area kept being heard (`aisdati.events.kinds`: a gap's `coverage`): the
other vessels near its two ends, during it, tell a vessel that stopped transmitting from a
receiver that stopped hearing.

Near: within `EventSettings.gap_coverage_m` of the straight line from the last report before
the gap to the first after it (where the vessel likely went). **heard**: another vessel
reported near during the gap (the receiver was hearing: the vessel likely stopped
transmitting); **quiet**: none did, though other vessels reported near before the gap and
after it, within the gap's duration of it (the area went silent: its coverage); null: no
neighbour around to tell."""

from __future__ import annotations

import numpy as np

from aisdati.events.heard import Heard
from aisdati.geo import haversine_m

HEARD, QUIET = "heard", "quiet"


def gap_coverage(
    heard: Heard, mmsi: int, span_s: tuple[float, float], ends: np.ndarray, radius_m: float
) -> str | None:
    """The coverage of vessel `mmsi`'s gap from `span_s[0]` to `span_s[1]` (seconds) between
    `ends` ([2, 2] lon/lat: its last report before, its first after), from the reports of the
    other vessels `heard`."""
    start, end = span_s
    length = end - start
    near = heard.near(start - length, end + length, on_line(ends, radius_m), radius_m)
    near = near[heard.mmsi[near] != mmsi]
    t = heard.time_s[near]
    if ((t > start) & (t < end)).any():
        return HEARD
    return QUIET if (t <= start).any() and (t >= end).any() else None


def on_line(ends: np.ndarray, radius_m: float) -> np.ndarray:
    """[k, 2] lon/lat along the straight line between `ends` ([2, 2]), at most `radius_m`
    apart: within `radius_m` of one of them is within about it of the line."""
    apart = float(haversine_m(*ends[0], *ends[1]))
    steps = int(np.ceil(apart / radius_m)) + 1
    share = np.linspace(0.0, 1.0, max(steps, 2))[:, None]
    return ends[0] + share * (ends[1] - ends[0])
