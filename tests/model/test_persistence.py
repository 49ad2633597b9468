"""DATI's networks on disk (`aisdati.model.persistence`): weights files of real models
damaged the ways a disk, a transfer or a hand edit damages them are one line with the reason
(issue 27, items 10 and 20), never a traceback."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers.cli import one_line_error
from tests.helpers.models import copy_of, detect_with, not_an_archive, truncate


def edit_weights(edit):
    """A damage of a weights file: `edit(state, out)` changes the state dict in place (or
    returns what to save instead); `out` is the method's output layer."""

    def damage(path: Path, out: str) -> None:
        state = torch.load(path, weights_only=True)
        instead = edit(state, out)
        torch.save(state if instead is None else instead, path)

    return damage


def _reshaped(state, key):
    state[key] = torch.zeros(*state[key].shape[:-1], state[key].shape[-1] + 1)


def _nan_weight(state, out):
    state[f"{out}.weight"].fill_(np.nan)


def _missing_bias(state, out):
    del state[f"{out}.bias"]


def _unexpected(state, out):
    state["extra.weight"] = torch.zeros(1)


def _wider(state, out):
    _reshaped(state, f"{out}.weight")


WEIGHT_DAMAGE = [
    ("truncated", lambda path, out: truncate(path),
     r"cannot load model weights .*\.pt: the file is damaged, cut short or corrupt \("),
    ("not-a-zip", lambda path, out: not_an_archive(path), r"\.pt is not a model weights file"),
    ("not-a-state-dict", edit_weights(lambda state, out: [1, 2, 3]),
     r"\.pt holds no state dict of named tensors"),
    ("nan-weight", edit_weights(_nan_weight),
     r"cannot load model weights .*\.pt: {out}\.weight holds NaN or inf"),
    ("missing-key", edit_weights(_missing_bias),
     r"cannot load model weights .*\.pt: missing {out}\.bias$"),
    ("unexpected-key", edit_weights(_unexpected),
     r"cannot load model weights .*\.pt: unexpected extra\.weight$"),
    ("wrong-size", edit_weights(_wider),
     r"cannot load model weights .*\.pt: {out}\.weight is \[(\d+), 32, 4\] in the file, the "
     r"model needs \[\1, 32, 3\]"),
]  # fmt: skip


OUTPUT_LAYER = {"dati": "forward_actor.out", "bc": "mean"}


@pytest.mark.parametrize("method", ["dati", "bc"])
@pytest.mark.parametrize("damage, needle", [d[1:] for d in WEIGHT_DAMAGE],
                         ids=[d[0] for d in WEIGHT_DAMAGE])  # fmt: skip
def test_damaged_weights_are_one_line_with_the_reason(ny_models, tmp_path, method, damage, needle):
    """Item 10, and item 20's reason: which entries are missing or unexpected, or the first size
    that differs with both shapes (it was cut to "Error(s) in loading state_dict for X:")."""
    models = copy_of(ny_models, tmp_path, digests=False)
    out = OUTPUT_LAYER[method]
    damage(models / ("down.pt" if method == "dati" else "down-bc.pt"), out)
    result = detect_with(ny_models, models, tmp_path / "r", method)
    one_line_error(result, needle.replace("{out}", re.escape(out)))
