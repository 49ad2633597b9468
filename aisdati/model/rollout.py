"""Rollouts of trained forward actors and the paper's metric with robust statistics.

At inference the agent is "fooled with no cheese signal": from each unseen reference's first
point it generates a whole trajectory through g with its own latent noise, and the smoothed,
normalised DTW to the reference at the horizon is its score (Table 1 reports the lowest over
seeds x references). Because a best-of-100 hides instability, the median and the interquartile
mean (IQM, Agarwal et al. 2021) with a 95% bootstrap interval are reported beside it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import trim_mean

from aisdati.model.dati import DATIConfig, LatentNoise, NoiseProcess
from aisdati.model.env import Reference, TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks


@dataclass
class Rollouts:
    """Generated trajectories [member][reference] and their final smoothed DTW [E, R]."""

    paths: list[list[np.ndarray]]
    scores: np.ndarray


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
    """Roll `act` out for member e on references[e][r] in env_grid[e][r] from the reference's
    first point, on its own predictions (no cheese signal); one batched call of `act` per step.
    Returns the paths [E][R] and the final smoothed normalised DTW [E, R]."""
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
        LatentNoise(
            config,
            [seed_generator(seed, member_seed, r) for r in range(refs)],
            [process] * refs,
        )
        for member_seed, process in zip(nets.seeds, processes, strict=True)
    ]
    state_dim = nets.forward_actor.input_features.weight.shape[1]

    def act(obs: np.ndarray) -> np.ndarray:
        x = torch.as_tensor(obs)
        eta = torch.stack([n.sample()[:, 0] for n in noises])
        with torch.no_grad():
            time = nets.time_features(x[..., state_dim:])
            return nets.forward_actor(x[..., :state_dim], eta, time).numpy()

    return act


def rollout(
    nets: DATINetworks,
    env_grid: Sequence[Sequence[TrajectoryImitationEnv]],
    references: Sequence[Sequence[Reference]],
    config: DATIConfig,
    seed: int = 0,
    noise: Sequence[NoiseProcess] | None = None,
) -> Rollouts:
    """Roll out DATI member e on references[e][r] in env_grid[e][r]."""
    act = dati_policy(nets, config, len(env_grid[0]), seed, noise)
    return Rollouts(*rollout_policy(act, env_grid, references))


@dataclass(frozen=True)
class Summary:
    """The paper's metric and robust statistics over a set of scores (lower is better)."""

    best: float
    median: float
    iqm: float
    iqm_low: float
    iqm_high: float
    n: int


def interquartile_mean(values: np.ndarray) -> float:
    return float(trim_mean(values, 0.25))


def summarize(scores: np.ndarray, resamples: int = 2000, seed: int = 0) -> Summary:
    """Best, median and IQM with a percentile-bootstrap 95% interval of the IQM."""
    x = np.asarray(scores, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    rng = np.random.default_rng(seed)
    boots = [interquartile_mean(rng.choice(x, size=len(x))) for _ in range(resamples)]
    low, high = np.percentile(boots, [2.5, 97.5])
    return Summary(
        float(x.min()), float(np.median(x)), interquartile_mean(x), float(low), float(high), len(x)
    )
