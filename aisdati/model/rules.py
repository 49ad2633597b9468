"""Known update rules g(ŝ, â) -> ŝ' (the agent's kinematic intuition) and their perfect decisions.

A rule declares its decision variables and their physical range; the environment and the networks
work with decisions scaled into [-1, 1] (the actors' tanh outputs) through `BoxScaler`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from aisdati.geo import spherical_decision, spherical_step


@dataclass(frozen=True)
class BoxScaler:
    """Affine map between a physical box [low, high] and the unit box [-1, 1] (or [0, 1])."""

    low: np.ndarray
    high: np.ndarray
    unit_low: float = -1.0

    def scale(self, x: np.ndarray) -> np.ndarray:
        span = self.high - self.low
        return self.unit_low + (1.0 - self.unit_low) * (np.asarray(x) - self.low) / span

    def unscale(self, u: np.ndarray) -> np.ndarray:
        span = self.high - self.low
        return (
            self.low
            + (np.asarray(u, dtype=np.float64) - self.unit_low) / (1.0 - self.unit_low) * span
        )


class UpdateRule(ABC):
    """g: the deterministic part of the dynamics that the agent knows in advance."""

    metric: str
    """DTW point distance between states: "euclidean" or "haversine"."""
    decision_names: tuple[str, ...]

    @property
    @abstractmethod
    def decision_scaler(self) -> BoxScaler: ...

    @abstractmethod
    def step(self, state: np.ndarray, decision: np.ndarray) -> np.ndarray:
        """The next state from a state and a physical (unscaled) decision."""

    @abstractmethod
    def perfect_decisions(self, positions: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """Definition 3.2: the decisions [n, k] that `step` maps exactly from each of the n + 1
        reference positions onto the next; `dts` [n] are the real time steps between them."""


@dataclass(frozen=True)
class PlanarRule(UpdateRule):
    """Eq. (3): ŝ' = ŝ + (u cos ξ, u sin ξ) dt, decisions (speed u, heading ξ in radians)."""

    dt: float
    max_speed: float
    min_speed: float = 0.0
    metric: str = "euclidean"
    decision_names: tuple[str, ...] = ("speed", "heading")

    @property
    def decision_scaler(self) -> BoxScaler:
        return BoxScaler(np.array([self.min_speed, -np.pi]), np.array([self.max_speed, np.pi]))

    def step(self, state: np.ndarray, decision: np.ndarray) -> np.ndarray:
        u, xi = decision[..., 0], decision[..., 1]
        return state + np.stack([u * np.cos(xi), u * np.sin(xi)], axis=-1) * self.dt

    def perfect_decisions(self, positions: np.ndarray, dts: np.ndarray) -> np.ndarray:
        delta = np.diff(positions, axis=0)
        speed = np.linalg.norm(delta, axis=-1) / self.dt
        return np.stack([speed, np.arctan2(delta[..., 1], delta[..., 0])], axis=-1)


@dataclass(frozen=True)
class SphericalRule(UpdateRule):
    """Eq. (5): states (lon, lat) in degrees, decisions (SOG knots, COG degrees, dt hours).

    COG is a circular quantity; its decoded range is the 360° window centred on `cog_center`.
    With the default 180 the window is [0, 360], the plain reading; centring it on the training
    traffic's mean course keeps the cluster's headings away from the wrap-around, where an L1
    loss between 359° and 1° (or a tanh output) would otherwise average north into south."""

    max_sog: float
    max_dt_h: float
    cog_center: float = 180.0
    metric: str = "haversine"
    decision_names: tuple[str, ...] = ("sog", "cog", "dt")

    @property
    def decision_scaler(self) -> BoxScaler:
        c = self.cog_center
        return BoxScaler(
            np.array([0.0, c - 180.0, 0.0]), np.array([self.max_sog, c + 180.0, self.max_dt_h])
        )

    def step(self, state: np.ndarray, decision: np.ndarray) -> np.ndarray:
        lon, lat = spherical_step(
            state[..., 0], state[..., 1], decision[..., 0], decision[..., 1], decision[..., 2]
        )
        return np.stack([lon, lat], axis=-1)

    def perfect_decisions(self, positions: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """The SOG and COG (in the rule's window) that reach each next report in its real time
        step (hours)."""
        lon, lat = positions[:-1, 0], positions[:-1, 1]
        sog, cog = spherical_decision(lon, lat, positions[1:, 0], positions[1:, 1], dts)
        cog = (cog - self.cog_center + 180.0) % 360.0 + self.cog_center - 180.0
        return np.stack([sog, cog, np.asarray(dts, dtype=np.float64)], axis=-1)


def mean_course(cog_deg: np.ndarray, weights: np.ndarray | None = None) -> float:
    """Circular mean of courses in degrees [0, 360) (180 when they cancel out)."""
    rad = np.radians(cog_deg)
    w = np.ones_like(rad) if weights is None else weights
    x, y = float(np.sum(w * np.sin(rad))), float(np.sum(w * np.cos(rad)))
    if np.hypot(x, y) < 1e-12:
        return 180.0
    return round(float(np.degrees(np.arctan2(x, y))), 9) % 360.0
