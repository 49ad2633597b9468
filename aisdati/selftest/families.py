"""Synthetic trajectory families (table 1 and appendix A.1 of the paper).

A family is a parametric curve s(t) = (x(t, α), y(t, α)) on t ∈ [0, T] with T = 2π/ω, sampled at
τ + 1 equally spaced instants (τ steps). One shape parameter α is drawn uniformly from its interval
per episode; every other parameter is fixed inside the two coordinate functions.

Define your own family in a few lines and register it, so that `aisdati selftest --family NAME`
and the environment find it::

    import numpy as np
    from aisdati.selftest.families import Family, register_family

    register_family(Family(
        name="spiral",
        x=lambda t, a: a * t * np.cos(t),
        y=lambda t, a: a * t * np.sin(t),
        alpha_range=(0.5, 1.0),
        omega=0.5,
    ))
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from aisdati.dtw import dtw
from aisdati.errors import UserError

Coordinate = Callable[[np.ndarray, float], np.ndarray]

BOUNDS_MARGIN = 0.1
"""Fraction of the family's extent added on each side of its bounding box: the region the agent
may move in before it sticks at the boundary."""

SPEED_MARGIN = 1.25
"""Headroom above the family's fastest step for the decoded speed range."""


@dataclass(frozen=True)
class Family:
    """A family of reference trajectories F_α of the trajectory-imitation game."""

    name: str
    x: Coordinate
    y: Coordinate
    alpha_range: tuple[float, float]
    omega: float
    steps: int = 200
    wraps: bool = False
    """True when α is an angle that winds around (Ribbons): the boundary members then coincide,
    and the DTW diameter is twice the distance between α_min and the median α."""
    exact: bool = False
    """The authors' geometry: the region is the family's exact bounding box and the decoded
    speed spans exactly [s_min, s_max] of its steps. False (ours): `BOUNDS_MARGIN` on the box
    and [0, `SPEED_MARGIN` x s_max], so that an agent a little off the family is not stuck."""
    grid_size: int = field(default=21, repr=False)

    @property
    def period(self) -> float:
        """T = 2π/ω, the time span of one reference."""
        return 2 * np.pi / self.omega

    @property
    def dt(self) -> float:
        return self.period / self.steps

    def times(self) -> np.ndarray:
        return np.linspace(0.0, self.period, self.steps + 1)

    def reference(self, alpha: float) -> np.ndarray:
        """The member of shape parameter α as a [steps + 1, 2] array of positions."""
        t = self.times()
        return np.stack([self.x(t, alpha), self.y(t, alpha)], axis=1).astype(np.float64)

    def sample_alpha(self, rng: np.random.Generator) -> float:
        lo, hi = self.alpha_range
        return float(rng.uniform(lo, hi))

    def boundary_alphas(self) -> tuple[float, float]:
        """The two members whose DTW defines the family's diameter (Fig. 1's blue and green)."""
        lo, hi = self.alpha_range
        return (lo, (lo + hi) / 2) if self.wraps else (lo, hi)

    @cached_property
    def _grid(self) -> np.ndarray:
        alphas = np.linspace(*self.alpha_range, self.grid_size)
        return np.stack([self.reference(a) for a in alphas])

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Low and high corners of the region the agent lives in (the family's box, plus
        `BOUNDS_MARGIN` unless `exact`)."""
        pts = self._grid.reshape(-1, 2)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.0 if self.exact else BOUNDS_MARGIN * np.maximum(hi - lo, 1e-9)
        return lo - pad, hi + pad

    @cached_property
    def speed_range(self) -> tuple[float, float]:
        """The decoded speed range: [s_min, s_max] of the family's steps when `exact`, else
        [0, s_max] with headroom."""
        steps = np.linalg.norm(np.diff(self._grid, axis=1), axis=2) / self.dt
        if self.exact:
            lo, hi = float(steps.min()), float(steps.max())
            return lo, max(hi, lo + 1e-9)  # a constant-speed family still has a range
        return 0.0, float(steps.max() * SPEED_MARGIN)

    @property
    def max_speed(self) -> float:
        return self.speed_range[1]

    @cached_property
    def diameter(self) -> float:
        """DTW "diameter" D>: the normaliser of every DTW reported for this family."""
        a, b = self.boundary_alphas()
        d = dtw(self.reference(a), self.reference(b))
        return 2 * d if self.wraps else d


def _fixed_start() -> Family:
    omega = kappa = 0.9
    return Family(
        name="fixedstart",
        x=lambda t, a: np.sqrt(a * t),
        y=lambda t, a: np.cos(omega * t) * np.exp(-kappa * t),
        alpha_range=(5.0, 10.0),
        omega=omega,
    )


def _u_shaped() -> Family:
    omega = 0.9
    return Family(
        name="ushaped",
        x=lambda t, a: omega * t,
        y=lambda t, a: np.cos(omega * t) - a * np.cos(2 * omega * t) / 2,
        alpha_range=(0.2, 0.8),
        omega=omega,
    )


def _circles() -> Family:
    omega = 0.4
    return Family(
        name="circles",
        x=lambda t, a: a * np.cos(omega * t),
        y=lambda t, a: a * np.sin(omega * t),
        alpha_range=(0.5, 1.0),
        omega=omega,
    )


def _ribbons() -> Family:
    omega, r1, r2 = 0.4, 1.0, 2.0
    return Family(
        name="ribbons",
        x=lambda t, a: (r1 - r2 * np.cos(omega * t / 4)) * np.cos(omega * t + a),
        y=lambda t, a: (r1 - r2 * np.cos(omega * t / 4)) * np.sin(omega * t + a),
        alpha_range=(-np.pi, np.pi),
        omega=omega,
        wraps=True,
    )


FAMILIES: dict[str, Family] = {
    f.name: f for f in (_fixed_start(), _u_shaped(), _circles(), _ribbons())
}
"""The registry of families by lower-case name; the paper's four come first."""


def register_family(family: Family) -> Family:
    """Make a user-defined family available by name (to the environment and `selftest`)."""
    FAMILIES[family.name.lower()] = family
    return family


def get_family(name: str) -> Family:
    try:
        return FAMILIES[name.lower()]
    except KeyError:
        raise UserError(f"unknown family {name!r}; choose from {', '.join(FAMILIES)}") from None
