"""Anomalies written into real tracks, one small function per kind, for measuring detection.

No public AIS anomaly labels exist, so detection is measured as trajectory-anomaly papers do
(GM-VSAE, MST-OATD): real held-out tracks are altered in documented ways and the detectors must
rank the altered ones above the untouched ones. Each kind takes the track's positions (lon, lat
degrees), report times (seconds from its start) and reported motion (SOG kn, COG deg, heading
deg, NaN where not available), a random generator and its parameters, and returns the new
positions, times and reported motion, the index range [start, end) of the altered stretch in
the new track and, for each new report, the source report its other fields come from. Ranges
`(lo, hi)` are drawn uniformly. Distances are metres on the sphere.

What a vessel reports is altered as its kind says, never re-derived from positions: detect
reads the reported motion, and untouched tracks keep theirs, so derived values would tell the
altered tracks apart by their smoothness alone.

- detour: a smooth lateral bump, amplitude * sin²(πu), over a contiguous stretch (the "shifted
  segment" of GM-VSAE / MST-OATD, in metres); span 0.2-0.35 of the track, km 2-5. The vessel
  sails it: reported motion follows the new path (`_follow`).
- jump: a contiguous stretch displaced by one vector, as a spoofed position; span 0.1-0.2,
  km 3-6; reported motion unchanged.
- shift: as jump, smaller and shorter: span 0.05-0.2, km 1-2.
- loiter: circles inserted mid-track (30-70 % along), sailed at the track's median step length
  and report interval; radius_km 0.5-1.5, loops 1-2; reported motion follows the circles.
- speed: a stretch sailed at another speed (its report intervals divided by the factor,
  positions unchanged, reported SOG times the factor); span 0.2-0.35, slow 0.3 or fast 2-3.
- gap: the reports of a stretch removed; span 0.2-0.4; its range the two reports around the
  hole.
- noise: GM-VSAE's random-point perturbation, a share of the reports each moved in a random
  direction; fraction 0.2, km 0.5-1; reported motion unchanged.
- course-noise: Gaussian noise on the reported COG over a stretch; span 0.05-0.2, sigma_deg
  10-20; positions unchanged (a faulty compass or GNSS course).
- speed-noise: the same on the reported SOG, clipped at 0; span 0.05-0.2, sigma_kn 2-5.
- drift: a stretch re-timed so the vessel sails its positions at 1-5 kn (knots) for at least
  `DRIFT_MIN_S`, reporting that SOG, its course as COG and a heading 60-120 degrees off it
  (heading_deg); span 0.1-0.2.

A position-only score (DTW to rollouts or to the nearest track) cannot see `speed`, `gap` or
the reported-motion kinds by design; `aisdati evaluate` still reports them, with the events.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aisdati.errors import UserError
from aisdati.geo import courses_deg, initial_bearing_deg, legs_m, moved_m
from aisdati.options import parse_names
from aisdati.tracks.schema import KNOT_MPS

Range = tuple[float, float]
DEFAULTS: dict[str, dict[str, Range]] = {
    "detour": {"span": (0.2, 0.35), "km": (2.0, 5.0)},
    "jump": {"span": (0.1, 0.2), "km": (3.0, 6.0)},
    "shift": {"span": (0.05, 0.2), "km": (1.0, 2.0)},
    "loiter": {"radius_km": (0.5, 1.5), "loops": (1.0, 2.0)},
    "speed": {"span": (0.2, 0.35), "slow": (0.3, 0.3), "fast": (2.0, 3.0)},
    "gap": {"span": (0.2, 0.4)},
    "noise": {"fraction": (0.2, 0.2), "km": (0.5, 1.0)},
    "course-noise": {"span": (0.05, 0.2), "sigma_deg": (10.0, 20.0)},
    "speed-noise": {"span": (0.05, 0.2), "sigma_kn": (2.0, 5.0)},
    "drift": {"span": (0.1, 0.2), "knots": (1.0, 5.0), "heading_deg": (60.0, 120.0)},
}
LIMITS: dict[str, Range] = {
    "span": (0.01, 0.9),
    "km": (0.0, 1000.0),
    "radius_km": (0.01, 100.0),
    "loops": (0.1, 20.0),
    "slow": (0.01, 1.0),
    "fast": (1.0, 100.0),
    "fraction": (0.0, 1.0),
    "sigma_deg": (0.0, 180.0),
    "sigma_kn": (0.0, 50.0),
    "knots": (0.1, 30.0),
    "heading_deg": (0.0, 180.0),
}
"""The allowed interval of each parameter."""
SCALED = ("km", "radius_km", "sigma_deg", "sigma_kn")
"""The parameters an anomaly's strength multiplies (`with_strength`): how far it strays."""
MIN_POINTS = 10
"""A track needs this many reports to take an anomaly."""
DRIFT_MIN_S = 660.0
"""A drift lasts at least this long (AisAbnormal's 10 minutes, and a margin)."""
STILL_MPS = 0.05
"""Below this speed a report's path has no speed to scale (`_follow`)."""


@dataclass
class Injected:
    positions: np.ndarray
    times_s: np.ndarray
    motion: np.ndarray
    """[n, 3] reported SOG (kn), COG (deg), heading (deg, NaN where not available)."""
    stretch: tuple[int, int]
    """[start, end) indices of the altered reports in the new track."""
    rows: np.ndarray
    """[n] the source report each new report takes its other fields from (status, ...)."""


def with_strength(params: dict, strength: float) -> dict:
    """`params` (KIND -> NAME -> range overrides) with every distance range (`SCALED`) of every
    kind multiplied by `strength`: 0.3 writes anomalies at 0.3x their usual size (the subtle
    tier)."""
    if not 0.0 < strength <= 10.0:
        raise UserError(f"--strength must be in (0, 10], got {strength:g}")
    out = {kind: dict(values) for kind, values in params.items()}
    for kind, defaults in DEFAULTS.items():
        for name in SCALED:
            if name in defaults:
                lo, hi = out.get(kind, {}).get(name, defaults[name])
                out.setdefault(kind, {})[name] = (lo * strength, hi * strength)
    return out


def derived_motion(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """[n, 3] the motion positions imply, for a track without reported motion: SOG and COG of
    each report towards the next (the last repeats the one before), no heading."""
    dt = np.maximum(np.diff(t), 1e-3)
    sog = np.r_[legs_m(p) / dt / KNOT_MPS, 0.0]
    cog = np.r_[initial_bearing_deg(p[:-1, 0], p[:-1, 1], p[1:, 0], p[1:, 1]), 0.0]
    sog[-1], cog[-1] = sog[-2], cog[-2]
    return np.column_stack([sog, cog % 360.0, np.full(len(p), np.nan)])


def _draw(rng: np.random.Generator, r: Range) -> float:
    return float(rng.uniform(r[0], r[1])) if r[1] > r[0] else float(r[0])


def _stretch(rng: np.random.Generator, n: int, span: Range) -> tuple[int, int]:
    """A contiguous index range covering a drawn fraction of the track, never its endpoints."""
    k = min(max(2, round(_draw(rng, span) * n)), n - 2)
    start = int(rng.integers(1, n - k))
    return start, start + k


def _move(positions: np.ndarray, bearing_deg: np.ndarray, metres: np.ndarray) -> np.ndarray:
    """Points moved `metres` along `bearing_deg` (local flat-Earth step, fine at these scales)."""
    return np.column_stack(moved_m(positions[:, 0], positions[:, 1], bearing_deg, metres))


SPEED_REPORTS = 3
"""Reports either side over which a path's local speed is measured: its length along the path
over the time, so that the ratio of two paths' speeds carries no position noise of one step
(over one step, the ratio of two noisy speeds made a detour's reported speeds jump)."""


def _local(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each report's path bearing (deg) and speed (m/s) along the path over `SPEED_REPORTS`
    reports either side."""
    k = np.arange(len(p))
    prv = np.maximum(k - SPEED_REPORTS, 0)
    nxt = np.minimum(k + SPEED_REPORTS, len(p) - 1)
    along = np.r_[0.0, np.cumsum(legs_m(p))] if len(p) > 1 else np.zeros(len(p))
    return courses_deg(p), (along[nxt] - along[prv]) / np.maximum(t[nxt] - t[prv], 1e-3)


def _follow(p, t, m, new_p, new_t, rows) -> np.ndarray:
    """The reported motion of a vessel that really sails the new path: each new report's source
    values (`rows`), COG and heading turned by the change of the local path's bearing, SOG
    scaled by the change of its speed, so the reports keep their own report-to-report noise."""
    old_course, old_speed = _local(p, t)
    new_course, new_speed = _local(new_p, new_t)
    turn = new_course - old_course[rows]
    src, before = m[rows], old_speed[rows]
    ratio = new_speed / np.maximum(before, STILL_MPS)
    sog = np.where(before > STILL_MPS, src[:, 0] * ratio, new_speed / KNOT_MPS)
    return np.column_stack([sog, (src[:, 1] + turn) % 360.0, (src[:, 2] + turn) % 360.0])


def _same(p, t, m, stretch: tuple[int, int], new_p=None, new_t=None) -> Injected:
    """An anomaly that keeps every report's reported motion and count."""
    n = len(p)
    return Injected(
        p.copy() if new_p is None else new_p,
        t.copy() if new_t is None else new_t,
        m.copy(),
        stretch,
        np.arange(n),
    )


def detour(p, t, m, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    u = (np.arange(i, j) - i + 1) / (j - i + 1)
    side = 90.0 if rng.random() < 0.5 else -90.0
    amp = _draw(rng, prm["km"]) * 1000.0
    out = p.copy()
    out[i:j] = _move(p[i:j], courses_deg(p)[i:j] + side, amp * np.sin(np.pi * u) ** 2)
    rows = np.arange(len(p))
    return Injected(out, t.copy(), _follow(p, t, m, out, t, rows), (i, j), rows)


def jump(p, t, m, rng, prm) -> Injected:
    """Also `shift`: a stretch displaced by one vector, its reports saying what they said."""
    i, j = _stretch(rng, len(p), prm["span"])
    out = p.copy()
    dist = np.full(j - i, _draw(rng, prm["km"]) * 1000.0)
    out[i:j] = _move(p[i:j], np.full(j - i, rng.uniform(0, 360)), dist)
    return _same(p, t, m, (i, j), new_p=out)


def loiter(p, t, m, rng, prm) -> Injected:
    n = len(p)
    at = int(rng.integers(int(0.3 * n), int(0.7 * n)))
    radius = _draw(rng, prm["radius_km"]) * 1000.0
    loops = _draw(rng, prm["loops"])
    step_m = float(np.median(legs_m(p)))
    dt = float(np.median(np.diff(t)))
    k = max(8, round(2 * np.pi * radius * loops / max(step_m, 1.0)))
    start_bearing = courses_deg(p)[at] - 90.0
    centre = _move(p[at : at + 1], np.array([start_bearing + 180.0]), np.array([radius]))
    angles = start_bearing + 360.0 * loops * np.arange(1, k + 1) / k
    ring = _move(np.repeat(centre, k, axis=0), angles, np.full(k, radius))
    pos = np.vstack([p[: at + 1], ring, p[at + 1 :]])
    times = np.r_[t[: at + 1], t[at] + dt * np.arange(1, k + 1), t[at + 1 :] + dt * k]
    rows = np.r_[np.arange(at + 1), np.full(k, at), np.arange(at + 1, n)]
    return Injected(pos, times, _follow(p, t, m, pos, times, rows), (at + 1, at + 1 + k), rows)


def speed(p, t, m, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    factor = _draw(rng, prm["slow"] if rng.random() < 0.5 else prm["fast"])
    dt = np.diff(t)
    dt[i - 1 : j - 1] = dt[i - 1 : j - 1] / factor
    got = _same(p, t, m, (i, j), new_t=np.r_[0.0, np.cumsum(dt)] + t[0])
    got.motion[i:j, 0] *= factor
    return got


def gap(p, t, m, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    keep = np.r_[np.arange(i), np.arange(j, len(p))]
    return Injected(p[keep], t[keep], m[keep], (i - 1, i + 1), keep)


def noise(p, t, m, rng, prm) -> Injected:
    n = len(p)
    k = max(1, round(_draw(rng, prm["fraction"]) * (n - 2)))
    idx = np.sort(rng.choice(np.arange(1, n - 1), size=min(k, n - 2), replace=False))
    out = p.copy()
    dist = np.array([_draw(rng, prm["km"]) for _ in idx]) * 1000.0
    out[idx] = _move(p[idx], rng.uniform(0, 360, len(idx)), dist)
    return _same(p, t, m, (int(idx[0]), int(idx[-1]) + 1), new_p=out)


def course_noise(p, t, m, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    got = _same(p, t, m, (i, j))
    sigma = _draw(rng, prm["sigma_deg"])
    got.motion[i:j, 1] = (m[i:j, 1] + rng.normal(0.0, sigma, j - i)) % 360.0
    return got


def speed_noise(p, t, m, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    got = _same(p, t, m, (i, j))
    sigma = _draw(rng, prm["sigma_kn"])
    got.motion[i:j, 0] = np.maximum(m[i:j, 0] + rng.normal(0.0, sigma, j - i), 0.0)
    return got


def drift(p, t, m, rng, prm) -> Injected:
    """Reports [i, j) re-timed to sail their positions at the drawn speed, for at least
    `DRIFT_MIN_S` (slower where the stretch is too short to last that long), reporting that
    speed, the path's course and a heading turned 60-120 degrees off it."""
    i, j = _stretch(rng, len(p), prm["span"])
    legs = legs_m(p)[i : j - 1]
    metres = float(legs.sum())
    lasts = max(metres / (_draw(rng, prm["knots"]) * KNOT_MPS), DRIFT_MIN_S)
    dt = np.diff(t)
    share = legs / metres if metres > 0 else np.full(len(legs), 1.0 / len(legs))
    dt[i : j - 1] = lasts * share
    got = _same(p, t, m, (i, j), new_t=np.r_[0.0, np.cumsum(dt)] + t[0])
    cog = courses_deg(p)[i:j] % 360.0
    off = _draw(rng, prm["heading_deg"]) * (1.0 if rng.random() < 0.5 else -1.0)
    got.motion[i:j] = np.column_stack(
        [np.full(j - i, metres / lasts / KNOT_MPS), cog, (cog + off) % 360.0]
    )
    return got


KINDS: dict[str, Callable[..., Injected]] = {
    "detour": detour,
    "jump": jump,
    "shift": jump,  # the same displacement, smaller and shorter (DEFAULTS)
    "loiter": loiter,
    "speed": speed,
    "gap": gap,
    "noise": noise,
    "course-noise": course_noise,
    "speed-noise": speed_noise,
    "drift": drift,
}


def parse_kinds(text: str) -> tuple[str, ...]:
    return parse_names(text, KINDS, "anomaly kind")


def parse_params(items: list[str] | None) -> dict[str, dict[str, Range]]:
    """`["detour.km=1-3", "jump.km=4"]` over the defaults; each value checked against LIMITS."""
    params = {k: dict(v) for k, v in DEFAULTS.items()}
    for item in items or []:
        key, sep, value = item.partition("=")
        kind, dot, name = key.strip().lower().partition(".")
        if not sep or not dot or kind not in params or name not in params[kind]:
            known = ", ".join(f"{k}.{n}" for k, v in DEFAULTS.items() for n in v)
            raise UserError(f"--param {item!r}: expected KIND.NAME=LO-HI, one of {known}")
        lo_s, _, hi_s = value.strip().partition("-")
        try:
            lo = float(lo_s)
            hi = float(hi_s) if hi_s else lo
        except ValueError:
            raise UserError(f"--param {item!r}: {value!r} is not a number or range") from None
        lim = LIMITS[name]
        if not (np.isfinite(lo) and np.isfinite(hi) and lim[0] <= lo <= hi <= lim[1]):
            raise UserError(
                f"--param {item!r}: needs {lim[0]:g} <= low <= high <= {lim[1]:g}, got {value}"
            )
        params[kind][name] = (lo, hi)
    return params


def inject(
    kind: str,
    positions: np.ndarray,
    times_s: np.ndarray,
    rng: np.random.Generator,
    params: dict[str, dict[str, Range]] | None = None,
    motion: np.ndarray | None = None,
) -> Injected:
    """Write one anomaly of `kind` into a track; `motion`: its reported SOG, COG and heading
    ([n, 3]; None: a track of positions alone, its motion derived from them)."""
    if len(positions) < MIN_POINTS:
        raise ValueError(f"a track needs at least {MIN_POINTS} reports to take an anomaly")
    p = np.asarray(positions, np.float64)
    t = np.asarray(times_s, np.float64)
    m = derived_motion(p, t) if motion is None else np.asarray(motion, np.float64)
    prm = (params or DEFAULTS)[kind]
    return KINDS[kind](p, t, m, rng, prm)
