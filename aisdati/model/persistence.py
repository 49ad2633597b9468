"""DATI on disk: trained networks (a weights-only `.pt` file plus a JSON card) and the training
checkpoint that resumes a `DATITrainer` exactly (`DATITrainer.state_dict`).

Everything is written under a temporary name and renamed (`atomic_write_bytes`), and read with
`torch.load(weights_only=True)`, which never executes code from the file: a model or checkpoint
received from someone else is safe to open. What is read is checked before it is used, since
the networks are built at the sizes the card asks for and the weights go where the networks
say: sizes within `MAX_UNITS`/`MAX_LAYERS`/`MAX_SEEDS`, weights that are a state dict of finite
tensors, and of the networks' own names and shapes. Damaged or foreign files are one-line
`UserError`s that say what is wrong (`state_mismatch`: which entries are missing or unexpected,
or the first size that differs, with both shapes).
"""

from __future__ import annotations

import io
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import nn

from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.networks import DATINetworks, NetworkConfig
from aisdati.model.readers import first_line, read_json, torch_load_error
from aisdati.outdir import atomic_write_bytes

NETWORKS_FORMAT = "aisdati-dati/1"
CHECKPOINT_FORMAT = "aisdati-trainer/1"
MAX_UNITS = 256
"""The widest layer (and state or decision) a model file may ask for: the paper's networks have
16 to 76 units. With `MAX_LAYERS` and 16 seeds, DATI's four networks hold 90 million weights
(0.36 GB), which any machine can build before finding that the weights do not fit them."""
MAX_LAYERS = 16
"""The most hidden layers a model file may ask for (the paper's: 4)."""
MAX_SEEDS = 64
"""The most ensemble members a model file may hold (an AIS lane model: at most 16)."""


# ------------------------------------------------------------------------------ networks
def network_bytes(nets: DATINetworks) -> bytes:
    """The weights as `<stem>.pt` holds them: the state dict, on the CPU (from any device)."""
    buf = io.BytesIO()
    torch.save({name: w.cpu() for name, w in nets.state_dict().items()}, buf)
    return buf.getvalue()


def network_meta(nets: DATINetworks, config: DATIConfig) -> dict[str, Any]:
    """What `<stem>.json` holds of the networks beside the card: format, sizes, seeds, config."""
    return {
        "format": NETWORKS_FORMAT,
        "state_dim": nets.state_dim,
        "decision_dim": nets.decision_dim,
        "seeds": nets.seeds,
        "config": config.to_dict(),
    }


def load_networks(stem: Path) -> tuple[DATINetworks, DATIConfig, dict[str, Any]]:
    """Read `<stem>.pt` and the networks' part of `<stem>.json` (`network_bytes`,
    `network_meta`); any damage is a one-line `UserError`."""
    weights, card = stem.with_suffix(".pt"), stem.with_suffix(".json")
    for f in (weights, card):
        if not f.is_file():
            raise UserError(f"model file not found: {f}")
    meta = read_json(card)
    if not isinstance(meta, dict) or meta.get("format") != NETWORKS_FORMAT:
        raise UserError(f"{card} is not an aisdati model card")
    try:
        config = DATIConfig.from_dict(meta["config"])
        dims, seeds = (meta["state_dim"], meta["decision_dim"]), meta["seeds"]
        check_network_sizes(config.network, dims, seeds)
        nets = DATINetworks(*dims, config.network, seeds)
    except UserError as exc:
        raise UserError(f"cannot load model {stem}: {exc}") from None
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise UserError(f"cannot load model {stem}: {first_line(exc)}") from None
    load_weights(nets, weights)
    return nets, config, meta


def check_network_sizes(cfg: NetworkConfig, dims: Sequence[Any], seeds: Sequence[Any]) -> None:
    """Refuse sizes no model has before networks are built at them (one line)."""
    sizes = {"state_dim": dims[0], "decision_dim": dims[1]}
    sizes |= {k: getattr(cfg, k) for k in ("feature_units", "latent_dim", "hidden_units")}
    sizes |= {"time_embedding_dim": cfg.time_embedding_dim, "hidden_layers": cfg.hidden_layers}
    for name, value in sizes.items():
        most = MAX_LAYERS if name == "hidden_layers" else MAX_UNITS
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= most:
            raise UserError(f"{name} must be an integer in [1, {most}], got {value!r}")
    if not isinstance(seeds, list) or not 1 <= len(seeds) <= MAX_SEEDS:
        raise UserError(f"seeds must be a list of 1 to {MAX_SEEDS} seeds")


def read_weights(path: Path) -> dict[str, torch.Tensor]:
    """The state dict in a weights-only `.pt` file: named, finite tensors."""
    if not path.is_file():
        raise UserError(f"model file not found: {path}")
    with path.open("rb") as fh:
        if fh.read(2) != b"PK":  # torch.save writes a zip archive
            raise UserError(f"{path} is not a model weights file (damaged or foreign)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # a damaged archive or pickle: many exception types
        damaged = "the file is damaged, cut short or corrupt"
        reason = torch_load_error(exc, "model", damaged)
        raise UserError(f"cannot load model weights {path}: {reason}") from None
    if not isinstance(state, dict) or not all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in state.items()
    ):
        raise UserError(f"{path} holds no state dict of named tensors (damaged or foreign)")
    for key, value in state.items():
        if value.is_floating_point() and not torch.isfinite(value).all():
            raise UserError(f"cannot load model weights {path}: {key} holds NaN or inf")
    return state


def load_weights(module: nn.Module, path: Path) -> None:
    """Load `path`'s weights into `module`, refusing (in one line) weights that do not fit."""
    state = read_weights(path)
    problem = state_mismatch(module.state_dict(), state)
    if problem is not None:
        raise UserError(f"cannot load model weights {path}: {problem}")
    module.load_state_dict(state)


def state_mismatch(expected: Mapping[str, Any], found: Mapping[str, Any]) -> str | None:
    """Why the state dict `found` does not fit a module whose own is `expected`, in one line
    (None: it fits): the entries missing and unexpected, else the first size that differs."""
    missing = [k for k in expected if k not in found]
    unexpected = [k for k in found if k not in expected]
    if missing or unexpected:
        said = [f"{what} {_listed(keys)}" for what, keys in
                (("missing", missing), ("unexpected", unexpected)) if keys]  # fmt: skip
        return "; ".join(said)
    for key, want in expected.items():
        got = found[key]
        if not isinstance(got, torch.Tensor) or got.shape != want.shape:
            shape = list(got.shape) if isinstance(got, torch.Tensor) else type(got).__name__
            return f"{key} is {shape} in the file, the model needs {list(want.shape)}"
    return None


def load_error(exc: BaseException) -> str:
    """Why loading a saved state failed, in one line. torch's `load_state_dict` says "Error(s)
    in loading state_dict for X:" on its first line and each reason on one of its own: the
    first reason is kept (a size mismatch names both shapes). A missing entry is a KeyError."""
    if isinstance(exc, KeyError) and exc.args:
        return f"it has no {exc.args[0]!r} entry"
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    if len(lines) > 1 and lines[0].startswith("Error(s) in loading state_dict"):
        lines = lines[1:]
    text = lines[0] if lines else type(exc).__name__
    return re.sub(r"torch\.Size\((\[[^\]]*\])\)", r"\1", text)[:300]


def _listed(keys: Sequence[str], shown: int = 3) -> str:
    more = f" and {len(keys) - shown} more" if len(keys) > shown else ""
    return ", ".join(keys[:shown]) + more


# ---------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: Path, trainer: DATITrainer, extra: dict[str, Any]) -> None:
    """Write the trainer's state (under "trainer") with the caller's `extra` entries: what it
    needs to resume too, such as the references its environments are on."""
    buf = io.BytesIO()
    torch.save({"trainer": {"format": CHECKPOINT_FORMAT, **trainer.state_dict()}, **extra}, buf)
    atomic_write_bytes(path, buf.getvalue())


def read_checkpoint(path: Path, required: Sequence[str] = ()) -> dict[str, Any]:
    """What `save_checkpoint` wrote, with the `required` entries of `extra`; doc["trainer"]
    goes to `DATITrainer.load_state_dict`. Every float tensor in it must be finite."""
    try:
        doc = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # damaged or foreign file: many exception types
        reason = torch_load_error(exc, "checkpoint", "damaged or not a checkpoint")
        raise UserError(f"cannot read checkpoint {path}: {reason}") from None
    trainer = doc.get("trainer") if isinstance(doc, dict) else None
    if not isinstance(trainer, dict) or trainer.get("format") != CHECKPOINT_FORMAT:
        raise UserError(f"{path} is not an aisdati training checkpoint")
    missing = [k for k in required if k not in doc]
    if missing:
        raise UserError(f"checkpoint {path} is damaged: it has no {_listed(missing)}")
    where = _non_finite(doc)
    if where is not None:
        raise UserError(f"checkpoint {path} is damaged: {where} holds NaN or inf")
    return doc


def _non_finite(doc: Any) -> str | None:
    """The path of the first float tensor in `doc` holding NaN or inf (None: none does)."""
    todo: list[tuple[str, Any]] = [("", doc)]
    while todo:
        name, node = todo.pop()
        if isinstance(node, dict):
            todo += [(f"{name}.{k}" if name else str(k), v) for k, v in node.items()]
        elif isinstance(node, (list, tuple)):
            todo += [(f"{name}[{i}]", v) for i, v in enumerate(node)]
        elif isinstance(node, torch.Tensor) and node.is_floating_point():
            finite = bool(torch.isfinite(node).all())
            if not finite:
                return name
    return None
