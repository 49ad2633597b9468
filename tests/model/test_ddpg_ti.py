"""DDPG-TI as a batched ensemble, held to Stable-Baselines3's DDPG: same updates from the same
weights and batches, each seed independent of its ensemble, trained end to end on a family."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from aisdati.model.ddpg_ti import DDPGTIConfig, DDPGTITrainer, ddpg_ti_act
from aisdati.model.networks import EnsembleLinear
from aisdati.model.rollout import rollout_policy
from aisdati.selftest.protocol import evaluation_references
from aisdati.selftest.sources import make_family_env
from tests.helpers.line_family import LINE


def _sb3_ddpg_ti(env, cfg: DDPGTIConfig):
    """SB3's own DDPG with DDPG-TI's extractor, architecture and two learning rates."""
    from stable_baselines3 import DDPG
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
    from stable_baselines3.common.utils import update_learning_rate

    class Extractor(BaseFeaturesExtractor):
        def __init__(self, observation_space):
            super().__init__(observation_space, cfg.state_features + cfg.time_embedding_dim)
            self.state = nn.Linear(observation_space.shape[0] - 1, cfg.state_features)
            self.freq = nn.Parameter(torch.zeros(cfg.time_embedding_dim))
            self.phase = nn.Parameter(torch.zeros(cfg.time_embedding_dim))

        def forward(self, obs):
            z = obs[:, -1:] * self.freq + self.phase
            return torch.cat(
                [torch.tanh(self.state(obs[:, :-1])), z[:, :1], torch.sin(z[:, 1:])], 1
            )

    class TwoRates(DDPG):
        def _update_learning_rate(self, optimizers):
            update_learning_rate(self.actor.optimizer, cfg.lr_actor)
            update_learning_rate(self.critic.optimizer, cfg.lr_critic)

    model = TwoRates(
        "MlpPolicy",
        env,
        learning_rate=cfg.lr_actor,
        batch_size=cfg.batch_size,
        tau=cfg.tau,
        gamma=cfg.gamma,
        policy_kwargs={
            "features_extractor_class": Extractor,
            "share_features_extractor": True,
            "net_arch": [cfg.hidden_units] * cfg.hidden_layers,
            "activation_fn": nn.Tanh,
        },
        device="cpu",
    )
    model.set_logger(Logger(None, []))
    return model


def _linears(head) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """(weight [E, in, out], bias [E, 1, out]) of a head's layers in order, split blocks joined."""
    first = head.hidden.first
    layers = [(torch.cat(list(first.weights), dim=1), first.bias)]
    layers += [(m.weight, m.bias) for m in head.hidden.rest if isinstance(m, EnsembleLinear)]
    return [*layers, (head.out.weight, head.out.bias)]


def _pairs(trainer: DDPGTITrainer, model) -> list[tuple[torch.Tensor, torch.Tensor, str]]:
    """(our [E, ...] parameter, SB3's parameter, how to map member k) for every weight."""
    pairs = []
    for ours, theirs in (
        (trainer.actor, model.actor),
        (trainer.target_actor, model.actor_target),
    ):
        ext = theirs.features_extractor
        pairs += [
            (ours.features.state.weight, ext.state.weight, "T"),
            (ours.features.state.bias, ext.state.bias, "row"),
            (ours.features.time2vec.freq, ext.freq, "row"),
            (ours.features.time2vec.phase, ext.phase, "row"),
        ]
        linears = [m for m in theirs.mu if isinstance(m, nn.Linear)]
        for (w, b), lin in zip(_linears(ours.head), linears, strict=True):
            pairs += [(w, lin.weight, "T"), (b, lin.bias, "row")]
    for ours, theirs in (
        (trainer.critic, model.critic),
        (trainer.target_critic, model.critic_target),
    ):
        linears = [m for m in theirs.qf0 if isinstance(m, nn.Linear)]
        for (w, b), lin in zip(_linears(ours), linears, strict=True):
            pairs += [(w, lin.weight, "T"), (b, lin.bias, "row")]
    return pairs


def _member(ours: torch.Tensor, k: int, how: str) -> torch.Tensor:
    return ours[k].T if how == "T" else ours[k].reshape(-1)


def test_an_update_is_sb3_ddpgs_update():
    """From member 1's weights and the same three batches, SB3's `train` and ours end equal:
    critic and actor steps, Adam's state, the shared extractor learning from the actor only,
    and the soft updates (the extractor's target moved twice)."""
    torch.manual_seed(0)
    cfg = DDPGTIConfig()
    env = make_family_env(LINE)
    trainer = DDPGTITrainer([make_family_env(LINE), make_family_env(LINE)], [3, 4], cfg)
    model = _sb3_ddpg_ti(env, cfg)
    with torch.no_grad():
        for ours, theirs, how in _pairs(trainer, model):
            theirs.copy_(_member(ours, 1, how))
    before = [theirs.detach().clone() for _, theirs, _ in _pairs(trainer, model)]
    from stable_baselines3.common.type_aliases import ReplayBufferSamples

    rng = torch.Generator().manual_seed(1)
    for _ in range(3):
        obs = torch.rand(2, cfg.batch_size, 3, generator=rng)
        batch = {
            "obs": obs,
            "action": torch.rand(2, cfg.batch_size, 2, generator=rng) * 2 - 1,
            "reward": torch.where(torch.rand(2, cfg.batch_size, 1, generator=rng) < 0.5, 1.0, -1.0),
            "next_obs": torch.rand(2, cfg.batch_size, 3, generator=rng),
            "done": (torch.rand(2, cfg.batch_size, 1, generator=rng) < 0.1).float(),
        }
        sample = ReplayBufferSamples(
            observations=batch["obs"][1],
            actions=batch["action"][1],
            next_observations=batch["next_obs"][1],
            dones=batch["done"][1],
            rewards=batch["reward"][1],
        )
        model.replay_buffer.sample = lambda *a, s=sample, **k: s
        model.train(gradient_steps=1, batch_size=cfg.batch_size)
        trainer.update(batch)
    pairs = _pairs(trainer, model)
    for (ours, theirs, how), start in zip(pairs, before, strict=True):
        assert torch.allclose(_member(ours, 1, how), theirs, rtol=1e-4, atol=1e-6)
        assert not torch.equal(theirs, start)  # every weight moved, targets included
        assert not torch.equal(_member(ours, 1, how), _member(ours, 0, how))


def test_each_seed_trains_as_if_alone():
    cfg = DDPGTIConfig(episodes=4, learning_starts=30)  # 80 steps, 50 updates
    pair = DDPGTITrainer([make_family_env(LINE) for _ in range(2)], [3, 4], cfg)
    alone = DDPGTITrainer([make_family_env(LINE)], [4], cfg)
    pair.train(), alone.train()
    assert pair.updates == alone.updates == 80 - 30
    obs = torch.rand(1, 7, 3)
    with torch.no_grad():
        ours = pair.actor(obs.expand(2, -1, -1))[1]
        single = alone.actor(obs)[0]
    assert torch.allclose(ours, single, atol=1e-5)
    assert not torch.allclose(ours, pair.actor(obs.expand(2, -1, -1))[0].detach(), atol=1e-3)


def test_ddpg_ti_trains_and_rolls_out():
    cfg = DDPGTIConfig(episodes=4)  # 80 steps: trains from step 65 on
    trainer = DDPGTITrainer([make_family_env(LINE)], [0], cfg)
    ended = []
    actor = trainer.train(lambda t, logs: ended.extend((g.member, g.episode) for g in logs))
    assert ended == [(0, 1), (0, 2), (0, 3), (0, 4)] and trainer.updates == 80 - 64
    assert sum(trainer.actor.features.widths) == 156
    assert trainer.opt_actor.param_groups[0]["lr"] == pytest.approx(1e-4)
    assert trainer.opt_critic.param_groups[0]["lr"] == pytest.approx(2e-4)
    refs = evaluation_references(LINE, 2, 0)
    grid = [[make_family_env(LINE) for _ in refs]]
    paths, scores = rollout_policy(ddpg_ti_act(actor, [0], 2, cfg, seed=0), grid, [refs])
    again = rollout_policy(ddpg_ti_act(actor, [0], 2, cfg, seed=0), grid, [refs])[1]
    assert np.isfinite(scores).all() and np.array_equal(scores, again)
    assert len(paths[0][0]) == LINE.steps + 1


def test_members_of_one_ensemble_need_equal_episodes():
    from dataclasses import replace

    with pytest.raises(ValueError, match="equal length"):
        DDPGTITrainer([make_family_env(LINE), make_family_env(replace(LINE, steps=30))], [0, 1])
