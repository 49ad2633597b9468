"""What the trainers learn from, one store per member held as [E, capacity, dim] tensors: the
replay ring buffer of DATI and DDPG-TI, and BC's growing set of demonstrations."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from aisdati.model.env import TrajectoryImitationEnv


class EnsembleReplayBuffer:
    """A ring buffer per member of the transitions' fields (`dims`: name -> width, in order)."""

    def __init__(
        self, members: int, capacity: int, dims: dict[str, int], device: torch.device | str = "cpu"
    ):
        """The buffer lives on `device` (the networks'); indices are drawn on the CPU."""
        self.capacity, self.device = capacity, device
        self.data = {
            k: torch.zeros(members, capacity, width, device=device) for k, width in dims.items()
        }
        self.size = 0
        self.ptr = 0

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(self.data)

    def add(self, **batch: Tensor) -> None:
        """Append one transition per member; each value is [E, dim]."""
        for key in self.fields:
            self.data[key][:, self.ptr] = batch[key].to(self.device)
        self.ptr = (self.ptr + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int, generators: Sequence[torch.Generator]) -> dict[str, Tensor]:
        """A batch per member drawn uniformly with replacement, member k by generator k."""
        idx = torch.stack(
            [torch.randint(self.size, (batch_size,), generator=g) for g in generators]
        )
        idx, rows = idx.to(self.device), torch.arange(len(generators), device=self.device)[:, None]
        return {k: v[rows, idx] for k, v in self.data.items()}

    def keep(self, idx: list[int]) -> None:
        """Keep members `idx` only (members leaving the ensemble)."""
        self.data = {k: v[idx] for k, v in self.data.items()}

    def state_dict(self) -> dict[str, Any]:
        """The filled part of the buffer and where it writes next."""
        return {
            "data": {k: v[:, : self.size].clone() for k, v in self.data.items()},
            "size": self.size,
            "ptr": self.ptr,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        size = int(state["size"])
        for k, v in state["data"].items():
            self.data[k].zero_()
            self.data[k][:, :size] = v.to(self.device)
        self.size, self.ptr = size, int(state["ptr"])


class DemonstrationBuffer:
    """The demonstrations seen so far by E members, as [E, capacity, ·] tensors (state scaled
    into [0, 1], step index t, scaled perfect decision a_t) with a fill level per member; it
    grows when a member's next reference does not fit."""

    def __init__(self, members: int, capacity: int, state_dim: int, decision_dim: int):
        self.state = torch.zeros(members, capacity, state_dim)
        self.time = torch.zeros(members, capacity, 1)
        self.action = torch.zeros(members, capacity, decision_dim)
        self.size = [0] * members

    def add(self, k: int, env: TrajectoryImitationEnv) -> int:
        """Append the current reference of member k's environment; returns its step count."""
        ref = env.reference
        assert ref is not None
        n, lo = ref.steps, self.size[k]
        if lo + n > self.state.shape[1]:
            grow = max(n, self.state.shape[1])
            for name in ("state", "time", "action"):
                old = getattr(self, name)
                setattr(self, name, torch.cat([old, torch.zeros_like(old[:, :grow])], dim=1))
        states, times, actions = env.demonstration(ref)
        self.state[k, lo : lo + n] = torch.as_tensor(states)
        self.time[k, lo : lo + n, 0] = torch.as_tensor(times)
        self.action[k, lo : lo + n] = torch.as_tensor(actions)
        self.size[k] += n
        return n

    def sample(self, batch: int, generators: Sequence[torch.Generator]) -> list[Tensor]:
        """A batch per member drawn with replacement from everything it has seen."""
        idx = torch.stack(
            [
                torch.randint(n, (batch,), generator=g)
                for n, g in zip(self.size, generators, strict=True)
            ]
        )
        return self._rows(idx)

    def epoch(self, batch: int, generators: Sequence[torch.Generator]) -> list[list[Tensor]]:
        """One shuffled pass over each member's data in batches (the last one may be smaller);
        members hold as many pairs each (one reference of the family's τ per episode)."""
        n = min(self.size)
        order = torch.stack([torch.randperm(n, generator=g) for g in generators])
        return [self._rows(order[:, i : i + batch]) for i in range(0, n, batch)]

    def _rows(self, idx: Tensor) -> list[Tensor]:
        rows = torch.arange(idx.shape[0])[:, None]
        return [self.state[rows, idx], self.time[rows, idx], self.action[rows, idx]]
