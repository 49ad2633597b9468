"""Saving and loading trained DATI networks: a weights-only `.pt` file plus a JSON card.

`torch.load(weights_only=True)` never executes code from the file, so a model received from
someone else is safe to open. Both files are written under temporary names and renamed.
"""

from __future__ import annotations

import io
import json
import os
import pickle
import tempfile
from pathlib import Path
from typing import Any

import torch

from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig
from aisdati.model.networks import DATINetworks
from aisdati.options import raise_if_interrupted


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temporary file beside `path`, then rename: never a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp creates 0600; give the usual permissions
        raise_if_interrupted()
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_networks(stem: Path, nets: DATINetworks, config: DATIConfig, card: dict[str, Any]) -> None:
    """Write `<stem>.pt` (state dict) and `<stem>.json` (config, dimensions, seeds, card)."""
    buf = io.BytesIO()
    torch.save(nets.state_dict(), buf)
    meta = {
        "format": "aisdati-dati/1",
        "state_dim": nets.forward_actor.input_features.weight.shape[1],
        "decision_dim": nets.forward_actor.out.weight.shape[2],
        "seeds": nets.seeds,
        "config": config.to_dict(),
        **card,
    }
    atomic_write_bytes(stem.with_suffix(".pt"), buf.getvalue())
    atomic_write_bytes(stem.with_suffix(".json"), json.dumps(meta, indent=2, default=str).encode())


def load_networks(stem: Path) -> tuple[DATINetworks, DATIConfig, dict[str, Any]]:
    """Read what `save_networks` wrote; any damage is a one-line `UserError`."""
    weights, card = stem.with_suffix(".pt"), stem.with_suffix(".json")
    for f in (weights, card):
        if not f.is_file():
            raise UserError(f"model file not found: {f}")
    try:
        meta = json.loads(card.read_text())
        if not isinstance(meta, dict) or meta.get("format") != "aisdati-dati/1":
            raise UserError(f"{card} is not an aisdati model card")
        config = DATIConfig.from_dict(meta["config"])
        nets = DATINetworks(meta["state_dim"], meta["decision_dim"], config.network, meta["seeds"])
        state = torch.load(weights, map_location="cpu", weights_only=True)
        nets.load_state_dict(state)
    except UserError:
        raise
    except (OSError, ValueError, KeyError, TypeError, RuntimeError, pickle.UnpicklingError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise UserError(f"cannot load model {stem}: {first}") from None
    return nets, config, meta
