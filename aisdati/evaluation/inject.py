"""Anomalies written into real tracks, one small function per kind, for measuring detection.

No public AIS anomaly labels exist, so detection is measured as trajectory-anomaly papers do
(GM-VSAE, MST-OATD): real held-out tracks are altered in documented ways and the detectors must
rank the altered ones above the untouched ones. Each kind takes the track's positions (lon, lat
degrees) and report times (seconds from its start), a random generator and its parameters, and
returns the new positions and times and the index range [start, end) of the altered stretch in
the new track. Ranges `(lo, hi)` are drawn uniformly. Distances are metres on the sphere.

- detour: a smooth lateral bump, amplitude * sin²(πu), over a contiguous stretch (the "shifted
  segment" of GM-VSAE / MST-OATD, in metres); span 0.2-0.35 of the track, km 2-5.
- jump: a contiguous stretch displaced by one vector, as a spoofed position; span 0.1-0.2,
  km 3-6.
- loiter: circles inserted mid-track (30-70 % along), sailed at the track's median step length
  and report interval; radius_km 0.5-1.5, loops 1-2.
- speed: a stretch sailed at another speed (its report intervals divided by the factor,
  positions unchanged); span 0.2-0.35, slow 0.3 or fast 2-3 (even odds).
- gap: the reports of a stretch removed; span 0.2-0.4.
- noise: GM-VSAE's random-point perturbation, a share of the reports each moved in a random
  direction; fraction 0.2, km 0.5-1.

A position-only score (DTW to rollouts or to the nearest track) cannot see `speed` or `gap` by
design; `aisdati evaluate` still reports them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from aisdati.errors import UserError
from aisdati.geo import courses_deg, legs_m, moved_m
from aisdati.options import parse_names

Range = tuple[float, float]
DEFAULTS: dict[str, dict[str, Range]] = {
    "detour": {"span": (0.2, 0.35), "km": (2.0, 5.0)},
    "jump": {"span": (0.1, 0.2), "km": (3.0, 6.0)},
    "loiter": {"radius_km": (0.5, 1.5), "loops": (1.0, 2.0)},
    "speed": {"span": (0.2, 0.35), "slow": (0.3, 0.3), "fast": (2.0, 3.0)},
    "gap": {"span": (0.2, 0.4)},
    "noise": {"fraction": (0.2, 0.2), "km": (0.5, 1.0)},
}
LIMITS: dict[str, Range] = {
    "span": (0.01, 0.9),
    "km": (0.0, 1000.0),
    "radius_km": (0.01, 100.0),
    "loops": (0.1, 20.0),
    "slow": (0.01, 1.0),
    "fast": (1.0, 100.0),
    "fraction": (0.0, 1.0),
}
"""The allowed interval of each parameter."""
SCALED = ("km", "radius_km")
"""The parameters an anomaly's strength multiplies (`with_strength`): how far it strays."""
MIN_POINTS = 10
"""A track needs this many reports to take an anomaly."""


@dataclass
class Injected:
    positions: np.ndarray
    times_s: np.ndarray
    stretch: tuple[int, int]
    """[start, end) indices of the altered reports in the new track."""


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


def detour(p, t, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    u = (np.arange(i, j) - i + 1) / (j - i + 1)
    side = 90.0 if rng.random() < 0.5 else -90.0
    amp = _draw(rng, prm["km"]) * 1000.0
    out = p.copy()
    out[i:j] = _move(p[i:j], courses_deg(p)[i:j] + side, amp * np.sin(np.pi * u) ** 2)
    return Injected(out, t.copy(), (i, j))


def jump(p, t, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    out = p.copy()
    dist = np.full(j - i, _draw(rng, prm["km"]) * 1000.0)
    out[i:j] = _move(p[i:j], np.full(j - i, rng.uniform(0, 360)), dist)
    return Injected(out, t.copy(), (i, j))


def loiter(p, t, rng, prm) -> Injected:
    n = len(p)
    at = int(rng.integers(int(0.3 * n), int(0.7 * n)))
    radius = _draw(rng, prm["radius_km"]) * 1000.0
    loops = _draw(rng, prm["loops"])
    step_m = float(np.median(legs_m(p)))
    dt = float(np.median(np.diff(t)))
    m = max(8, round(2 * np.pi * radius * loops / max(step_m, 1.0)))
    start_bearing = courses_deg(p)[at] - 90.0
    centre = _move(p[at : at + 1], np.array([start_bearing + 180.0]), np.array([radius]))
    angles = start_bearing + 360.0 * loops * np.arange(1, m + 1) / m
    ring = _move(np.repeat(centre, m, axis=0), angles, np.full(m, radius))
    pos = np.vstack([p[: at + 1], ring, p[at + 1 :]])
    times = np.r_[t[: at + 1], t[at] + dt * np.arange(1, m + 1), t[at + 1 :] + dt * m]
    return Injected(pos, times, (at + 1, at + 1 + m))


def speed(p, t, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    factor = _draw(rng, prm["slow"] if rng.random() < 0.5 else prm["fast"])
    dt = np.diff(t)
    dt[i - 1 : j - 1] = dt[i - 1 : j - 1] / factor
    return Injected(p.copy(), np.r_[0.0, np.cumsum(dt)] + t[0], (i, j))


def gap(p, t, rng, prm) -> Injected:
    i, j = _stretch(rng, len(p), prm["span"])
    keep = np.r_[np.arange(i), np.arange(j, len(p))]
    return Injected(p[keep], t[keep], (i - 1, i + 1))


def noise(p, t, rng, prm) -> Injected:
    n = len(p)
    k = max(1, round(_draw(rng, prm["fraction"]) * (n - 2)))
    idx = np.sort(rng.choice(np.arange(1, n - 1), size=min(k, n - 2), replace=False))
    out = p.copy()
    dist = np.array([_draw(rng, prm["km"]) for _ in idx]) * 1000.0
    out[idx] = _move(p[idx], rng.uniform(0, 360, len(idx)), dist)
    return Injected(out, t.copy(), (int(idx[0]), int(idx[-1]) + 1))


KINDS: dict[str, Callable[..., Injected]] = {
    "detour": detour,
    "jump": jump,
    "loiter": loiter,
    "speed": speed,
    "gap": gap,
    "noise": noise,
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
) -> Injected:
    """Write one anomaly of `kind` into a track."""
    if len(positions) < MIN_POINTS:
        raise ValueError(f"a track needs at least {MIN_POINTS} reports to take an anomaly")
    prm = (params or DEFAULTS)[kind]
    return KINDS[kind](np.asarray(positions, np.float64), np.asarray(times_s, np.float64), rng, prm)
