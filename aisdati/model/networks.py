"""DATI's networks as ensembles: every layer holds E members' weights and runs one batched matmul.

Tensors are shaped [E, B, features]. Member k is initialised from its own torch.Generator, in the
same order whatever E is, so an ensemble of seeds (s1, s2) starts exactly like two runs with E = 1;
since losses are summed over members and Adam is elementwise, training stays member-independent.

Architecture (section 4.1 and appendix A.2 of the paper; choices where it is silent are marked):
- every input (state, decision, latent noise) goes through its own 16-unit tanh feature layer;
- the step index t goes through one Time2Vec layer of dimension 76 (75 periodic + 1 linear
  features), shared by the four networks of a member: it is evaluated once per batch by
  `DATINetworks.time_features` and its feature blocks are passed to the networks;
- actors: 4 hidden layers of 32 tanh units, tanh output;
- critics: the reward r ∈ {-1, +1} is tiled to the width of the other features, passed through a
  linear layer whose kernel is kept non-negative (so the critic's value rises with the reward),
  and concatenated with them; 4 hidden layers of 32 LeakyReLU(0.2) units, elu output.
- weights start Glorot-uniform with zero biases (Keras' defaults, as in the paper's code).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import torch
from torch import Tensor, nn


@dataclass(frozen=True)
class NetworkConfig:
    """Sizes of DATI's networks; the defaults are the paper's."""

    feature_units: int = 16
    time_embedding_dim: int = 76
    latent_dim: int = 64
    hidden_units: int = 32
    hidden_layers: int = 4
    time_embedding: bool = True
    """Ablation switch (Table 2): without it the networks get no time input."""
    reward_input: bool = True
    """Ablation switch (Table 2): without it the critics do not see the reward."""


def _glorot_(weight: Tensor, generators: Sequence[torch.Generator]) -> None:
    """Glorot-uniform initialisation of each member's [in, out] slice from its own generator."""
    fan_in, fan_out = weight.shape[-2], weight.shape[-1]
    bound = math.sqrt(6.0 / (fan_in + fan_out))
    with torch.no_grad():
        for k, gen in enumerate(generators):
            weight[k].uniform_(-bound, bound, generator=gen)


class EnsembleLinear(nn.Module):
    """y = x W_k + b_k for each member k, as one batched matmul over [E, B, in]."""

    def __init__(self, in_features: int, out_features: int, generators: Sequence[torch.Generator]):
        super().__init__()
        members = len(generators)
        self.weight = nn.Parameter(torch.empty(members, in_features, out_features))
        self.bias = nn.Parameter(torch.zeros(members, 1, out_features))
        _glorot_(self.weight, generators)

    def forward(self, x: Tensor) -> Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


class SplitLinear(nn.Module):
    """A linear layer over the concatenation of several feature blocks, holding one weight block
    per input block: the same function (initialised as one Glorot draw over the whole fan-in)
    without materialising the concatenation, and the gradient with respect to one block (the
    critics' gradient penalty) never touches the others."""

    def __init__(self, widths: Sequence[int], out_features: int, gens: Sequence[torch.Generator]):
        super().__init__()
        full = torch.empty(len(gens), sum(widths), out_features)
        _glorot_(full, gens)
        self.weights = nn.ParameterList(
            nn.Parameter(block.clone()) for block in torch.split(full, list(widths), dim=1)
        )
        self.bias = nn.Parameter(torch.zeros(len(gens), 1, out_features))

    def forward(self, parts: Sequence[Tensor]) -> Tensor:
        """Sum of the blocks' products; weight blocks past len(parts) are left to the caller
        (the critics apply their reward block as a rank-one term)."""
        out = self.bias
        # zip stops at the last part: a slice of the ParameterList would build a new module
        # (and register its parameters) at every call, a twentieth of a training's time
        for part, weight in zip(parts, self.weights, strict=False):
            out = torch.baddbmm(out, part, weight)
        return out


class NonNegativeLinear(EnsembleLinear):
    """A linear layer whose kernel is kept non-negative (Keras' NonNeg constraint): it starts as
    |Glorot| and `project_` clips it back to >= 0 after every optimiser step."""

    def __init__(self, in_features: int, out_features: int, generators: Sequence[torch.Generator]):
        super().__init__(in_features, out_features, generators)
        with torch.no_grad():
            self.weight.abs_()

    def project_(self) -> None:
        with torch.no_grad():
            self.weight.clamp_(min=0.0)

    def tiled_then(self, r: Tensor, following: Tensor) -> Tensor:
        """(tile(r) W + b) V for r [E, B, 1] tiled to the input width and a following weight
        slice V: since tile(r) W = r (1ᵀW), this is r (1ᵀW V) + b V, a rank-one product that
        never materialises the tiled reward (the same function, far cheaper)."""
        col = self.weight.sum(dim=1, keepdim=True)
        return torch.baddbmm(torch.bmm(self.bias, following), r, torch.bmm(col, following))


class Time2Vec(nn.Module):
    """Time2Vec (Kazemi et al. 2019): one linear and dim - 1 periodic (sin) features of t.

    Initialised uniformly in [-0.05, 0.05] (Keras' "uniform"), which keeps the periodic features
    slow over the few hundred to few thousand steps of an episode."""

    def __init__(self, dim: int, generators: Sequence[torch.Generator]):
        super().__init__()
        members = len(generators)
        self.freq = nn.Parameter(torch.empty(members, 1, dim))
        self.phase = nn.Parameter(torch.empty(members, 1, dim))
        with torch.no_grad():
            for k, gen in enumerate(generators):
                self.freq[k].uniform_(-0.05, 0.05, generator=gen)
                self.phase[k].uniform_(-0.05, 0.05, generator=gen)

    def forward(self, t: Tensor) -> list[Tensor]:
        """The [linear, periodic] feature blocks of t [E, B, 1], kept apart (no concatenation)."""
        lin = torch.baddbmm(self.phase[..., :1], t, self.freq[..., :1])
        per = torch.sin(torch.baddbmm(self.phase[..., 1:], t, self.freq[..., 1:]))
        return [lin, per]


class MLPTrunk(nn.Module):
    """The hidden layers: a `SplitLinear` over the input blocks, then hidden_layers - 1 more."""

    def __init__(
        self,
        widths: Sequence[int],
        cfg: NetworkConfig,
        gens: Sequence[torch.Generator],
        act: nn.Module,
    ):
        super().__init__()
        self.first = SplitLinear(widths, cfg.hidden_units, gens)
        layers: list[nn.Module] = [act]
        for _ in range(cfg.hidden_layers - 1):
            layers += [EnsembleLinear(cfg.hidden_units, cfg.hidden_units, gens), act]
        self.rest = nn.Sequential(*layers)

    def forward(self, parts: Sequence[Tensor], extra: Tensor | None = None) -> Tensor:
        """`extra` is added to the first layer's pre-activation (the critics' reward term)."""
        h = self.first(parts)
        return self.rest(h if extra is None else h + extra)


def _time_widths(cfg: NetworkConfig) -> list[int]:
    return [1, cfg.time_embedding_dim - 1] if cfg.time_embedding else []


class Actor(nn.Module):
    """π(x, η, t) -> y in [-1, 1]: the forward actor maps states to decisions, the backward
    actor decisions to states; both have this shape."""

    def __init__(
        self, in_dim: int, out_dim: int, cfg: NetworkConfig, gens: Sequence[torch.Generator]
    ):
        super().__init__()
        self.input_features = EnsembleLinear(in_dim, cfg.feature_units, gens)
        self.noise_features = EnsembleLinear(cfg.latent_dim, cfg.feature_units, gens)
        widths = [cfg.feature_units, cfg.feature_units, *_time_widths(cfg)]
        self.hidden = MLPTrunk(widths, cfg, gens, nn.Tanh())
        self.out = EnsembleLinear(cfg.hidden_units, out_dim, gens)

    def forward(self, x: Tensor, noise: Tensor, time: list[Tensor]) -> Tensor:
        """`time` holds the shared Time2Vec feature blocks of t (empty without time embedding)."""
        feats = [torch.tanh(self.input_features(x)), torch.tanh(self.noise_features(noise)), *time]
        return torch.tanh(self.out(self.hidden(feats)))


class Critic(nn.Module):
    """c(y, r, t) -> value: the Wasserstein critic of an actor's outputs, told the reward."""

    def __init__(self, in_dim: int, cfg: NetworkConfig, gens: Sequence[torch.Generator]):
        super().__init__()
        self.input_features = EnsembleLinear(in_dim, cfg.feature_units, gens)
        widths = [cfg.feature_units, *_time_widths(cfg)]
        other = sum(widths)
        self.reward_features = NonNegativeLinear(other, other, gens) if cfg.reward_input else None
        if cfg.reward_input:
            widths.append(other)
        self.hidden = MLPTrunk(widths, cfg, gens, nn.LeakyReLU(0.2))
        self.out = EnsembleLinear(cfg.hidden_units, 1, gens)

    def forward(self, x: Tensor, reward: Tensor, time: list[Tensor]) -> Tensor:
        feats = [torch.tanh(self.input_features(x)), *time]
        extra = None
        if self.reward_features is not None:
            extra = self.reward_features.tiled_then(reward, self.hidden.first.weights[-1])
        return nn.functional.elu(self.out(self.hidden(feats, extra)))


class DATINetworks(nn.Module):
    """The four networks of E DATI members and their shared Time2Vec layers."""

    def __init__(self, state_dim: int, decision_dim: int, cfg: NetworkConfig, seeds: Sequence[int]):
        super().__init__()
        self.cfg = cfg
        self.seeds = list(seeds)
        gens = [torch.Generator().manual_seed(int(s)) for s in seeds]
        self.time2vec = Time2Vec(cfg.time_embedding_dim, gens) if cfg.time_embedding else None
        self.forward_actor = Actor(state_dim, decision_dim, cfg, gens)
        self.backward_actor = Actor(decision_dim, state_dim, cfg, gens)
        self.forward_critic = Critic(decision_dim, cfg, gens)
        self.backward_critic = Critic(state_dim, cfg, gens)

    def time_features(self, t: Tensor) -> list[Tensor]:
        """Time2Vec blocks of the step index t [E, B, 1], computed once and fed to every network
        that sees the same t (the layer is shared, so this is the same function, evaluated once)."""
        return self.time2vec(t) if self.time2vec is not None else []

    @property
    def members(self) -> int:
        return len(self.seeds)

    @property
    def device(self) -> torch.device:
        """Where the networks are: every rollout runs there (`aisdati.execution.device`)."""
        return self.forward_actor.out.weight.device

    @property
    def state_dim(self) -> int:
        return self.forward_actor.input_features.weight.shape[1]

    @property
    def decision_dim(self) -> int:
        return self.forward_actor.out.weight.shape[2]

    def decide(self, obs: Tensor, noise: Tensor) -> Tensor:
        """The forward actors' decisions [E, B, k] (scaled into [-1, 1]) for observations
        [E, B, state + 1] (the state features, then the time input) and latent noise
        [E, B, latent], without gradient: how the trainer and every rollout act."""
        state, t = obs[..., : self.state_dim], obs[..., self.state_dim :]
        with torch.no_grad():
            time = self.time_features(t.contiguous())
            return self.forward_actor(state.contiguous(), noise, time)

    def critic_parameters(self) -> list[nn.Parameter]:
        return [
            *self.forward_critic.parameters(),
            *self.backward_critic.parameters(),
            *self.time2vec_parameters(),
        ]

    def policy_parameters(self) -> list[nn.Parameter]:
        """What a rollout needs: the forward actor and its Time2Vec."""
        return [*self.forward_actor.parameters(), *self.time2vec_parameters()]

    def project_(self) -> None:
        """Re-impose the critics' non-negative reward kernels after an optimiser step."""
        for critic in (self.forward_critic, self.backward_critic):
            if critic.reward_features is not None:
                critic.reward_features.project_()

    def time2vec_parameters(self) -> list[nn.Parameter]:
        """The shared Time2Vec layer's parameters (none without time embedding)."""
        return list(self.time2vec.parameters()) if self.time2vec is not None else []


def slice_members(nets: nn.Module, keep: list[int]) -> dict[nn.Parameter, nn.Parameter]:
    """Replace every parameter of `nets` by a new one holding members `keep`; returns old ->
    new. New parameter objects, not `p.data = ...`: a parameter keeps its gradient accumulator
    (with the shape it had) while any autograd graph still refers to it, and a graph left
    alive by a reference cycle would make the next backward fail on the old member count."""
    sliced = {}
    for module in nets.modules():
        for name, p in list(module.named_parameters(recurse=False)):
            new = nn.Parameter(p.detach()[keep].clone(), requires_grad=p.requires_grad)
            setattr(module, name, new)
            sliced[p] = new
    return sliced


Ensemble = TypeVar("Ensemble", bound=nn.Module)


def one_member(nets: Ensemble, member: int) -> Ensemble:
    """A copy of an ensemble's networks holding member `member` alone. Acting as one member
    (a cross-fitted calibration, member-wise scores, validation) through the whole ensemble
    computes every member's layers on every row and keeps one member's: M times the work, and
    M members scored in turn M^2 times (the area default's member-wise `stepspread` of 1,000
    tracks took 128.9 s that way, 55.9 s this way; docs/performance.md)."""
    single = copy.deepcopy(nets)
    slice_members(single, [member])
    if hasattr(single, "seeds"):  # DATI's networks and BC's policy name their members' seeds
        single.seeds = [single.seeds[member]]
    return single
