"""Reported against observed motion: the events that compare what a vessel's positions do
with what its reports say it does (`aisdati.events.kinds`: position-jump, speed-inconsistent,
course-inconsistent).

Each report's evidence is scaled by the vessel's own report-to-report variation (a robust
spread over its reports), so a 2-second and a 10-minute reporter are judged alike, and an
altered stretch, being a minority of the reports, stands out of the spread it barely moves."""

from __future__ import annotations

import numpy as np

from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found, cusum_stretches
from aisdati.geo import haversine_m, initial_bearing_deg

MAD_TO_SIGMA = 1.4826
CHORD_GPS = 4.0
"""A chord is read for its bearing from this many times the position noise on."""


def position_jumps(v: VesselReports, s: EventSettings) -> list[Found]:
    """Stretches displaced as a whole: a step in whose unexplained displacement (`residual`)
    is a jump, and a later step that jumps back by about the opposite vector."""
    if len(v) < s.jump_min_reports + 2:
        return []
    z = jump_sizes(v, s)
    r = v.residual
    candidates = np.flatnonzero(z > s.jump_z)
    longest = max(s.jump_min_reports, int(s.jump_max_share * len(v)))
    found, used = [], np.zeros(len(z), bool)
    pairs = [
        (min(z[i], z[j]), int(i), int(j))
        for i in candidates
        for j in candidates[(candidates - i >= s.jump_min_reports) & (candidates - i <= longest)]
        if _opposite(r[i], r[j])
    ]
    for strength, i, j in sorted(pairs, reverse=True):
        if used[i] or used[j]:
            continue
        used[i] = used[j] = True
        metres = float(np.hypot(*r[i]))
        found.append(
            Found(
                "position-jump", i + 1, j, i + 1, float(strength / s.jump_z),
                f"moved {metres:,.0f} m off its reported motion for {j - i} reports, and back",
            )
        )  # fmt: skip
    return found


def jump_sizes(v: VesselReports, s: EventSettings) -> np.ndarray:
    """[n - 1] each step's unexplained displacement over its scale: the GPS noise plus the
    vessel's typical unexplained share of the distance it sails in a step."""
    r = np.hypot(*v.residual.T)
    speed = np.hypot(*v.velocity.T)
    sailed = (speed[:-1] + speed[1:]) / 2 * v.dt_s
    share = np.median(np.maximum(r - s.gps_m, 0.0) / (sailed + s.gps_m)) if len(r) else 0.0
    return r / (s.gps_m + MAD_TO_SIGMA * share * sailed)


def _opposite(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether step b undoes step a's jump: their sum well under the smaller."""
    return bool(np.hypot(*(a + b)) <= 0.5 * min(np.hypot(*a), np.hypot(*b)))


def speed_inconsistent(v: VesselReports, s: EventSettings) -> list[Found]:
    """Stretches where the reported speed jumps from report to report (its departure from its
    neighbours' mean) far beyond the vessel's own jumps: what a faulty speed log or a forged
    speed does, at sea or at anchor. (Against the speed the positions show, the departures of
    honest reports a few minutes apart were too wide: AUC 0.94 against 0.99 on Kitimat.)"""
    if len(v) < 5:
        return []
    rough = v.sog[1:-1] - (v.sog[:-2] + v.sog[2:]) / 2
    said = (
        "reported speed jumps {size:.1f} kn (rms) from its neighbours', where this vessel's "
        "jump {scale:.1f}"
    )
    return _noisy("speed-inconsistent", rough, s.sog_floor_kn, said, s.speed_limit, s)


def course_inconsistent(v: VesselReports, s: EventSettings) -> list[Found]:
    """Stretches where the reported course departs from the course the positions show at each
    report (the bearing of the chord from the report before to the report after: the tangent
    of a steady turn) far beyond the vessel's own departures; read where the vessel is under
    way and the chord stands above the position noise. (Its departure from its neighbours'
    mean, as for speed, separated less: AUC 0.75 against 0.89 on Kitimat.)"""
    if len(v) < 5:
        return []
    chord_m = _chords(v)
    bearing = initial_bearing_deg(v.lon[:-2], v.lat[:-2], v.lon[2:], v.lat[2:])
    apart = (v.cog[1:-1] - bearing + 180.0) % 360.0 - 180.0
    read = (v.sog[1:-1] >= s.under_way_kn) & (chord_m >= CHORD_GPS * s.gps_m)
    apart = np.where(read, apart, np.nan)
    said = (
        "reported course {size:.0f} deg (rms) off the course its positions show, where this "
        "vessel's is {scale:.0f} off"
    )
    return _noisy("course-inconsistent", apart, s.cog_floor_deg, said, s.course_limit, s)


def _chords(v: VesselReports) -> np.ndarray:
    """[n - 2] metres from each report's predecessor to its successor."""
    return haversine_m(v.lon[:-2], v.lat[:-2], v.lon[2:], v.lat[2:])


def _noisy(
    kind: str, rough: np.ndarray, floor: float, said: str, limit: float, s: EventSettings
) -> list[Found]:
    """The CUSUM stretches (over `limit`) of squared departures over the vessel's robust
    spread (at least `floor`; NaN: not read); indices of report i + 1 for departure i; `said`:
    the evidence's words, with the stretch's rms departure (`size`) and the spread (`scale`)."""
    ok = np.isfinite(rough)
    spread = MAD_TO_SIGMA * np.median(np.abs(rough[ok] - np.median(rough[ok]))) if ok.any() else 0
    scale = max(float(spread), floor)
    x = np.minimum(np.where(ok, (rough / scale) ** 2, 0.0), s.noise_cap)
    rough = np.where(ok, rough, 0.0)
    out = []
    for a, b, peak in cusum_stretches(x, s.noise_drift, limit):
        size = float(np.sqrt(np.mean(rough[a : b + 1] ** 2)))
        out.append(
            Found(
                kind, a + 1, b + 1, a + 1 + int(np.argmax(x[a : b + 1])), peak / limit,
                said.format(size=size, scale=scale),
            )
        )  # fmt: skip
    return out
