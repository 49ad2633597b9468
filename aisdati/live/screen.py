"""Which vessels of a chunk some model-free kind may find an event in: one pass over all their
reports at once, so that the finders (`aisdati.events.find.FINDERS`, a few hundred
microseconds a vessel) run only where they can find something.

Each kind's screen is a condition its finder needs to find an event at its floor, read
without the costlier parts of its rule (the vessel's own spread only bounded from below, the
pairing of jumps, the length of a drifting vessel): where the screen says no, the finder finds
nothing, so a vessel no screen holds would give no event, and skipping it changes nothing. A
kind without a screen here holds every vessel (a new kind is judged everywhere until it has
one); tests/live/test_screen.py checks on real traffic that every vessel with an event at a
floor is held."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from aisdati.events.behaviour import angle_apart
from aisdati.events.find import finders
from aisdati.events.motion import CHORD_GPS, MAD_TO_SIGMA, unexplained_m
from aisdati.events.reports import VesselReports
from aisdati.events.rules import EventRules
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import cusum_stretches
from aisdati.geo import haversine_m, initial_bearing_deg
from aisdati.tracks.ashore import AshoreCheck


class Shape:
    """Many vessels' reports one after another (`v`, time order within each vessel; vessel
    `k`'s at `bounds[k]:bounds[k + 1]`) and where each vessel begins and ends."""

    def __init__(self, v: VesselReports, bounds: np.ndarray) -> None:
        self.v, self.bounds = v, np.asarray(bounds, np.int64)
        self.sizes = np.diff(self.bounds)
        self.vessels = len(self.sizes)
        self.group = np.repeat(np.arange(self.vessels), self.sizes)
        at = np.arange(len(v))
        self.first = at == self.bounds[:-1][self.group]
        self.last = at == self.bounds[1:][self.group] - 1
        self.same = self.group[:-1] == self.group[1:]
        """[n - 1] whether each step joins two reports of one vessel."""
        self.inner = ~self.first & ~self.last

    def count(self, mask: np.ndarray) -> np.ndarray:
        """[vessels] how many reports of each `mask` holds."""
        return np.bincount(self.group[mask], minlength=self.vessels)

    def count_steps(self, step: np.ndarray) -> np.ndarray:
        """[vessels] how many steps of each `step` holds (steps within one vessel only)."""
        return np.bincount(self.group[:-1][step & self.same], minlength=self.vessels)

    def any_step(self, step: np.ndarray) -> np.ndarray:
        return self.count_steps(step) > 0

    def any_at(self, reports: np.ndarray) -> np.ndarray:
        """[vessels] whether each has one of `reports` (indices)."""
        out = np.zeros(self.vessels, bool)
        out[self.group[reports]] = True
        return out

    def runs(self, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The first and last report of each run of True in `mask` within one vessel."""
        before = np.r_[False, mask[:-1]] & ~self.first
        after = np.r_[mask[1:], False] & ~self.last
        return np.flatnonzero(mask & ~before), np.flatnonzero(mask & ~after)


Screen = Callable[[Shape, EventSettings, "np.ndarray | None"], np.ndarray]


def may_find(
    v: VesselReports, bounds: np.ndarray, land: np.ndarray | None, rules: EventRules
) -> list[list[str]]:
    """For each vessel, the kinds the rules run that may find an event in its reports (`v`:
    many vessels' one after another, vessel `k`'s at `bounds[k]:bounds[k + 1]`; `land`: which
    are ashore, `aisdati.events.behaviour.land_mask`); an empty list: no event."""
    shape = Shape(v, bounds)
    kinds = list(finders(rules.reported_motion))
    held = np.zeros((shape.vessels, len(kinds)), bool)
    for j, kind in enumerate(kinds):
        screen = SCREENS.get(kind)
        held[:, j] = True if screen is None else screen(shape, rules.settings, land)
    out: list[list[str]] = [[] for _ in range(shape.vessels)]
    for k, j in zip(*np.nonzero(held), strict=True):
        out[k].append(kinds[j])
    return out


def _gap(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """A silence longer than the shortest gap (`gap_min_s`, which every vessel's limit is at
    least), after a report under way."""
    v, dt = c.v, c.v.dt_s
    step = c.same & (dt > s.gap_min_s) & (dt <= s.gap_max_s) & (v.sog[:-1] >= s.gap_under_way_kn)
    return c.any_step(step) & (c.sizes >= 3)


def _ashore(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """As many reports ashore as the rule asks."""
    if land is None:
        return np.zeros(c.vessels, bool)
    return c.count(land) >= AshoreCheck().min_reports


def _loitering(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """A slow stretch (by reports and positions) held `loiter_min_s` to `loiter_max_s`, with a
    report before and after it."""
    v = c.v
    implied = np.empty(len(v))
    implied[1:] = v.implied_kn if len(v) > 1 else v.sog[1:]
    first = c.bounds[:-1][c.sizes > 1]
    implied[first] = v.implied_kn[first] if len(v) > 1 else 0.0
    lone = c.bounds[:-1][c.sizes == 1]
    implied[lone] = v.sog[lone]
    slow = (v.sog < s.loiter_kn) & (implied < s.loiter_kn)
    a, b = c.runs(slow)
    held = v.time_s[b] - v.time_s[a]
    ok = ~c.first[a] & ~c.last[b] & (held >= s.loiter_min_s) & (held <= s.loiter_max_s)
    return c.any_at(a[ok])


def _drift(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """Course far from the heading at a drifting speed, held `drift_min_s`."""
    v = c.v
    apart = angle_apart(v.cog, v.heading)
    sideways = (apart > s.drift_angle_deg) & (180.0 - apart > s.drift_angle_deg)
    slow = (v.sog >= s.drift_min_kn) & (v.sog <= s.drift_max_kn)
    a, b = c.runs(sideways & slow & np.isfinite(v.heading))
    return c.any_at(a[v.time_s[b] - v.time_s[a] >= s.drift_min_s])


def _sudden_speed_change(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """A report under `ssc_to_kn` within `ssc_within_s` of an earlier one over `ssc_from_kn`."""
    v = c.v
    fast = np.maximum.accumulate(np.where(v.sog > s.ssc_from_kn, np.arange(len(v)), -1))
    j = np.flatnonzero((v.sog < s.ssc_to_kn) & ~c.first & (fast >= 0))
    k = fast[j]
    ok = (k >= c.bounds[c.group[j]]) & (v.time_s[j] - v.time_s[k] <= s.ssc_within_s)
    return c.any_at(j[ok])


def _position_jump(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """Two steps of a vessel under way, each with `jump_min_m` its reported motion does not
    explain, within `jump_step_max_s`."""
    v = c.v
    if len(v) < 2:
        return np.zeros(c.vessels, bool)
    moving = v.under_way(s.under_way_kn)
    step = (
        c.same
        & (unexplained_m(v, s) >= s.jump_min_m)
        & (v.dt_s <= s.jump_step_max_s)
        & (moving[:-1] | moving[1:])
    )
    return (c.count_steps(step) >= 2) & (c.sizes >= s.jump_min_reports + 2)


def _speed_inconsistent(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """The kind's CUSUM over its limit with each departure scaled by no more than the
    finder's scale (`least_spread`: a lower bound of the vessel's own spread)."""
    v, inner = c.v, c.inner
    i = np.flatnonzero(inner)
    rough = v.sog[i] - (v.sog[i - 1] + v.sog[i + 1]) / 2
    moving = v.under_way(s.under_way_kn)
    read = moving[i - 1] | moving[i] | moving[i + 1]
    return _over(c, i, np.where(read, rough, np.nan), s.sog_floor_kn, s.speed_limit, s)


def _course_inconsistent(c: Shape, s: EventSettings, land: np.ndarray | None) -> np.ndarray:
    """As for speed: the departures from the chord's bearing."""
    v, inner = c.v, c.inner
    i = np.flatnonzero(inner)
    chord = haversine_m(v.lon[i - 1], v.lat[i - 1], v.lon[i + 1], v.lat[i + 1])
    bearing = initial_bearing_deg(v.lon[i - 1], v.lat[i - 1], v.lon[i + 1], v.lat[i + 1])
    apart = (v.cog[i] - bearing + 180.0) % 360.0 - 180.0
    read = v.under_way(s.under_way_kn)[i] & (chord >= CHORD_GPS * s.gps_m)
    return _over(c, i, np.where(read, apart, np.nan), s.cog_floor_deg, s.course_limit, s)


def _over(
    c: Shape, i: np.ndarray, rough: np.ndarray, floor: float, limit: float, s: EventSettings
) -> np.ndarray:
    """Whether the CUSUM of `rough` (at inner reports `i`) over a scale no larger than the
    finder's (`least_spread`, at least `floor`) exceeds `limit` in each vessel of at least five
    reports; it starts again at each vessel's first and last report."""
    x = np.full(len(c.v), -np.inf)
    ok = np.isfinite(rough)
    scale = np.maximum(least_spread(c, i, rough, s.scale_window_s), floor)
    x[i] = np.minimum(np.where(ok, (np.where(ok, rough, 0.0) / scale) ** 2, 0.0), s.noise_cap)
    starts = [a for a, _, _ in cusum_stretches(x, s.noise_drift, limit)]
    return c.any_at(np.array(starts, np.int64)) & (c.sizes >= 5)


def least_spread(c: Shape, i: np.ndarray, rough: np.ndarray, window_s: float) -> np.ndarray:
    """[len(i)] no more than `aisdati.events.motion.local_spread` of `rough` (the vessel's own
    inner reports `i`, NaN not read) at each report: the median of the m values read within
    `window_s` around a report is at least the ceil(m/2)-th smallest the vessel's window reads,
    with m counted a second inside the window's edges (never more than the finder reads)."""
    g = c.group[i]
    t = c.v.time_s[i] - c.v.time_s[c.bounds[:-1]][g]
    span = (t.max(initial=0.0) + window_s) * 2 + 1.0
    key = g * span + t
    ok = np.isfinite(rough)
    read = np.r_[0, np.cumsum(ok)]
    half = window_s / 2 - 1.0
    m = read[np.searchsorted(key, key + half, "right")] - read[np.searchsorted(key, key - half)]
    k = (m + 1) // 2
    order = np.lexsort((np.abs(rough[ok]), g[ok]))
    smallest = np.abs(rough[ok])[order]
    first = np.searchsorted(g[ok][order], g)
    at = np.minimum(first + np.maximum(k - 1, 0), max(len(smallest) - 1, 0))
    least = smallest[at] if len(smallest) else np.zeros(len(i))
    return np.where(k > 0, MAD_TO_SIGMA * least, 0.0)


SCREENS: dict[str, Screen] = {
    "position-jump": _position_jump,
    "speed-inconsistent": _speed_inconsistent,
    "course-inconsistent": _course_inconsistent,
    "drift": _drift,
    "sudden-speed-change": _sudden_speed_change,
    "ashore": _ashore,
    "loitering": _loitering,
    "gap": _gap,
}
"""Each model-free kind's screen (a kind of `aisdati.events.find.FINDERS` missing here holds
every vessel)."""
