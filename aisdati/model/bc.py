"""The paper's BC baseline (section 3.3, 5.1 and appendix A.2), and BC as the paper ran it.

Both are trained on the same budget as DATI (episodes of τ steps, one reference drawn from the
family per episode) and rolled out like it: from an unseen reference's first point, on their own
predictions ŝ_t through the known rule g (`rollout_policy`).

**BC** (behavioural cloning, written in torch; the `imitation` library pins old gymnasium/SB3):
maximum likelihood of the perfect decisions a_t given the reference state s_t (scaled into
[0, 1]) and the step index t. Policy: a 156-unit feature extractor (80 tanh features of the state
and a Time2Vec embedding of t of dimension 76, the same extractor as DDPG-TI's), 4 x 32 tanh
hidden layers, and linear heads for the mean and the diagonal log standard deviation of a Gaussian.
Loss: −log p(a_t | s_t, t) − 10⁻³ · entropy, Adam 10⁻³. Choices where the paper is silent: each
episode adds its reference's τ (s_t, t, a_t) pairs to the member's data set and is followed by τ
updates on batches of 64 drawn from everything seen so far (one update per transition, as DATI
has one training batch per environment step); log σ is clamped to [−7, 2]; no early stopping.
At inference the policy is stochastic by default (a sample of the Gaussian, as `imitation`'s
policies roll out), `BCConfig.deterministic` uses the mean. All seeds train at once as an
ensemble (every layer holds E members' weights, `aisdati.model.networks`), which is the same
function as E separate runs.

**BC as the paper ran it** (`BC_PAPER`, method `bc-paper` of `aisdati selftest`): the paper
writes BC as π(s_t), and the authors' environment gives `imitation`'s BC only the position, so
this policy has no time input. Otherwise `imitation`'s defaults: batch 32, one learned log σ per
decision that does not depend on the state (SB3's Gaussian policies, starting at log σ = 0),
entropy weight 10⁻³, Adam 10⁻³, and its schedule: the demonstrations of all episodes (the same
100 references as ours) first, then `epochs` shuffled passes over them. The authors' BC script is
not in DLR-MI/dati, so the number of epochs is ours: 1, the value of `imitation`'s BC tutorial
(625 updates for 100 x 200 pairs; our BC makes 20,000).

**DDPG-TI** lives in `aisdati.model.ddpg_ti`: SB3's DDPG as a batched ensemble.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from aisdati.model.buffers import DemonstrationBuffer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.model.networks import EnsembleLinear, MLPTrunk, NetworkConfig, Time2Vec
from aisdati.model.rollout import Act, seed_generator
from aisdati.model.trainer import EpisodeLog, Trainer


# ------------------------------------------------------------------------------------------ BC
@dataclass(frozen=True)
class BCConfig:
    """Hyperparameters of the BC baseline; the paper's where it gives them (appendix A.2)."""

    episodes: int = 100
    state_features: int = 80
    time_embedding_dim: int = 76
    """80 + 76 = the paper's 156-unit feature extractor."""
    hidden_units: int = 32
    hidden_layers: int = 4
    lr: float = 1e-3
    entropy_weight: float = 1e-3
    batch_size: int = 64
    updates_per_episode: int | None = None
    """Gradient updates after each episode; None: one per step of the episode (τ)."""
    log_std_range: tuple[float, float] = (-7.0, 2.0)
    deterministic: bool = False
    """Roll out the Gaussian's mean instead of a sample."""
    time_input: bool = True
    """Whether the policy sees Time2Vec(t) beside the state (the paper's BC sees only s_t)."""
    state_dependent_std: bool = True
    """A log σ head on the hidden layer; False: one learned log σ per decision (`imitation`)."""
    epochs: int | None = None
    """None: τ updates after each episode on everything seen so far (ours). A number:
    `imitation`'s schedule, every episode's demonstrations first, then this many shuffled passes
    over them in batches of `batch_size`."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BCConfig:
        return cls(**{**data, "log_std_range": tuple(data["log_std_range"])})


BC_PAPER = BCConfig(time_input=False, state_dependent_std=False, batch_size=32, epochs=1)
"""BC as the paper ran it (`imitation`'s BC on the position only); see the module docstring."""


class BCPolicy(nn.Module):
    """E Gaussian policies p(a | s, t) (or p(a | s) without time input) as one ensemble:
    [E, B, ·] in, mean and log σ out."""

    def __init__(self, state_dim: int, decision_dim: int, cfg: BCConfig, seeds: Sequence[int]):
        super().__init__()
        self.cfg = cfg
        self.seeds = [int(s) for s in seeds]
        gens = [torch.Generator().manual_seed(s) for s in self.seeds]
        net = NetworkConfig(hidden_units=cfg.hidden_units, hidden_layers=cfg.hidden_layers)
        self.state_features = EnsembleLinear(state_dim, cfg.state_features, gens)
        self.time2vec = Time2Vec(cfg.time_embedding_dim, gens) if cfg.time_input else None
        widths = [cfg.state_features]
        if cfg.time_input:
            widths += [1, cfg.time_embedding_dim - 1]
        self.hidden = MLPTrunk(widths, net, gens, nn.Tanh())
        self.mean = EnsembleLinear(cfg.hidden_units, decision_dim, gens)
        self.log_std: nn.Module | nn.Parameter
        if cfg.state_dependent_std:
            self.log_std = EnsembleLinear(cfg.hidden_units, decision_dim, gens)
        else:
            self.log_std = nn.Parameter(torch.zeros(len(gens), 1, decision_dim))

    @property
    def feature_width(self) -> int:
        return self.cfg.state_features + self.cfg.time_embedding_dim * self.cfg.time_input

    def forward(self, state: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
        """Mean and log σ [E, B, k] of the decision given the state [E, B, d] and t [E, B, 1]
        (t is ignored without time input)."""
        time = self.time2vec(t) if self.time2vec is not None else []
        h = self.hidden([torch.tanh(self.state_features(state)), *time])
        mean = self.mean(h)
        if isinstance(self.log_std, nn.Parameter):
            log_std = self.log_std.expand_as(mean)
        else:
            log_std = self.log_std(h)
        return mean, log_std.clamp(*self.cfg.log_std_range)

    def loss(self, state: Tensor, t: Tensor, action: Tensor) -> Tensor:
        """Per-member −mean log-likelihood − entropy_weight · mean entropy [E]."""
        mean, log_std = self(state, t)
        dist = torch.distributions.Normal(mean, log_std.exp())
        nll = -dist.log_prob(action).sum(-1).mean(-1)
        entropy = dist.entropy().sum(-1).mean(-1)
        return nll - self.cfg.entropy_weight * entropy


class BCTrainer(Trainer[BCPolicy]):
    """Trains E BC members, one per (environment, seed), as one ensemble; a step is one
    episode of every member (all stop together, after `BCConfig.episodes`)."""

    def __init__(
        self,
        envs: Sequence[TrajectoryImitationEnv],
        seeds: Sequence[int],
        config: BCConfig | None = None,
    ):
        super().__init__(envs, seeds)
        self.cfg = config or BCConfig()
        state_dim = envs[0].observation_space.shape[0] - 1
        self.policy = BCPolicy(state_dim, envs[0].action_space.shape[0], self.cfg, self.seeds)
        self.opt = torch.optim.Adam(self.policy.parameters(), lr=self.cfg.lr, fused=True)
        capacity = self.cfg.episodes * max(env.source.max_steps for env in envs)
        self.data = DemonstrationBuffer(
            len(envs), capacity, state_dim, envs[0].action_space.shape[0]
        )
        self.losses: list[np.ndarray] = []
        """Each episode's mean loss of its updates per member [E] (NaN without updates)."""

    def step(self) -> list[EpisodeLog]:
        """Draw one reference per member, add its pairs, then update (each episode, or after the
        last one with `epochs`); logs the mean loss of the updates made (NaN if none)."""
        first = self.episode[0] == 0
        steps = []
        for k, (env, seed) in enumerate(zip(self.envs, self.seeds, strict=True)):
            env.reset(seed=seed if first else None)
            steps.append(self.data.add(k, env))
        self.episode = [e + 1 for e in self.episode]
        mean = self._update(max(steps))
        self.losses.append(mean)
        logs = [
            EpisodeLog(
                k, seed, self.episode[k], n, float("nan"), float("nan"), float(loss), self.done
            )
            for k, (seed, n, loss) in enumerate(zip(self.seeds, steps, mean, strict=True))
        ]
        self.history += logs
        return logs

    def _update(self, steps: int) -> np.ndarray:
        """This episode's updates; the mean loss [E] of the updates made (NaN if none)."""
        cfg = self.cfg
        if cfg.epochs is None:
            updates = cfg.updates_per_episode or steps
            batches = (self.data.sample(cfg.batch_size, self.generators) for _ in range(updates))
        elif self.episode[0] == cfg.episodes:
            gens, size = self.generators, cfg.batch_size
            batches = (b for _ in range(cfg.epochs) for b in self.data.epoch(size, gens))
        else:
            batches = iter(())
        total, count = torch.zeros(len(self.envs)), 0
        for s, t, a in batches:
            loss = self.policy.loss(s, t, a)
            self.opt.zero_grad(set_to_none=True)
            loss.sum().backward()
            self.opt.step()
            total += loss.detach()
            count += 1
        return (total / count).numpy() if count else np.full(len(self.envs), np.nan)

    @property
    def done(self) -> bool:
        return self.episode[0] >= self.cfg.episodes

    def model(self) -> BCPolicy:
        return self.policy


def bc_act(policy: BCPolicy, refs: int, seed: int = 0) -> Act:
    """The BC ensemble as a batched policy over [E, R] observations; each (member, reference)
    pair samples from its own generator keyed by (seed, member seed, reference)."""
    gens = [[seed_generator(seed, s, r) for r in range(refs)] for s in policy.seeds]

    def draw(shape: torch.Size) -> Tensor:
        return torch.stack(
            [torch.stack([torch.randn(shape[-1], generator=g) for g in row]) for row in gens]
        )

    return lambda obs: sample_decisions(policy, obs, draw)


def sample_decisions(
    policy: BCPolicy, obs: np.ndarray, draw: Callable[[torch.Size], Tensor]
) -> np.ndarray:
    """BC's decisions [E, B, k] for observations [E, B, state + 1] (the state, then the time
    input): the Gaussian's mean with `BCConfig.deterministic`, else mean + σ · `draw(shape)`
    (standard normal noise of the mean's shape, from the caller's generators). The one place
    BC samples, for the self-test's rollouts (`bc_act`) and the AIS detector's."""
    state_dim = policy.state_features.weight.shape[1]
    x = torch.as_tensor(obs, dtype=torch.float32)
    with torch.no_grad():
        mean, log_std = policy(x[..., :state_dim], x[..., state_dim:])
    if policy.cfg.deterministic:
        return mean.numpy()
    return (mean + log_std.exp() * draw(mean.shape)).numpy()
