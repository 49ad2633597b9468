"""DATI: the cycle-consistent Wasserstein actor-critic of section 4, trained as a batched ensemble.

One `DATITrainer` trains E independent members (one per seed, each with its own environment,
replay buffer, noise and random streams) in lockstep: every layer holds the E members' weights,
losses are summed over members, and one Adam per role over the stacked parameters behaves as E
independent optimisers because Adam is elementwise. E = 1 is a plain single run; E = 40 trains the
paper's 4 families x 10 seeds at once. Members that stop early are dropped from the ensemble so
their compute is not wasted.

Per environment step and member (section 4 and appendix A.2):
1. one batch of 64 transitions (ŝ_t, â_t, a_t, r_t, η_t, t) from the replay buffer;
2. 5 critic updates on it: WGAN-GP for c→ (real: perfect decisions a_t, fake: π→(ŝ_t, η_t, t))
   and c← (real: the agent's own states ŝ_t, fake: π←(â_t, η_t, t)), λ = 10;
3. one adversarial update of both actors (maximise their critics' values), then one update of
   the L1 terms, weight 10 each: ‖π←(π→(ŝ)) − ŝ‖₁ + ‖π→(ŝ) − a‖₁ + ‖π→(π←(â)) − â‖₁;
4. the forward actor acts from ŝ_t with fresh latent noise, the environment moves it and reveals
   the reference's next point, and the transition is stored.
Early stopping watches each member's own per-episode mean total loss (patience 10) and keeps the
forward actor (with its Time2Vec) of the best episode; `keep="final"` keeps the last episode's
instead (what the paper's code ends up doing: the self-test's `paper` preset).

Choices where the paper is silent (all configurable, see `DATIConfig`): the gradient penalty
interpolates between real samples and the *current* actor's fakes (Gulrajani et al.); the L1 terms
use Adam with its default β = (0.9, 0.999), as the paper's code does; the replay buffer starts
with `batch_size` near-perfect decisions on the member's first reference (the paper's code warms
up this way), their latent noise drawn like the real noise.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
import torch
from torch import Tensor

from aisdati.model.buffers import EnsembleReplayBuffer
from aisdati.model.env import Reference, TrajectoryImitationEnv
from aisdati.model.networks import DATINetworks, NetworkConfig, slice_members
from aisdati.model.noise import LatentNoise, NoiseProcess
from aisdati.model.trainer import EpisodeLog, Trainer

KEPT_PARAMETERS = ("forward_actor.", "time2vec.")
"""What a member ends with."""
WARMUP_SPREAD = 5.0 / 180.0
"""Spread of the warm-up decisions around the perfect ones, in scaled units (5° of heading)."""


REMOVED_SETTINGS = {"pretrain_variety": 1, "actor_average": 0.0}
"""Settings of earlier releases, measured and not adopted (docs/results/tried.md), with the value
that meant "off", at which a saved configuration still loads."""
REMOVED_NETWORK_SETTINGS = {"conditional_critic": False}


@dataclass(frozen=True)
class DATIConfig:
    """Hyperparameters of DATI; every default is the paper's (appendix A.2) unless noted."""

    network: NetworkConfig = field(default_factory=NetworkConfig)
    episodes: int = 100
    batch_size: int = 64
    buffer_capacity: int = 50_000
    critic_steps: int = 5
    gradient_penalty: float = 10.0
    l1_weight: float = 10.0
    lr_actor: float = 1e-4
    lr_critic: float = 1e-5
    lr_l1: float = 1e-3
    betas: tuple[float, float] = (0.5, 0.9)
    l1_betas: tuple[float, float] = (0.9, 0.999)
    """Not stated in the paper; its code leaves Adam's defaults for the L1 terms."""
    noise: str = "gaussian"
    """Latent noise process: "gaussian" or "ou" (Ornstein-Uhlenbeck); the paper picks the better."""
    noise_sigma: float = 0.3
    ou_theta: float = 0.15
    ou_dt: float = 1e-2
    patience: int = 10
    """Early stopping on the episode's total loss; 0 disables it."""
    keep: str = "best"
    """Which forward actor a member ends with: "best" (lowest episode metric) or "final"."""
    pretrain_epochs: int = 0
    """Passes of the forward actor's L1 pull over the references' own (state, perfect decision)
    pairs before the adversarial training (`DATITrainer.pretrain`). 0 is the paper's way, random
    actors; a warm start is a departure (as GAIL is often started from BC) that the AIS lanes
    measure."""
    adversarial_time2vec: bool = True
    """Whether the actors' adversarial loss also updates the shared Time2Vec (through the
    critics' time features). The paper's code freezes it there (critic.trainable = False when
    compiling the GAN); the critic and L1 losses update it either way."""

    def __post_init__(self) -> None:
        if self.keep not in ("best", "final"):
            raise ValueError(f"keep must be 'best' or 'final', got {self.keep!r}")

    @property
    def noise_process(self) -> NoiseProcess:
        return NoiseProcess(self.noise, self.ou_dt)

    def latent_noise(
        self,
        generators: Sequence[torch.Generator],
        processes: Sequence[NoiseProcess] | None = None,
        rows: int = 1,
    ) -> LatentNoise:
        """Latent noise of this configuration's width and σ for one stream per generator, each
        with its process (default: the configuration's), `rows` rows per stream."""
        processes = list(processes or [self.noise_process] * len(generators))
        dim = self.network.latent_dim
        return LatentNoise(generators, processes, dim, self.noise_sigma, self.ou_theta, rows)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DATIConfig:
        """A saved configuration; a setting removed since (`REMOVED_SETTINGS`) is dropped where
        it is at the paper's value, refused where it is not."""
        data = dict(data)
        network = dict(data.pop("network", {}))
        for where, removed in ((data, REMOVED_SETTINGS), (network, REMOVED_NETWORK_SETTINGS)):
            for key, off in removed.items():
                if key in where and where.pop(key) != off:
                    raise ValueError(f"{key} was removed (measured, not adopted): retrain")
        net = NetworkConfig(**network)
        for key in ("betas", "l1_betas"):
            if key in data:
                data[key] = tuple(data[key])
        return cls(network=net, **data)

    def with_network(self, **changes: Any) -> DATIConfig:
        return replace(self, network=replace(self.network, **changes))


def gradient_penalty(
    critic: Callable[..., Tensor],
    real: Tensor,
    fake: Tensor,
    reward: Tensor,
    t: list[Tensor],
    u: Tensor,
) -> Tensor:
    """Per-member mean of (‖∇_x c(x̂)‖₂ − 1)² at x̂ = u·real + (1−u)·fake, one u per sample."""
    x = (u * real + (1 - u) * fake).requires_grad_(True)
    (grad,) = torch.autograd.grad(critic(x, reward, t).sum(), x, create_graph=True)
    return ((grad.norm(dim=-1) - 1) ** 2).mean(dim=1)


class DATITrainer(Trainer[DATINetworks]):
    """Trains E DATI members, one per (environment, seed) pair, as one batched ensemble."""

    def __init__(
        self,
        envs: Sequence[TrajectoryImitationEnv],
        seeds: Sequence[int],
        config: DATIConfig | None = None,
        validate: Callable[[DATITrainer, int], float] | None = None,
        noise: Sequence[NoiseProcess] | None = None,
        device: str = "cpu",
    ):
        """`validate(trainer, k)`, when given, scores live member k at the end of each of its
        episodes (lower is better); the best actor and early stopping then follow that score
        instead of the episode's loss (the AIS training's validator scores the DTW of the
        actor's rollouts on validation tracks). `noise` gives each member its own latent noise
        process (default: the config's). `device` is where the networks, their optimisers
        and the replay buffer live (`aisdati.execution.device`): every random draw is still
        taken on the CPU from the members' generators and moved there, so a member trains the
        same on any device up to the device's float rounding."""
        super().__init__(envs, seeds)
        self.cfg = config or DATIConfig()
        self.device = torch.device(device)
        self.validate = validate
        self.state_dim = envs[0].observation_space.shape[0] - 1
        self.decision_dim = envs[0].action_space.shape[0]
        self.nets = DATINetworks(self.state_dim, self.decision_dim, self.cfg.network, self.seeds)
        self.nets.to(self.device)
        self.final = copy.deepcopy(self.nets)  # receives each member's best forward actor
        self._build_optimizers()
        # member-indexed state (envs, generators, noise, buffer, the running episodes),
        # compacted together when members leave the ensemble
        self.active = list(range(len(seeds)))
        """The members still training, by their index in `seeds`."""
        self.noise = self.cfg.latent_noise(self.generators, noise)
        dims = {
            "state": self.state_dim,
            "action": self.decision_dim,
            "perfect": self.decision_dim,
            "reward": 1,
            "noise": self.cfg.network.latent_dim,
            "time": 1,
        }
        self.buffer = EnsembleReplayBuffer(len(seeds), self.cfg.buffer_capacity, dims, self.device)
        n = len(seeds)
        self.best_loss = [float("inf")] * n
        self.wait = [0] * n
        self.best_episode = [0] * n
        self.pretrained_metric: list[float | None] = [None] * n
        """Each member's validation score right after `pretrain` (None without it)."""
        self._obs = [env.reset(seed=s)[0] for env, s in zip(self.envs, self.seeds, strict=True)]
        self._episode_loss = [0.0] * n
        self._episode_reward = [0.0] * n
        self._episode_steps = [0] * n
        self._warmup()

    # ------------------------------------------------------------------ setup
    def _build_optimizers(self) -> None:
        c, nets = self.cfg, self.nets
        actors = [
            *nets.forward_actor.parameters(),
            *nets.backward_actor.parameters(),
            *nets.time2vec_parameters(),
        ]
        self.opt_critic = torch.optim.Adam(
            nets.critic_parameters(), lr=c.lr_critic, betas=c.betas, fused=True
        )
        self.opt_actor = torch.optim.Adam(actors, lr=c.lr_actor, betas=c.betas, fused=True)
        self.opt_l1 = torch.optim.Adam(actors, lr=c.lr_l1, betas=c.l1_betas, fused=True)

    def _warmup(self) -> None:
        """Seed each member's buffer with `batch_size` near-perfect decisions on its first
        reference, so that training can start at the first step."""
        b = self.cfg.batch_size
        rows: dict[str, list[Tensor]] = {k: [] for k in self.buffer.fields}
        for k, env in enumerate(self.envs):
            gen = self.generators[k]
            ref = env.reference
            perm = torch.randperm(ref.steps, generator=gen)
            steps = torch.cat([torch.tensor([0]), perm[perm != 0]])[:b]
            steps = steps.repeat(-(-b // len(steps)))[:b]
            perfect = torch.as_tensor(env.perfect_actions[steps.numpy()], dtype=torch.float32)
            spread = torch.randn(perfect.shape, generator=gen) * WARMUP_SPREAD
            spread[0] = 0.0
            states = env.source.reference_states(ref)[steps.numpy()]
            rows["state"].append(torch.as_tensor(states, dtype=torch.float32))
            rows["action"].append((perfect + spread).clamp(-1, 1))
            rows["perfect"].append(perfect)
            ok = spread.abs().amax(dim=1, keepdim=True) < WARMUP_SPREAD
            rows["reward"].append(torch.where(ok, 1.0, -1.0))
            rows["noise"].append(torch.cat([self.noise.draw(k) for _ in range(b)]))
            time = env.source.time_input(steps.numpy(), ref.steps)
            rows["time"].append(torch.as_tensor(time, dtype=torch.float32)[:, None])
        stacked = {key: torch.stack(v) for key, v in rows.items()}
        for i in range(b):
            self.buffer.add(**{key: v[:, i] for key, v in stacked.items()})

    # --------------------------------------------------------------- training
    def train_batch(self) -> Tensor:
        """One training batch per member; returns each member's total loss [E]."""
        c, nets = self.cfg, self.nets
        batch = self.buffer.sample(c.batch_size, self.generators)
        s, a_hat, a_real = batch["state"], batch["action"], batch["perfect"]
        r, eta, step = batch["reward"], batch["noise"], batch["time"]

        for p in nets.critic_parameters():
            p.requires_grad_(True)
        for _ in range(c.critic_steps):
            t = nets.time_features(step)
            with torch.no_grad():
                fake_a = nets.forward_actor(s, eta, t)
                fake_s = nets.backward_actor(a_hat, eta, t)
            u_f = torch.stack([torch.rand(c.batch_size, 1, generator=g) for g in self.generators])
            u_b = torch.stack([torch.rand(c.batch_size, 1, generator=g) for g in self.generators])
            u_f, u_b = u_f.to(self.device), u_b.to(self.device)
            cf, cb = nets.forward_critic, nets.backward_critic
            real_f, fake_f, real_b, fake_b = a_real, fake_a, s, fake_s
            loss_f = (cf(fake_f, r, t).mean(1) - cf(real_f, r, t).mean(1)).squeeze(-1)
            loss_b = (cb(fake_b, r, t).mean(1) - cb(real_b, r, t).mean(1)).squeeze(-1)
            loss_f = loss_f + c.gradient_penalty * gradient_penalty(cf, real_f, fake_f, r, t, u_f)
            loss_b = loss_b + c.gradient_penalty * gradient_penalty(cb, real_b, fake_b, r, t, u_b)
            critic_loss = loss_f + loss_b
            self.opt_critic.zero_grad(set_to_none=True)
            critic_loss.sum().backward()
            self.opt_critic.step()
            nets.project_()

        for p in nets.critic_parameters():
            p.requires_grad_(False)
        if nets.time2vec is not None and c.adversarial_time2vec:
            nets.time2vec.requires_grad_(True)
        t = nets.time_features(step)
        gen_a = nets.forward_actor(s, eta, t)
        gen_s = nets.backward_actor(a_hat, eta, t)
        adv = -(
            nets.forward_critic(gen_a, r, t).mean(1) + nets.backward_critic(gen_s, r, t).mean(1)
        )
        adv = adv.squeeze(-1)
        self.opt_actor.zero_grad(set_to_none=True)
        adv.sum().backward()
        self.opt_actor.step()

        if nets.time2vec is not None:
            nets.time2vec.requires_grad_(True)
        l1 = self._l1_step(s, a_hat, a_real, eta, step)
        return critic_loss.detach() + adv.detach() + l1

    def _l1_step(
        self, s: Tensor, a_hat: Tensor, a_real: Tensor, eta: Tensor, step: Tensor
    ) -> Tensor:
        """One update of the L1 terms (cycle consistency both ways and the pull towards the
        perfect decisions); returns each member's weighted L1 loss [E]."""
        nets = self.nets
        t = nets.time_features(step)
        fa = nets.forward_actor(s, eta, t)
        back = nets.backward_actor(a_hat, eta, t)
        l1 = (
            (nets.backward_actor(fa, eta, t) - s).abs().mean(dim=(1, 2))
            + (fa - a_real).abs().mean(dim=(1, 2))
            + (nets.forward_actor(back, eta, t) - a_hat).abs().mean(dim=(1, 2))
        ) * self.cfg.l1_weight
        self.opt_l1.zero_grad(set_to_none=True)
        l1.sum().backward()
        self.opt_l1.step()
        return l1.detach()

    def pretrain(self, demonstrations: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> None:
        """`pretrain_epochs` passes of the forward actor's pull towards the perfect decisions
        over each member's references as demonstrated (states [n, d], time inputs [n], scaled
        perfect decisions [n, k]; one tuple per member): behaviour cloning by L1, with the
        L1 terms' optimiser. Each member draws its batches with replacement from its own pairs,
        as many batches as an epoch of the largest member. The cycle terms are left out: the
        untrained backward actor's states would teach the forward actor to ignore the state.
        With a validator the pretrained actor is scored and kept as episode 0's.
        Call before the first step (`DATIConfig.pretrain_epochs`)."""
        c, nets = self.cfg, self.nets
        if not c.pretrain_epochs:
            return
        if len(demonstrations) != len(self.active) or self.history:
            raise ValueError("pretrain once, before training, with one demonstration per member")
        data = [
            [torch.as_tensor(x, dtype=torch.float32, device=self.device) for x in d]
            for d in demonstrations
        ]
        updates = c.pretrain_epochs * -(-max(len(d[0]) for d in data) // c.batch_size)
        for _ in range(updates):
            picks = [
                torch.randint(len(d[0]), (c.batch_size,), generator=g).to(self.device)
                for d, g in zip(data, self.generators, strict=True)
            ]
            s, step, a = (
                torch.stack([d[i][p] for d, p in zip(data, picks, strict=True)]) for i in range(3)
            )
            t = nets.time_features(step[..., None])
            eta = torch.stack([self.noise.draw(m, c.batch_size) for m in range(len(data))])
            eta = eta.to(self.device)
            pull = (nets.forward_actor(s, eta, t) - a).abs().mean(dim=(1, 2))
            self.opt_l1.zero_grad(set_to_none=True)
            (pull.sum() * c.l1_weight).backward()
            self.opt_l1.step()
        if self.validate is not None:
            # the warm start is a candidate like any episode's actor (episode 0): the
            # adversarial training must beat it on validation to replace it
            for k in range(len(data)):
                metric = self.validate(self, k)
                self.pretrained_metric[k] = self.best_loss[k] = metric
                self._save_best(k)

    def _act(self) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """Every member's state, decision, latent noise and time input, on the CPU (where the
        environments step)."""
        obs = torch.as_tensor(np.stack(self._obs), dtype=torch.float32)[:, None, :]
        eta = self.noise.sample()
        action = self.nets.decide(obs.to(self.device), eta.to(self.device)).cpu()
        state, t = obs[:, 0, : self.state_dim], obs[:, 0, self.state_dim :]
        return state, action[:, 0], eta[:, 0], t

    def step(self) -> list[EpisodeLog]:
        """One environment step of every active member (with its training batch first)."""
        losses = self.train_batch().cpu()
        state, action, eta, t = self._act()
        rewards, perfect, ended = [], [], []
        for k, env in enumerate(self.envs):
            obs, reward, terminated, truncated, info = env.step(action[k].numpy())
            self._obs[k] = obs
            rewards.append(reward)
            perfect.append(info["perfect_action"])
            self._episode_loss[k] += float(losses[k])
            self._episode_reward[k] += reward
            self._episode_steps[k] += 1
            if terminated or truncated:
                ended.append((k, info["dtw_smoothed"]))
        self.buffer.add(
            state=state,
            action=action,
            perfect=torch.as_tensor(np.stack(perfect)),
            reward=torch.tensor(rewards, dtype=torch.float32)[:, None],
            noise=eta,
            time=t,
        )
        logs = [self._end_episode(k, dtw) for k, dtw in ended]
        self.remove_members([k for (k, _), log in zip(ended, logs, strict=True) if log.stopped])
        return logs

    def running_episode(self, k: int) -> tuple[int, float]:
        """Steps taken and mean reward so far in active member k's current episode (for
        progress bars: the episode's log exists only once it ends)."""
        steps = self._episode_steps[k]
        return steps, self._episode_reward[k] / max(steps, 1)

    def _end_episode(self, k: int, final_dtw: float) -> EpisodeLog:
        member = self.active[k]
        steps = self._episode_steps[k]
        mean_loss = self._episode_loss[k] / steps
        self.episode[member] += 1
        metric = mean_loss if self.validate is None else self.validate(self, k)
        improved = metric < self.best_loss[member]
        if improved:
            self.best_loss[member] = metric
            self.best_episode[member] = self.episode[member]
            self.wait[member] = 0
        else:
            self.wait[member] += 1
        patience_out = 0 < self.cfg.patience <= self.wait[member]
        stopped = patience_out or self.episode[member] >= self.cfg.episodes
        if (improved and self.cfg.keep == "best") or (stopped and self.cfg.keep == "final"):
            self._save_best(k)
        log = EpisodeLog(
            member,
            self.seeds[member],
            self.episode[member],
            steps,
            self._episode_reward[k] / steps,
            final_dtw,
            mean_loss,
            stopped,
            None if self.validate is None else metric,
        )
        self.history.append(log)
        self._episode_loss[k], self._episode_reward[k], self._episode_steps[k] = 0.0, 0.0, 0
        if not stopped:
            self._obs[k] = self.envs[k].reset()[0]
            self.noise.reset(k)
        return log

    def _save_best(self, k: int) -> None:
        """Copy member k's live forward actor and Time2Vec into the final networks (the
        kept one)."""
        member = self.active[k]
        live = dict(self.nets.named_parameters())
        with torch.no_grad():
            for name, p in self.final.named_parameters():
                if name.startswith(KEPT_PARAMETERS):
                    p[member].copy_(live[name][k])

    def remove_members(self, leaving: list[int]) -> None:
        """Remove active members `leaving` (positions in `active`) from the ensemble: slice
        weights, optimiser state, buffers, noise and the running episodes."""
        if not leaving:
            return
        keep = [k for k in range(len(self.active)) if k not in leaving]
        self.active = [self.active[k] for k in keep]
        if not keep:
            return
        sliced = slice_members(self.nets, keep)
        for opt in (self.opt_critic, self.opt_actor, self.opt_l1):
            for group in opt.param_groups:
                group["params"] = [sliced[p] for p in group["params"]]
            for old, new in sliced.items():
                st = opt.state.pop(old, None)
                if st:
                    for key in ("exp_avg", "exp_avg_sq"):
                        st[key] = st[key][keep].clone()
                    opt.state[new] = st
        self.envs = [self.envs[k] for k in keep]
        self._obs = [self._obs[k] for k in keep]
        self.generators = [self.generators[k] for k in keep]
        self.noise.keep(keep)
        self.buffer.keep(keep)
        for lst in (self._episode_loss, self._episode_reward, self._episode_steps):
            lst[:] = [lst[k] for k in keep]

    # ---------------------------------------------------------------- resume
    def state_dict(self) -> dict[str, Any]:
        """Everything the next steps depend on, taken between two steps: the live and final
        networks, the three Adam optimisers, the replay buffer, every random stream
        (the members' generators, which also drive their latent noise, and the environments'
        numpy generators), the latent noise, the episode counters, the early-stopping state,
        the history, the current observations and each environment's running episode. Only
        tensors, lists, dicts and numbers, so it loads with `torch.load(weights_only=True)`.
        The references the environments are on are the caller's to save: see
        `load_state_dict`."""
        buffer = self.buffer.state_dict()
        return {
            "nets": self.nets.state_dict(),
            "final": self.final.state_dict(),
            "opt_critic": self.opt_critic.state_dict(),
            "opt_actor": self.opt_actor.state_dict(),
            "opt_l1": self.opt_l1.state_dict(),
            "buffer": buffer["data"],
            "buffer_size": buffer["size"],
            "buffer_ptr": buffer["ptr"],
            "generators": [g.get_state() for g in self.generators],
            "env_rng": [env.np_random.bit_generator.state for env in self.envs],
            "env_episodes": [
                _map_leaves(env.episode_state(), np.ndarray, torch.as_tensor) for env in self.envs
            ],
            "noise": self.noise.state.clone(),
            "active": list(self.active),
            "episode": list(self.episode),
            "best_loss": list(self.best_loss),
            "wait": list(self.wait),
            "best_episode": list(self.best_episode),
            "pretrained_metric": list(self.pretrained_metric),
            "history": [dict(log.__dict__) for log in self.history],
            "obs": [torch.as_tensor(o) for o in self._obs],
            "episode_loss": list(self._episode_loss),
            "episode_reward": list(self._episode_reward),
            "episode_steps": list(self._episode_steps),
        }

    def load_state_dict(self, state: dict[str, Any], references: Sequence[Reference]) -> None:
        """Continue exactly from `state_dict`, in a trainer freshly built with the same
        environments, seeds and configuration; `references[k]` is the reference that active
        member k's environment was on (each environment is reset onto it, then given its
        running episode: the members of an ensemble end their episodes at different steps)."""
        active = [int(a) for a in state["active"]]
        if len(active) < len(self.active):
            self.remove_members([k for k, m in enumerate(self.active) if m not in active])
        self.nets.load_state_dict(state["nets"])
        self.final.load_state_dict(state["final"])
        self.opt_critic.load_state_dict(state["opt_critic"])
        self.opt_actor.load_state_dict(state["opt_actor"])
        self.opt_l1.load_state_dict(state["opt_l1"])
        self.buffer.load_state_dict(
            {"data": state["buffer"], "size": state["buffer_size"], "ptr": state["buffer_ptr"]}
        )
        for g, s in zip(self.generators, state["generators"], strict=True):
            g.set_state(s)
        episodes = state.get("env_episodes") or [None] * len(references)  # older: all at t = 0
        for env, ref, rng_state, episode in zip(
            self.envs, references, state["env_rng"], episodes, strict=True
        ):
            env.reset(options={"reference": ref})
            env.np_random.bit_generator.state = rng_state
            if episode is not None:
                env.load_episode_state(_map_leaves(episode, torch.Tensor, torch.Tensor.numpy))
        self.noise.state = state["noise"].clone()
        self.episode = [int(x) for x in state["episode"]]
        self.best_loss = [float(x) for x in state["best_loss"]]
        self.wait = [int(x) for x in state["wait"]]
        self.best_episode = [int(x) for x in state["best_episode"]]
        self.pretrained_metric = list(state.get("pretrained_metric", self.pretrained_metric))
        self.history = [EpisodeLog(**h) for h in state["history"]]
        self._obs = [o.numpy().copy() for o in state["obs"]]
        self._episode_loss = [float(x) for x in state["episode_loss"]]
        self._episode_reward = [float(x) for x in state["episode_reward"]]
        self._episode_steps = [int(x) for x in state["episode_steps"]]

    @property
    def done(self) -> bool:
        return not self.active

    def model(self) -> DATINetworks:
        """The networks holding each member's kept (best or final) forward actor."""
        return self.final


def _map_leaves(state: dict[str, Any], kind: type, to: Callable[[Any], Any]) -> dict[str, Any]:
    """`state` with every `kind` leaf (nested dicts included) passed through `to`: an
    environment's numpy arrays become tensors for a checkpoint (`weights_only` loads no numpy)
    and back."""
    out: dict[str, Any] = {}
    for key, value in state.items():
        if isinstance(value, dict):
            value = _map_leaves(value, kind, to)
        elif isinstance(value, kind):
            value = to(value)
        out[key] = value
    return out
