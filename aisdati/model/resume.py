"""Exact resume of a `DATITrainer` after any member's episode end.

`trainer_state` captures everything that the next steps depend on: the live, final and averaged
networks, the three Adam optimisers, the replay buffer, every random stream (torch generators of
the members, which also drive their latent noise; the environments' numpy generators), the latent
noise state, the episode counters, the early-stopping state, the history and the current
observations. Each environment is reset onto the reference it had drawn and then given its
episode's state (position, step, smoothed DTW and the incremental DTW's rows): the members of a
seed ensemble end their episodes at different steps, so a checkpoint finds most of them
mid-episode. Each member's shuffled episode order is saved by the caller
(`AISTrackSource.state_dict`).

Everything is tensors, lists, dicts and numbers, so the file loads with
`torch.load(weights_only=True)`: no code runs from a checkpoint.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from aisdati.errors import UserError
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.model.dati import DATITrainer, EpisodeLog
from aisdati.model.env import Reference

FORMAT = "aisdati-trainer/1"


def _convert(state: dict[str, Any], kind: type, to: Callable[[Any], Any]) -> dict[str, Any]:
    """`state` with every `kind` leaf (nested dicts included) passed through `to`: numpy arrays
    become tensors for saving (`weights_only` loads no numpy) and back for loading."""
    out: dict[str, Any] = {}
    for key, value in state.items():
        if isinstance(value, dict):
            value = _convert(value, kind, to)
        elif isinstance(value, kind):
            value = to(value)
        out[key] = value
    return out


def trainer_state(trainer: DATITrainer) -> dict[str, Any]:
    """The trainer's state between two steps."""
    buf = trainer.buffer
    return {
        "format": FORMAT,
        "nets": trainer.nets.state_dict(),
        "final": trainer.final.state_dict(),
        "average": None if trainer.average is None else trainer.average.state_dict(),
        "opt_critic": trainer.opt_critic.state_dict(),
        "opt_actor": trainer.opt_actor.state_dict(),
        "opt_l1": trainer.opt_l1.state_dict(),
        "buffer": {k: v[:, : buf.size].clone() for k, v in buf.data.items()},
        "buffer_size": buf.size,
        "buffer_ptr": buf.ptr,
        "generators": [g.get_state() for g in trainer.generators],
        "env_rng": [env.np_random.bit_generator.state for env in trainer.envs],
        "env_episodes": [
            _convert(env.episode_state(), np.ndarray, torch.as_tensor) for env in trainer.envs
        ],
        "noise": trainer.noise.state.clone(),
        "active": list(trainer.active),
        "episode": list(trainer.episode),
        "best_loss": list(trainer.best_loss),
        "wait": list(trainer.wait),
        "best_episode": list(trainer.best_episode),
        "pretrained_metric": list(trainer.pretrained_metric),
        "history": [dict(log.__dict__) for log in trainer.history],
        "obs": [torch.as_tensor(o) for o in trainer._obs],
        "episode_loss": list(trainer._episode_loss),
        "episode_reward": list(trainer._episode_reward),
        "episode_steps": list(trainer._episode_steps),
    }


def load_trainer_state(
    trainer: DATITrainer, state: dict[str, Any], references: list[Reference]
) -> None:
    """Restore `trainer_state` into a trainer freshly built with the same environments, seeds and
    configuration; `references[k]` is the reference active member k's environment had drawn."""
    active = [int(a) for a in state["active"]]
    if len(active) < len(trainer.active):
        trainer._drop([k for k, m in enumerate(trainer.active) if m not in active])
    trainer.nets.load_state_dict(state["nets"])
    trainer.final.load_state_dict(state["final"])
    if trainer.average is not None:
        trainer.average.load_state_dict(state["average"])
    trainer.opt_critic.load_state_dict(state["opt_critic"])
    trainer.opt_actor.load_state_dict(state["opt_actor"])
    trainer.opt_l1.load_state_dict(state["opt_l1"])
    buf = trainer.buffer
    size = int(state["buffer_size"])
    for k, v in state["buffer"].items():
        buf.data[k].zero_()
        buf.data[k][:, :size] = v
    buf.size, buf.ptr = size, int(state["buffer_ptr"])
    for g, s in zip(trainer.generators, state["generators"], strict=True):
        g.set_state(s)
    episodes = state.get("env_episodes") or [None] * len(references)  # older: all at t = 0
    for env, ref, rng_state, episode in zip(
        trainer.envs, references, state["env_rng"], episodes, strict=True
    ):
        env.reset(options={"reference": ref})
        env.np_random.bit_generator.state = rng_state
        if episode is not None:
            env.load_episode_state(_convert(episode, torch.Tensor, torch.Tensor.numpy))
    trainer.noise.state = state["noise"].clone()
    trainer.episode = [int(x) for x in state["episode"]]
    trainer.best_loss = [float(x) for x in state["best_loss"]]
    trainer.wait = [int(x) for x in state["wait"]]
    trainer.best_episode = [int(x) for x in state["best_episode"]]
    trainer.pretrained_metric = list(state.get("pretrained_metric", trainer.pretrained_metric))
    trainer.history = [EpisodeLog(**h) for h in state["history"]]
    trainer._obs = [o.numpy().copy() for o in state["obs"]]
    trainer._episode_loss = [float(x) for x in state["episode_loss"]]
    trainer._episode_reward = [float(x) for x in state["episode_reward"]]
    trainer._episode_steps = [int(x) for x in state["episode_steps"]]


def save_checkpoint(path: Path, trainer: DATITrainer, extra: dict[str, Any]) -> None:
    buf = io.BytesIO()
    torch.save({"trainer": trainer_state(trainer), **extra}, buf)
    atomic_write_bytes(path, buf.getvalue())


def read_checkpoint(path: Path) -> dict[str, Any]:
    try:
        doc = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # damaged or foreign file: many exception types
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UserError(f"cannot read checkpoint {path}: {first[:200]}") from None
    if not isinstance(doc, dict) or doc.get("trainer", {}).get("format") != FORMAT:
        raise UserError(f"{path} is not an aisdati training checkpoint")
    return doc
