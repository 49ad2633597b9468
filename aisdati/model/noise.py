"""The noise processes of the trainers and their rollouts: one Ornstein-Uhlenbeck step, DATI's
latent noise η_t and DDPG-TI's exploration noise.

Every member (and, in rollouts, every reference or row) draws from its own torch generator, so
its noise does not depend on the ensemble it is part of.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import torch
from torch import Tensor

Value = TypeVar("Value", Tensor, np.ndarray)


def ou_step(x: Value, noise: Value, theta: float, dt: float, sigma: float = 1.0) -> Value:
    """One Euler step of the mean-zero Ornstein-Uhlenbeck process dx = −θ x dt + σ dW from x:
    x − θ x dt + σ √dt · noise, for standard normal `noise` of x's shape (SB3's
    `OrnsteinUhlenbeckActionNoise`, DDPG-TI's), or with σ = 1 for draws already scaled by σ
    (DATI's latent draws, which its Gaussian process uses as they are)."""
    return x - theta * x * dt + sigma * np.sqrt(dt) * noise


@dataclass(frozen=True)
class NoiseProcess:
    """One member's latent noise process: "gaussian" or "ou" with its time step."""

    kind: str = "gaussian"
    ou_dt: float = 1e-2


class LatentNoise:
    """Latent noise η_t ([E, rows, dim]) of E streams, each Gaussian N(0, σ²) or
    Ornstein-Uhlenbeck (started and reset at 0) as its `NoiseProcess` says, each drawing from
    its own generator. The trainer's streams are its members (one row each); a rollout's are its
    (member, reference) pairs or one stream of many rows (`DATIConfig.latent_noise`)."""

    def __init__(
        self,
        generators: Sequence[torch.Generator],
        processes: Sequence[NoiseProcess],
        dim: int,
        sigma: float,
        theta: float,
        rows: int = 1,
    ):
        if len(processes) != len(generators):
            raise ValueError("give one noise process per member")
        self.generators = list(generators)
        self.processes = list(processes)
        self.dim, self.sigma, self.theta, self.rows = dim, sigma, theta, rows
        self.state = torch.zeros(len(self.generators), rows, dim)

    def draw(self, k: int, rows: int = 1) -> Tensor:
        """A [rows, dim] draw of N(0, σ²) from stream k's generator."""
        return torch.randn((rows, self.dim), generator=self.generators[k]) * self.sigma

    def reset(self, k: int) -> None:
        self.state[k].zero_()

    def sample(self) -> Tensor:
        """The next η_t of every stream ([E, rows, dim], a copy)."""
        for k, process in enumerate(self.processes):
            draw = self.draw(k, self.rows)
            if process.kind == "ou":
                self.state[k] = ou_step(self.state[k], draw, self.theta, process.ou_dt)
            else:
                self.state[k] = draw
        return self.state.clone()

    def keep(self, idx: list[int]) -> None:
        """Keep streams `idx` only (members leaving the ensemble)."""
        self.generators = [self.generators[i] for i in idx]
        self.processes = [self.processes[i] for i in idx]
        self.state = self.state[idx]


class OUNoise:
    """Ornstein-Uhlenbeck exploration noise per member ([E, dim], `ou_step`, started and reset
    at 0), drawn from the generators the caller passes."""

    def __init__(self, members: int, dim: int, sigma: float, theta: float, dt: float):
        self.sigma, self.theta, self.dt = sigma, theta, dt
        self.state = torch.zeros(members, dim)

    def sample(self, generators: Sequence[torch.Generator]) -> Tensor:
        draws = torch.stack([torch.randn(self.state.shape[1], generator=g) for g in generators])
        self.state = ou_step(self.state, draws, self.theta, self.dt, self.sigma)
        return self.state

    def reset(self, k: int) -> None:
        self.state[k] = 0.0


# ------------------------------------------------------------------- noise keyed by row, not batch
GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 values: a bijection whose outputs look independent,
    so that a key and a counter give random bits without a generator's state."""
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def keyed_normal(keys: np.ndarray, counter: int, dim: int) -> np.ndarray:
    """[n, dim] standard normal draws (Box-Muller), row i a function of `keys[i]` and `counter`
    alone: a row's noise is the same whatever other rows share its batch, in whichever order or
    chunk they come (scoring: a track's score never depends on the tracks judged with it)."""
    keys = np.asarray(keys, np.uint64)
    with np.errstate(over="ignore"):
        base = mix64(keys + np.uint64(counter + 1) * GOLDEN)
        lanes = mix64(np.arange(1, 2 * dim + 1, dtype=np.uint64) * GOLDEN)
        bits = mix64(base[:, None] ^ lanes[None, :])
    u = (bits >> np.uint64(11)).astype(np.float64) * 2.0**-53
    radius = np.sqrt(-2.0 * np.log1p(-u[:, :dim]))
    return radius * np.cos(2.0 * np.pi * u[:, dim:])


class KeyedNoise:
    """Latent noise of rows that each draw from their own key (`keyed_normal`), Gaussian
    N(0, σ²) or Ornstein-Uhlenbeck (started at 0) as `process` says: the scoring counterpart of
    `LatentNoise`, whose streams are the batch's."""

    def __init__(
        self,
        keys: np.ndarray,
        dim: int,
        sigma: float = 1.0,
        theta: float = 0.0,
        process: NoiseProcess = NoiseProcess(),
    ):
        self.keys, self.dim, self.sigma, self.theta = keys, dim, sigma, theta
        self.process, self.count = process, 0
        self.state = np.zeros((len(keys), dim))

    def sample(self) -> Tensor:
        """The next draw of every row ([n, dim])."""
        draw = keyed_normal(self.keys, self.count, self.dim) * self.sigma
        self.count += 1
        if self.process.kind == "ou":
            self.state = ou_step(self.state, draw, self.theta, self.process.ou_dt)
        else:
            self.state = draw
        return torch.as_tensor(self.state, dtype=torch.float32)
