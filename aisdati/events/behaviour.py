"""What a vessel does, from its reports alone (`aisdati.events.kinds`): drift, sudden speed
change, loitering, a gap at sea and reports ashore."""

from __future__ import annotations

import numpy as np

from aisdati.events.reports import AT_ANCHOR, MOORED, VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found, runs
from aisdati.tracks.ashore import AshoreCheck


def angle_apart(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest angle between two bearings, degrees in [0, 180]."""
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


def drift(v: VesselReports, s: EventSettings, length_m: float = np.nan) -> list[Found]:
    """Course far from the heading and from its reverse at a drifting speed, held long."""
    if length_m < s.drift_min_length_m:  # NaN (unknown) compares False: judged
        return []
    apart = angle_apart(v.cog, v.heading)
    sideways = (apart > s.drift_angle_deg) & (180.0 - apart > s.drift_angle_deg)
    slow = (v.sog >= s.drift_min_kn) & (v.sog <= s.drift_max_kn)
    out = []
    for a, b in runs(sideways & slow & np.isfinite(v.heading)):
        held = v.time_s[b] - v.time_s[a]
        if held >= s.drift_min_s:
            out.append(
                Found(
                    "drift", a, b, a, held / s.drift_min_s,
                    f"course {np.median(apart[a:b + 1]):.0f} deg off heading at "
                    f"{np.median(v.sog[a:b + 1]):.1f} kn for {held / 60:.0f} min",
                )
            )  # fmt: skip
    return out


def sudden_speed_change(v: VesselReports, s: EventSettings) -> list[Found]:
    """A fall from over `ssc_from_kn` to under `ssc_to_kn` within `ssc_within_s`, the low speed
    held for `ssc_hold_s`: from the last fast report to the report that completes the hold."""
    out = []
    for a, b in runs(v.sog < s.ssc_to_kn):
        if a == 0 or v.time_s[b] - v.time_s[a] < s.ssc_hold_s:
            continue
        before = np.flatnonzero(
            (v.sog[:a] > s.ssc_from_kn) & (v.time_s[a] - v.time_s[:a] <= s.ssc_within_s)
        )
        if before.size:
            k = int(before[-1])
            held = a + int(np.searchsorted(v.time_s[a : b + 1], v.time_s[a] + s.ssc_hold_s))
            out.append(
                Found(
                    "sudden-speed-change", k, min(held, b), a, v.sog[k] / s.ssc_from_kn,
                    f"{v.sog[k]:.1f} kn to {v.sog[a]:.1f} kn in {v.time_s[a] - v.time_s[k]:.0f} s",
                )
            )  # fmt: skip
    return out


def loitering(v: VesselReports, s: EventSettings) -> list[Found]:
    """Slow by its reports and its positions for `loiter_min_s`, with the vessel under way
    before and after, not saying it is at anchor or moored."""
    implied = np.concatenate([v.implied_kn[:1], v.implied_kn]) if len(v) > 1 else v.sog
    slow = (v.sog < s.loiter_kn) & (implied < s.loiter_kn)
    out = []
    for a, b in runs(slow):
        held = v.time_s[b] - v.time_s[a]
        parked = np.isin(v.status[a : b + 1], (AT_ANCHOR, MOORED)).mean() > 0.5
        if a == 0 or b == len(v) - 1 or not s.loiter_min_s <= held <= s.loiter_max_s or parked:
            continue
        out.append(
            Found(
                "loitering", a, b, (a + b) // 2, held / s.loiter_min_s,
                f"under {s.loiter_kn:g} kn for {held / 3600:.1f} h between stretches under way",
            )
        )  # fmt: skip
    return out


def land_mask(positions: np.ndarray, seen: np.ndarray | None) -> np.ndarray | None:
    """[n] which of a vessel's reports ([n, 2] lon/lat) are ashore (`aisdati.tracks.ashore`:
    on land by the coastline and its margin, where the area's training traffic never reported,
    `seen`): the one land check of a vessel's reports, which the gap and ashore kinds (and the
    live watch's silences, on the last report) read; None where the coastline is too coarse."""
    check = AshoreCheck()
    return check.reports(positions, seen) if check.available() else None


def gaps(v: VesselReports, s: EventSettings, land: np.ndarray | None) -> list[Found]:
    """Silences far longer than the vessel's usual interval, after reporting under way, with
    both ends on water (`land`: `land_mask`; a vessel in port or leaving the coverage is not
    going dark at sea)."""
    if len(v) < 3:
        return []
    usual = float(np.median(v.dt_s))
    limit = gap_limit(v, s)
    steps = np.flatnonzero(
        (v.dt_s > limit) & (v.dt_s <= s.gap_max_s) & (v.sog[:-1] >= s.gap_under_way_kn)
    )
    if steps.size == 0:
        return []
    on_land = np.zeros(len(steps), bool) if land is None else land[steps] | land[steps + 1]
    return [
        Found(
            "gap",
            int(k),
            int(k) + 1,
            int(k),
            float(v.dt_s[k] / limit),
            f"silent {v.dt_s[k] / 60:.0f} min at sea (usually every {usual:.0f} s)",
        )
        for k, land in zip(steps, on_land, strict=True)
        if not land
    ]


def gap_limit(v: VesselReports, s: EventSettings) -> float:
    """How long a vessel may be silent before it is a gap: at least `gap_min_s` and
    `gap_factor` times its usual (median) interval. One rule for the batch's gaps between
    reports and the live watch's silence that has not ended yet."""
    return float(silence_limit(float(np.median(v.dt_s)), s))


def silence_limit(usual_s: np.ndarray | float, s: EventSettings) -> np.ndarray:
    """`gap_limit` from a vessel's usual (median) interval, for many vessels at once (the live
    watch's vessels of one chunk)."""
    return np.maximum(s.gap_min_s, s.gap_factor * np.asarray(usual_s, np.float64))


def ashore(v: VesselReports, land: np.ndarray | None) -> list[Found]:
    """Each run of reports ashore (`land`: `land_mask`), when the vessel has at least the rule's
    number of them."""
    check = AshoreCheck()
    if land is None or land.sum() < check.min_reports:
        return []
    return [
        Found(
            "ashore",
            a,
            b,
            a,
            float(land.sum() / check.min_reports),
            f"{b - a + 1} report(s) {check.margin_m:g} m or more inland",
        )
        for a, b in runs(land)
    ]
