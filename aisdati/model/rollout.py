"""Rollouts of trained policies on references, batched over members and references.

At inference the agent is "fooled with no cheese signal": from each unseen reference's first
point it generates a whole trajectory through g with its own noise, and the smoothed, normalised
DTW to the reference at the horizon is its score (the paper's metric is the lowest over seeds x
references). `rollout_policy` runs any batched policy (`Act`); `dati_policy` is DATI's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import torch

from aisdati.model.dati import DATIConfig
from aisdati.model.env import Reference, TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks
from aisdati.model.noise import NoiseProcess

Act = Callable[[np.ndarray], np.ndarray]
"""A batched policy: observations [E, R, obs] -> scaled decisions [E, R, k]."""


def seed_generator(*key: int) -> torch.Generator:
    """A generator keyed by integers (evaluation seed, member seed, reference index), so that a
    member's rollouts do not depend on which ensemble or worker it was trained in."""
    state = np.random.SeedSequence([int(k) for k in key]).generate_state(1)[0]
    return torch.Generator().manual_seed(int(state))


def rollout_policy(
    act: Act,
    env_grid: Sequence[Sequence[TrajectoryImitationEnv]],
    references: Sequence[Sequence[Reference]],
) -> tuple[list[list[np.ndarray]], np.ndarray]:
    """Roll `act` out for member e on `references[e][r]` in `env_grid[e][r]` from the reference's
    first point, on its own predictions (no cheese signal); one batched call of `act` per step.
    Returns the paths `[E][R]` and the final smoothed normalised DTW `[E, R]`."""
    members, refs = len(env_grid), len(env_grid[0])
    obs = np.stack(
        [
            [env_grid[e][r].reset(options={"reference": references[e][r]})[0] for r in range(refs)]
            for e in range(members)
        ]
    ).astype(np.float32)
    paths = [[[env_grid[e][r].position.copy()] for r in range(refs)] for e in range(members)]
    scores = np.full((members, refs), np.nan)
    alive = np.ones((members, refs), dtype=bool)
    while alive.any():
        actions = act(obs)
        for e, r in zip(*np.nonzero(alive), strict=True):
            env = env_grid[e][r]
            obs[e, r], _, terminated, truncated, info = env.step(actions[e, r])
            paths[e][r].append(env.position.copy())
            if terminated or truncated:
                alive[e, r] = False
                scores[e, r] = info["dtw_smoothed"]
    return [[np.asarray(p) for p in row] for row in paths], scores


def dati_policy(
    nets: DATINetworks,
    config: DATIConfig,
    refs: int,
    seed: int = 0,
    noise: Sequence[NoiseProcess] | None = None,
) -> Act:
    """DATI's forward actors as a batched policy; each (member, reference) pair draws its latent
    noise from its own stream, with the member's process (`noise`, default: the config's)."""
    processes = list(noise or [config.noise_process] * nets.members)
    noises = [
        config.latent_noise([seed_generator(seed, member_seed, r) for r in range(refs)], [p] * refs)
        for member_seed, p in zip(nets.seeds, processes, strict=True)
    ]

    device = nets.device

    def act(obs: np.ndarray) -> np.ndarray:
        eta = torch.stack([n.sample()[:, 0] for n in noises]).to(device)
        return nets.decide(torch.as_tensor(obs).to(device), eta).cpu().numpy()

    return act
