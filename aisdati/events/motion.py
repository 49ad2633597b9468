"""Reported against observed motion: the events that compare what a vessel's positions do
with what its reports say it does (`aisdati.events.kinds`: position-jump, speed-inconsistent,
course-inconsistent). Each judges a vessel under way only.

Each report's evidence is scaled by the vessel's own report-to-report variation over the
hours around it (`local_spread`: a robust spread over a centred window of
`EventSettings.scale_window_s`), so a 2-second and a 10-minute reporter are judged alike, an
altered stretch, being a minority of those reports, stands out of the spread it barely moves,
and the event depends on those hours of the vessel's reports only (not on the batch)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from aisdati.events.kinds import KINDS
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found, cusum_stretches
from aisdati.geo import haversine_m, initial_bearing_deg

MAD_TO_SIGMA = 1.4826
CHORD_GPS = 4.0
"""A chord is read for its bearing from this many times the position noise on."""
JUMP_MAX_S = KINDS["position-jump"].max_s or np.inf


def local_spread(time_s: np.ndarray, values: np.ndarray, window_s: float) -> np.ndarray:
    """[n] a robust spread of `values` (centred on zero) over the reports within `window_s`
    around each (centred): 1.4826 x the median absolute value; NaN values are not read, and
    a report with none read around it gets 0."""
    if len(values) == 0:
        return np.zeros(0)
    index = pd.to_datetime(np.round(time_s * 1e6).astype(np.int64), unit="us")
    series = pd.Series(np.abs(values), index=index)
    median = series.rolling(pd.Timedelta(seconds=window_s), center=True, min_periods=1).median()
    return MAD_TO_SIGMA * np.nan_to_num(median.to_numpy(), nan=0.0)


def position_jumps(v: VesselReports, s: EventSettings) -> list[Found]:
    """Stretches displaced as a whole: a step of a vessel under way whose unexplained
    displacement (`residual`) is a jump, and a later step within the kind's bound that jumps
    back by about the opposite vector."""
    if len(v) < s.jump_min_reports + 2:
        return []
    z = jump_sizes(v, s)
    r = v.residual
    metres = unexplained_m(v, s)
    moving = v.under_way(s.under_way_kn)
    candidates = np.flatnonzero(
        (z > s.jump_z)
        & (metres >= s.jump_min_m)
        & (v.dt_s <= s.jump_step_max_s)
        & (moving[:-1] | moving[1:])
    )
    found, used = [], np.zeros(len(z), bool)
    pairs = [
        (min(z[i], z[j]), int(i), int(j))
        for i in candidates
        for j in candidates[
            (candidates - i >= s.jump_min_reports)
            & (v.time_s[candidates] - v.time_s[i + 1] <= JUMP_MAX_S)
        ]
        if _opposite(r[i], r[j])
    ]
    for strength, i, j in sorted(pairs, reverse=True):
        if used[i] or used[j] or used[i:j].any():
            continue
        used[i : j + 1] = True
        found.append(
            Found(
                "position-jump", i + 1, j, i + 1, float(strength / s.jump_z),
                f"moved {metres[i]:,.0f} m off its reported motion for {j - i} reports "
                f"({(v.time_s[j] - v.time_s[i + 1]) / 60:.0f} min), and back",
            )
        )  # fmt: skip
    return found


def unexplained_m(v: VesselReports, s: EventSettings) -> np.ndarray:
    """[n - 1] metres of each step's `residual` that neither the position noise's scale nor a
    clock offset explains: along the course, up to `clock_s` of the vessel's reported speed is
    a report timed by another receiver's clock (a shore station seconds off shifts a fast
    vessel's report along its track, and keeps doing so for as long as it hears it)."""
    r = v.residual
    mean_v = (v.velocity[:-1] + v.velocity[1:]) / 2
    speed = np.hypot(*mean_v.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = np.where(speed[:, None] > 0, mean_v / speed[:, None], 0.0)
    along = np.sum(r * unit, axis=1)
    cross = r - along[:, None] * unit
    return np.hypot(np.hypot(*cross.T), np.maximum(np.abs(along) - speed * s.clock_s, 0.0))


def jump_sizes(v: VesselReports, s: EventSettings) -> np.ndarray:
    """[n - 1] each step's unexplained displacement (`unexplained_m`) over its scale: the GPS
    noise plus the vessel's typical unexplained share of the distance it sails in a step (over
    the hours around it)."""
    r = unexplained_m(v, s)
    speed = np.hypot(*v.velocity.T)
    sailed = (speed[:-1] + speed[1:]) / 2 * v.dt_s
    share = np.maximum(r - s.gps_m, 0.0) / (sailed + s.gps_m)
    typical = local_spread(v.time_s[1:], share, s.scale_window_s) / MAD_TO_SIGMA
    return r / (s.gps_m + MAD_TO_SIGMA * typical * sailed)


def _opposite(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether step b undoes step a's jump: their sum well under the smaller."""
    return bool(np.hypot(*(a + b)) <= 0.5 * min(np.hypot(*a), np.hypot(*b)))


def speed_inconsistent(v: VesselReports, s: EventSettings) -> list[Found]:
    """Stretches where the reported speed jumps from report to report (its departure from its
    neighbours' mean) far beyond the vessel's own jumps: what a faulty speed log or a forged
    speed does; read where the report or a neighbour has the vessel under way. (Against the
    speed the positions show, the departures of honest reports a few minutes apart were too
    wide: AUC 0.94 against 0.99 on Kitimat.)"""
    if len(v) < 5:
        return []
    rough = v.sog[1:-1] - (v.sog[:-2] + v.sog[2:]) / 2
    moving = v.under_way(s.under_way_kn)
    read = moving[:-2] | moving[1:-1] | moving[2:]
    said = (
        "reported speed jumps {size:.1f} kn (rms) from its neighbours', where this vessel's "
        "jump {scale:.1f}"
    )
    rough = np.where(read, rough, np.nan)
    return _noisy("speed-inconsistent", v, rough, s.sog_floor_kn, said, s.speed_limit, s)


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
    read = v.under_way(s.under_way_kn)[1:-1] & (chord_m >= CHORD_GPS * s.gps_m)
    apart = np.where(read, apart, np.nan)
    said = (
        "reported course {size:.0f} deg (rms) off the course its positions show, where this "
        "vessel's is {scale:.0f} off"
    )
    return _noisy("course-inconsistent", v, apart, s.cog_floor_deg, said, s.course_limit, s)


def _chords(v: VesselReports) -> np.ndarray:
    """[n - 2] metres from each report's predecessor to its successor."""
    return haversine_m(v.lon[:-2], v.lat[:-2], v.lon[2:], v.lat[2:])


def _noisy(
    kind: str,
    v: VesselReports,
    rough: np.ndarray,
    floor: float,
    said: str,
    limit: float,
    s: EventSettings,
) -> list[Found]:
    """The CUSUM stretches (over `limit`) of squared departures of reports 1..n-2 over the
    vessel's local robust spread (at least `floor`; NaN: not read, which lets the CUSUM fall);
    `said`: the evidence's words, with the stretch's rms departure (`size`) and its median
    spread (`scale`)."""
    ok = np.isfinite(rough)
    scale = np.maximum(local_spread(v.time_s[1:-1], rough, s.scale_window_s), floor)
    x = np.minimum(np.where(ok, (rough / scale) ** 2, 0.0), s.noise_cap)
    rough = np.where(ok, rough, 0.0)
    out = []
    for a, b, peak in cusum_stretches(x, s.noise_drift, limit):
        size = float(np.sqrt(np.mean(rough[a : b + 1] ** 2)))
        out.append(
            Found(
                kind, a + 1, b + 1, a + 1 + int(np.argmax(x[a : b + 1])), peak / limit,
                said.format(size=size, scale=float(np.median(scale[a : b + 1]))),
            )
        )  # fmt: skip
    return out
