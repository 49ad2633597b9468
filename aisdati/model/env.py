"""The trajectory-imitation game ("mouse and hidden cheese", section 3.2) as a Gymnasium env.

Each episode draws one reference trajectory. The agent starts on its first point and, at every
step, chooses a decision (scaled into [-1, 1]); the known update rule g moves it; the reference's
next point is then revealed and the agent is rewarded +1 when the exponentially smoothed DTW
between its own prefix and the reference prefix (including the point just revealed) is below ε,
else -1. A move that would leave the region keeps the agent where it is ("sticking").

Observation: (x, y) of the agent scaled into [0, 1] by the region's box, and the step index t.
The references, the region and the DTW normalisation come from a `ReferenceSource`, so the same
environment serves the self-test's synthetic families and real AIS tracks: this module knows
neither.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from aisdati import ENV_ID as ENV_ID  # registered with Gymnasium by aisdati/__init__.py
from aisdati.dtw import IncrementalDTW
from aisdati.model.rules import UpdateRule


@dataclass(frozen=True)
class Reference:
    """One reference trajectory: n + 1 positions, the n real time steps between them, a label."""

    positions: np.ndarray
    dts: np.ndarray
    label: dict[str, Any] = field(default_factory=dict)

    @property
    def steps(self) -> int:
        return len(self.positions) - 1


class ReferenceSource(ABC):
    """Where references come from, the region they live in, and how DTW is normalised."""

    rule: UpdateRule
    bounds: tuple[np.ndarray, np.ndarray]
    max_steps: int

    @abstractmethod
    def sample(self, rng: np.random.Generator) -> Reference: ...

    @abstractmethod
    def normalize(self, distance: float, path_length: int) -> float:
        """The DTW value compared with ε (synthetic: DTW / diameter)."""

    def contains(self, position: np.ndarray) -> bool:
        """Whether a position lies in the region; the default region is the bounding box."""
        lo, hi = self.bounds
        return bool(np.all(position >= lo) and np.all(position <= hi))

    def restart(self) -> None:
        """Called on a seeded reset: forget any sampling state, so that the same seed draws
        the same references (Gymnasium's reset contract). Sources that draw afresh from the
        environment's generator every time have nothing to forget."""
        return None

    def resolve(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        """Where a move ends: the proposed point, or where the agent is when it would leave the
        region (the paper's sticking)."""
        ok = bool(np.all(np.isfinite(proposed))) and self.contains(proposed)
        return proposed if ok else position

    # The networks' view of the agent. By default (the paper's) the state is the position
    # scaled into [0, 1] by the region's box and the time input is the step index.
    @property
    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Low and high of the state features (the observation space)."""
        return np.zeros(2), np.ones(2)

    @property
    def time_high(self) -> float:
        return float(self.max_steps)

    def features(self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """States [..., d] of agents at `positions` that were at `previous` `dts` earlier."""
        lo, hi = self.bounds
        return np.clip((np.asarray(positions, np.float64) - lo) / (hi - lo), 0.0, 1.0)

    def time_input(self, t: np.ndarray, horizon: int) -> np.ndarray:
        return np.asarray(t, np.float64)

    def reference_states(self, ref: Reference) -> np.ndarray:
        """The states [n, d] of the reference's own points 0..n-1 (each from its predecessor)."""
        pos = ref.positions[:-1]
        prev = np.vstack([pos[:1], pos[:-1]])
        dts = np.r_[0.0, ref.dts[:-1]]
        return self.features(pos, prev, dts)


class TrajectoryImitationEnv(gym.Env):
    """Gymnasium environment of the trajectory-imitation task."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (Gymnasium's convention)

    def __init__(
        self,
        source: ReferenceSource,
        rule: UpdateRule | None = None,
        epsilon: float = 0.1,
        smoothing: float = 0.9,
    ) -> None:
        self.source = source
        self.rule = rule or source.rule
        self.epsilon = epsilon
        self.smoothing = smoothing
        self.decision_scaler = self.rule.decision_scaler
        n_decisions = len(self.rule.decision_names)
        low, high = source.state_bounds
        self.observation_space = gym.spaces.Box(
            low=np.r_[low, 0.0].astype(np.float32),
            high=np.r_[high, source.time_high].astype(np.float32),
            dtype=np.float32,
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(n_decisions,), dtype=np.float32)
        self._dtw = IncrementalDTW(metric=self.rule.metric, capacity=source.max_steps + 1)
        self.reference: Reference | None = None
        self.position = np.zeros(2)
        self.previous = np.zeros(2)
        self.last_dt = 0.0
        self.t = 0
        self.smoothed = 0.0
        self._perfect = np.zeros((0, n_decisions))

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a new episode; `options={"reference": Reference}` pins the reference."""
        super().reset(seed=seed)
        if seed is not None:
            self.source.restart()
        options = options or {}
        ref = options.get("reference") or self.source.sample(self.np_random)
        self.reference = ref
        self._perfect = self.scaled_perfect(ref)
        self.position = ref.positions[0].astype(np.float64).copy()
        self.previous = self.position.copy()
        self.last_dt = 0.0
        self.t = 0
        self.smoothed = 0.0
        self._dtw.reset()
        self._dtw.push(self.position, ref.positions[0])
        return self._observation(), {"reference": ref}

    def episode_state(self) -> dict[str, Any]:
        """Where the current episode stands (the reference aside), so that a checkpoint taken
        while it runs continues it exactly: see `load_episode_state`."""
        return {
            "position": self.position.copy(),
            "previous": self.previous.copy(),
            "last_dt": self.last_dt,
            "t": self.t,
            "smoothed": self.smoothed,
            "dtw": self._dtw.state_dict(),
        }

    def load_episode_state(self, state: dict[str, Any]) -> None:
        """Continue an episode of `episode_state`; call after `reset` onto its reference."""
        self.position = np.array(state["position"], dtype=np.float64)
        self.previous = np.array(state["previous"], dtype=np.float64)
        self.last_dt, self.t = float(state["last_dt"]), int(state["t"])
        self.smoothed = float(state["smoothed"])
        self._dtw.load_state_dict(state["dtw"])

    def scaled_perfect(self, ref: Reference) -> np.ndarray:
        """The perfect decisions [n, k] of a reference (definition 3.2), scaled into [-1, 1]."""
        perfect = self.rule.perfect_decisions(ref.positions, ref.dts)
        return np.clip(self.decision_scaler.scale(perfect), -1, 1)

    def demonstration(self, ref: Reference) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The reference as supervised pairs: its own states [n, d], time inputs [n] and scaled
        perfect decisions [n, k] (what BC learns from, and DATI's optional pretraining)."""
        n = ref.steps
        times = np.asarray(self.source.time_input(np.arange(n), n), np.float64)
        return self.source.reference_states(ref), times, self.scaled_perfect(ref)

    @property
    def perfect_actions(self) -> np.ndarray:
        """The scaled perfect decisions a_0..a_{n-1} of the current reference (definition 3.2)."""
        return self._perfect

    @property
    def horizon(self) -> int:
        return self.reference.steps if self.reference is not None else self.source.max_steps

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self.reference is None:
            raise RuntimeError("call reset() before step()")
        decision = self.decision_scaler.unscale(np.clip(action, -1.0, 1.0))
        proposed = self.rule.step(self.position, decision)
        moved = self.source.resolve(self.position, proposed)
        stuck = bool(np.all(moved == self.position))
        self.previous, self.position = self.position, moved
        self.last_dt = float(self.reference.dts[self.t])
        self.t += 1
        revealed = self.reference.positions[self.t]
        distance = self._dtw.push(self.position, revealed)
        value = self.source.normalize(distance, self._dtw.path_length)
        self.smoothed = self.smoothing * value + (1.0 - self.smoothing) * self.smoothed
        reward = 1.0 if self.smoothed < self.epsilon else -1.0
        terminated = self.t >= self.reference.steps
        info = {
            "dtw": distance,
            "dtw_normalized": value,
            "dtw_smoothed": self.smoothed,
            "stuck": stuck,
            "perfect_action": self._perfect[self.t - 1].astype(np.float32),
        }
        return self._observation(), reward, terminated, False, info

    def _observation(self) -> np.ndarray:
        state = self.source.features(self.position, self.previous, self.last_dt)
        time = self.source.time_input(self.t, self.horizon)
        return np.r_[state, time].astype(np.float32)
