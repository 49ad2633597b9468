"""DDPG-TI, the paper's reinforcement-learning baseline (section 3.4 and appendix A.2), as a
batched ensemble: E seeds train in lockstep, every layer holding E members' weights.

It is Stable-Baselines3's `DDPG` (TD3 with one critic, no target policy noise, no policy delay)
written over `aisdati.model.networks`' ensemble layers, because 120 SB3 models trained one after
another spent most of Table 1's time in per-step Python overhead (`benchmarks/selftest_speed.py`).
`tests/model/test_ddpg_ti.py` holds it to SB3: from the same weights and batches, SB3's `train` and
`DDPGTITrainer.update` end with the same weights. What it keeps of SB3's DDPG, point by point:
- the agent observes (ŝ_t, t); a features extractor [tanh(W ŝ_t + b) (80), Time2Vec(t) (76)] of
  156 units is shared by actor and critic (`share_features_extractor=True`): it learns from the
  actor's loss only, the critic reads it without gradient, and its target copy (shared by the
  target actor and critic) is soft-updated twice per step, once with each network;
- actor: 4 x 32 tanh hidden units, tanh output; critic: [features, decision] -> 4 x 32 tanh -> Q;
  layers start as torch's `nn.Linear` (uniform in ±1/√fan-in), Time2Vec uniform in ±0.05;
- critic loss: mean squared error to r + γ (1 − done) Q'(s', μ'(s')); actor loss: −Q(s, μ(s));
  Adam (10⁻⁴ actor, 2·10⁻⁴ critic, the paper's; torch's other defaults); soft updates τ;
- collection: the first `learning_starts` decisions uniform in [−1, 1], then the actor's; every
  decision plus Ornstein-Uhlenbeck noise (reset each episode), clipped to [−1, 1]; one gradient
  step per environment step once more than `learning_starts` steps were taken; replay sampled
  uniformly with replacement.
Each member draws from its own generators (initialisation keyed by its seed, exploration and
replay by seed + 1), so a member trains the same in any ensemble.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from aisdati.model.buffers import EnsembleReplayBuffer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.networks import EnsembleLinear, MLPTrunk, NetworkConfig, SplitLinear, Time2Vec
from aisdati.model.noise import OUNoise, ou_step
from aisdati.model.rollout import Act, seed_generator
from aisdati.model.trainer import EpisodeLog, Trainer


@dataclass(frozen=True)
class DDPGTIConfig:
    """Hyperparameters of DDPG-TI; the paper's where it gives them (appendix A.2), SB3's DDPG
    defaults where it is silent (batch 64 and a replay of 50 000 are ours)."""

    episodes: int = 100
    state_features: int = 80
    time_embedding_dim: int = 76
    hidden_units: int = 32
    hidden_layers: int = 4
    gamma: float = 0.9
    tau: float = 1e-3
    lr_actor: float = 1e-4
    lr_critic: float = 2e-4
    noise_sigma: float = 0.3
    noise_theta: float = 0.15
    noise_dt: float = 1e-2
    batch_size: int = 64
    buffer_size: int = 50_000
    learning_starts: int = 64
    inference_noise: bool = True
    """Add the OU noise to the actor's decisions at inference, as the paper writes it."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @property
    def network(self) -> NetworkConfig:
        return NetworkConfig(hidden_units=self.hidden_units, hidden_layers=self.hidden_layers)


def _torch_linear_init_(module: nn.Module, generators: Sequence[torch.Generator]) -> None:
    """Re-draw every ensemble linear layer of `module` like torch's `nn.Linear` (weights and
    biases uniform in ±1/√fan-in, fan-in over all input blocks), member k from generator k."""
    with torch.no_grad():
        for layer in module.modules():
            if isinstance(layer, EnsembleLinear):
                blocks = [layer.weight]
            elif isinstance(layer, SplitLinear):
                blocks = list(layer.weights)
            else:
                continue
            bound = 1.0 / math.sqrt(sum(w.shape[1] for w in blocks))
            for k, gen in enumerate(generators):
                for w in blocks:
                    w[k].uniform_(-bound, bound, generator=gen)
                layer.bias[k].uniform_(-bound, bound, generator=gen)


class DDPGTIFeatures(nn.Module):
    """(ŝ_t, t) -> the 156 shared feature blocks [tanh(W ŝ_t + b), Time2Vec(t) linear, periodic]."""

    def __init__(self, state_dim: int, cfg: DDPGTIConfig, gens: Sequence[torch.Generator]):
        super().__init__()
        self.state = EnsembleLinear(state_dim, cfg.state_features, gens)
        self.time2vec = Time2Vec(cfg.time_embedding_dim, gens)

    @property
    def widths(self) -> list[int]:
        return [self.state.weight.shape[2], 1, self.time2vec.freq.shape[2] - 1]

    def forward(self, obs: Tensor) -> list[Tensor]:
        """obs [E, B, state + 1], the step index last (the environment's observation)."""
        return [torch.tanh(self.state(obs[..., :-1])), *self.time2vec(obs[..., -1:])]


class DDPGTIActorHead(nn.Module):
    """μ from the shared features: 4 x 32 tanh, tanh output in [−1, 1]."""

    def __init__(self, widths: Sequence[int], out: int, cfg: DDPGTIConfig, gens):
        super().__init__()
        self.hidden = MLPTrunk(widths, cfg.network, gens, nn.Tanh())
        self.out = EnsembleLinear(cfg.hidden_units, out, gens)

    def forward(self, features: list[Tensor]) -> Tensor:
        return torch.tanh(self.out(self.hidden(features)))


class DDPGTICriticHead(nn.Module):
    """Q from the shared features and a decision: 4 x 32 tanh, linear output."""

    def __init__(self, widths: Sequence[int], decision_dim: int, cfg: DDPGTIConfig, gens):
        super().__init__()
        self.hidden = MLPTrunk([*widths, decision_dim], cfg.network, gens, nn.Tanh())
        self.out = EnsembleLinear(cfg.hidden_units, 1, gens)

    def forward(self, features: list[Tensor], decision: Tensor) -> Tensor:
        return self.out(self.hidden([*features, decision]))


class DDPGTIActor(nn.Module):
    """The deterministic policy μ(ŝ_t, t) of E members: observations [E, B, obs] -> [E, B, k]."""

    def __init__(self, features: DDPGTIFeatures, head: DDPGTIActorHead):
        super().__init__()
        self.features = features
        self.head = head

    def forward(self, obs: Tensor) -> Tensor:
        return self.head(self.features(obs))


class DDPGTITrainer(Trainer[DDPGTIActor]):
    """Trains E DDPG-TI members, one per (environment, seed), as one ensemble in lockstep."""

    def __init__(
        self,
        envs: Sequence[TrajectoryImitationEnv],
        seeds: Sequence[int],
        config: DDPGTIConfig | None = None,
    ):
        super().__init__(envs, seeds)
        if len({env.source.max_steps for env in envs}) > 1:
            raise ValueError("members of one DDPG-TI ensemble need episodes of equal length")
        self.cfg = c = config or DDPGTIConfig()
        obs_dim = envs[0].observation_space.shape[0]
        k = envs[0].action_space.shape[0]
        gens = [torch.Generator().manual_seed(s) for s in self.seeds]
        features = DDPGTIFeatures(obs_dim - 1, c, gens)
        self.actor = DDPGTIActor(features, DDPGTIActorHead(features.widths, k, c, gens))
        self.critic = DDPGTICriticHead(features.widths, k, c, gens)
        _torch_linear_init_(self.actor, gens)
        _torch_linear_init_(self.critic, gens)
        # the target critic reads the target actor's features, as SB3's does
        self.target_actor = copy.deepcopy(self.actor)
        self.target_critic = copy.deepcopy(self.critic)
        for p in [*self.target_actor.parameters(), *self.target_critic.parameters()]:
            p.requires_grad_(False)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=c.lr_actor, fused=True)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=c.lr_critic, fused=True)
        self.noise = OUNoise(len(envs), k, c.noise_sigma, c.noise_theta, c.noise_dt)
        dims = {"obs": obs_dim, "action": k, "reward": 1, "next_obs": obs_dim, "done": 1}
        self.buffer = EnsembleReplayBuffer(len(envs), c.buffer_size, dims)
        self._obs = np.stack(
            [env.reset(seed=s)[0] for env, s in zip(envs, self.seeds, strict=True)]
        )
        self.timesteps = 0
        self.updates = 0
        self._episode_reward = np.zeros(len(envs))
        self._episode_loss = torch.zeros(len(envs))
        self._episode_updates = np.zeros(len(envs), dtype=int)

    def _decide(self) -> Tensor:
        """Each member's decision for its current observation: uniform in [−1, 1] while fewer
        than `learning_starts` steps were taken, the actor's after; plus OU noise, clipped."""
        if self.timesteps < self.cfg.learning_starts:
            k = self.noise.state.shape[1]
            action = torch.stack([torch.rand(k, generator=g) * 2 - 1 for g in self.generators])
        else:
            with torch.no_grad():
                obs = torch.as_tensor(self._obs, dtype=torch.float32)[:, None]
                action = self.actor(obs)[:, 0]
        return (action + self.noise.sample(self.generators)).clamp(-1.0, 1.0)

    def step(self) -> list[EpisodeLog]:
        """One environment step of every member, then one update once past `learning_starts`;
        logs the episodes that ended (their mean loss: critic plus actor, over the episode's
        updates, NaN before the first)."""
        action = self._decide()
        next_obs, rewards, dones, ended = [], [], [], []
        for k, env in enumerate(self.envs):
            obs, reward, terminated, truncated, info = env.step(action[k].numpy())
            next_obs.append(obs)  # the terminal observation when the episode ends
            rewards.append(reward)
            dones.append(float(terminated))  # a time limit is not a terminal state (SB3)
            if terminated or truncated:
                ended.append((k, info["dtw_smoothed"]))
        self.timesteps += 1
        self.buffer.add(
            obs=torch.as_tensor(self._obs, dtype=torch.float32),
            action=action,
            reward=torch.tensor(rewards, dtype=torch.float32)[:, None],
            next_obs=torch.as_tensor(np.stack(next_obs), dtype=torch.float32),
            done=torch.tensor(dones, dtype=torch.float32)[:, None],
        )
        self._obs = np.stack(next_obs)
        self._episode_reward += rewards
        if self.timesteps > self.cfg.learning_starts:
            critic, actor = self.update(self.buffer.sample(self.cfg.batch_size, self.generators))
            self._episode_loss += critic + actor
            self._episode_updates += 1
        return [self._end_episode(k, dtw) for k, dtw in ended]

    def _end_episode(self, k: int, final_dtw: float) -> EpisodeLog:
        self.episode[k] += 1
        self.noise.reset(k)
        steps = self.envs[k].t
        self._obs[k] = self.envs[k].reset()[0]
        updates = int(self._episode_updates[k])
        loss = float(self._episode_loss[k]) / updates if updates else float("nan")
        log = EpisodeLog(
            k,
            self.seeds[k],
            self.episode[k],
            steps,
            float(self._episode_reward[k]) / steps,
            final_dtw,
            loss,
            self.episode[k] >= self.cfg.episodes,
        )
        self.history.append(log)
        self._episode_reward[k], self._episode_loss[k], self._episode_updates[k] = 0.0, 0.0, 0
        return log

    def update(self, batch: dict[str, Tensor]) -> tuple[Tensor, Tensor]:
        """One gradient step of every member on its batch ([E, B, ·] per field), as SB3's
        `TD3.train` with one critic and no target noise; returns (critic, actor) losses [E]."""
        c = self.cfg
        with torch.no_grad():
            following = self.target_actor.features(batch["next_obs"])
            q_next = self.target_critic(following, self.target_actor.head(following))
            target = batch["reward"] + (1 - batch["done"]) * c.gamma * q_next
        features = self.actor.features(batch["obs"])
        # the critic reads the shared features without gradient; the critic step leaves them
        # unchanged, so the actor's step below reuses them with their gradient
        held = [f.detach() for f in features]
        critic_loss = ((self.critic(held, batch["action"]) - target) ** 2).mean(dim=(1, 2))
        self.opt_critic.zero_grad(set_to_none=True)
        critic_loss.sum().backward()
        self.opt_critic.step()
        actor_loss = -self.critic(held, self.actor.head(features)).mean(dim=(1, 2))
        self.opt_actor.zero_grad(set_to_none=True)
        actor_loss.sum().backward()
        self.opt_actor.step()
        self._soft_update()
        self.updates += 1
        return critic_loss.detach(), actor_loss.detach()

    def _soft_update(self) -> None:
        """SB3's polyak updates: critic, then actor; the shared features' target is moved twice
        (it belongs to both networks there)."""
        tau = self.cfg.tau
        features = list(self.actor.features.parameters())
        target_features = list(self.target_actor.features.parameters())
        pairs = [
            (features, target_features),
            (list(self.critic.parameters()), list(self.target_critic.parameters())),
            (features, target_features),
            (list(self.actor.head.parameters()), list(self.target_actor.head.parameters())),
        ]
        with torch.no_grad():
            for live, target in pairs:
                torch._foreach_mul_(target, 1 - tau)
                torch._foreach_add_(target, live, alpha=tau)

    @property
    def done(self) -> bool:
        return self.timesteps >= self.cfg.episodes * self.envs[0].source.max_steps

    def model(self) -> DDPGTIActor:
        return self.actor


def ddpg_ti_act(
    actor: DDPGTIActor, seeds: Sequence[int], refs: int, cfg: DDPGTIConfig, seed: int = 0
) -> Act:
    """The trained actors as a batched policy over [E, R] observations: μ(ŝ_t, t) plus, with
    `cfg.inference_noise`, an OU process per (member, reference) keyed by the seeds."""
    k = actor.head.out.weight.shape[2]
    gens = [[seed_generator(seed, s, r) for r in range(refs)] for s in seeds]
    state = np.zeros((len(seeds), refs, k))

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            out = actor(torch.as_tensor(obs, dtype=torch.float32)).numpy()
        if not cfg.inference_noise:
            return out
        draws = np.stack([[torch.randn(k, generator=g).numpy() for g in row] for row in gens])
        state[:] = ou_step(state, draws, cfg.noise_theta, cfg.noise_dt, cfg.noise_sigma)
        return np.clip(out + state, -1.0, 1.0)

    return act
