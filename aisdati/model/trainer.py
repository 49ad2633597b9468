"""What the three trainers (DATI, BC, DDPG-TI) share: E members trained in lockstep, one per
(environment, seed), a `step` that says which members' episodes it ended, and one callback
protocol for whoever follows the training (the self-test, AIS training, progress bars).

The protocol, after Stable-Baselines3's `BaseCallback.on_step` but as one plain callable:
`callback(trainer, logs)` is called after every `step` with the `EpisodeLog`s of the episodes
that step ended (usually none), so a progress bar counts `logs` and a step bar reads the
trainer's state. Raising in it (a Ctrl-C) stops training between two steps.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import torch

from aisdati.model.env import TrajectoryImitationEnv

Model = TypeVar("Model")


@dataclass
class EpisodeLog:
    """What one member did in one training episode. Fields a trainer has no value for are NaN
    (BC does not act in the environment: no reward, no DTW)."""

    member: int
    """The member's index in the trainer's `seeds` (whatever members have left the ensemble)."""
    seed: int
    episode: int
    steps: int
    mean_reward: float
    final_dtw: float
    mean_loss: float
    stopped: bool
    """Whether this was the member's last episode."""
    validation: float | None = None
    """The validation score of the episode's actor, when the trainer validates (DATI)."""


Callback = Callable[["Trainer[Any]", list[EpisodeLog]], None]
"""`callback(trainer, logs)`: called after every training step with the episodes it ended."""


class Trainer(ABC, Generic[Model]):
    """E members, one per (environment, seed). Member k's exploration, replay and noise draw
    from `generators[k]` (seeded by its seed + 1; its networks start from its seed), so a
    member trains the same in any ensemble."""

    def __init__(self, envs: Sequence[TrajectoryImitationEnv], seeds: Sequence[int]):
        if len(envs) != len(seeds) or not envs:
            raise ValueError("give one environment per seed, at least one")
        self.envs = list(envs)
        self.seeds = [int(s) for s in seeds]
        self.generators = [torch.Generator().manual_seed(s + 1) for s in self.seeds]
        self.episode = [0] * len(self.seeds)
        """Episodes each member has finished, indexed like `seeds`."""
        self.history: list[EpisodeLog] = []

    @abstractmethod
    def step(self) -> list[EpisodeLog]:
        """One step of training; the logs of the episodes it ended."""

    @property
    @abstractmethod
    def done(self) -> bool:
        """Whether every member has finished training."""

    @abstractmethod
    def model(self) -> Model:
        """What training produces (the networks that roll out)."""

    def train(self, callback: Callback | None = None) -> Model:
        """Step until done, calling `callback(self, logs)` after every step; returns `model()`."""
        while not self.done:
            logs = self.step()
            if callback is not None:
                callback(self, logs)
        return self.model()
