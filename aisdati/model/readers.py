"""Reading the JSON and `.npz` files a model is made of, trusting nothing in them.

A model folder can come from someone else, be cut short by a full disk or be edited by hand. What
is read from it reaches numba kernels that do not check their indices, and allocations sized by
its numbers, so every file is checked before use: a JSON card for its size and nesting (a deeply
nested document is a `RecursionError`, a huge one exhausts memory), each `.npz` array for its
dtype, rank, size and finiteness, from its header before its data is read (so an object array is
never unpickled and a huge one never allocated). Any problem is a one-line `UserError` that names
the file and says what is wrong with it.
"""

from __future__ import annotations

import json
import math
import pickle
import re
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aisdati.errors import UserError

MAX_JSON_BYTES = 64 << 20
"""The largest card read: a card of 100,000 training tracks (ids, keys, start points and four
calibration scores each) is about 15 MB."""
MAX_JSON_DEPTH = 32
"""The deepest nesting read: a card's deepest field (a member's training curve) is 5 levels."""
KIND_NAMES = {"f": "floats", "i": "integers", "u": "integers", "b": "booleans"}
PICKLED_CALL = re.compile(r"GLOBAL ([\w.]+)")
"""What a pickle refused by `torch.load(weights_only=True)` asked to import (torch's words)."""


def first_line(exc: BaseException, limit: int = 200) -> str:
    """An exception's message as one short line (its type where it has none)."""
    text = " ".join(str(exc).split())
    return text[:limit] if text else type(exc).__name__


def torch_load_error(exc: BaseException, what: str, damaged: str) -> str:
    """Why `torch.load(weights_only=True)` refused a file, in one line: `damaged` and the cause,
    or, for a pickle asking to run code, that it is no safe aisdati `what`. Never torch's own
    text for a pickle, which advises loading the file with `weights_only=False`: that would run
    whatever code a planted file holds."""
    if not isinstance(exc, pickle.UnpicklingError):
        return f"{damaged} ({first_line(exc)})"
    found = PICKLED_CALL.search(str(exc))
    if found is None:
        return f"{damaged} (not a torch file of tensors)"
    return (
        f"not a safe aisdati {what}: it asks to run {found.group(1)}, which aisdati never does; "
        "retrain it, or use a trusted copy"
    )


def read_json(path: Path, what: str = "model card", max_bytes: int = MAX_JSON_BYTES) -> Any:
    """The JSON document at `path`, of at most `max_bytes` and `MAX_JSON_DEPTH` levels."""
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise UserError(f"{what} {path} is {size:,} bytes, more than any holds ({max_bytes:,})")
        doc = json.loads(path.read_text(encoding="utf-8"))
    except RecursionError:
        raise UserError(f"{what} {path} is nested too deeply to be a {what}") from None
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot read {what} {path}: {first_line(exc)}") from None
    if json_depth(doc, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise UserError(f"{what} {path} is nested more than {MAX_JSON_DEPTH} levels deep")
    return doc


def json_depth(doc: Any, limit: int) -> int:
    """Levels of lists and objects in `doc` (a scalar: 0), counted up to `limit` + 1 without
    recursion."""
    deepest, todo = 0, [(doc, 1)]
    while todo:
        node, depth = todo.pop()
        if not isinstance(node, (dict, list)):
            continue
        deepest = max(deepest, depth)
        if depth > limit:
            return depth
        children = node.values() if isinstance(node, dict) else node
        todo.extend((child, depth + 1) for child in children)
    return deepest


@dataclass(frozen=True)
class ArraySpec:
    """What one array of an `.npz` must be."""

    kinds: str
    """The dtype kinds it may have: "f" floats (which must be finite), "iu" integers, "b"."""
    ndim: int
    width: int | None = None
    """The length of its last axis, where fixed."""
    max_items: int = 1 << 27
    """The most values it may hold: a file asking for more is refused before it is read."""


class _Refused(Exception):
    """What is wrong with a file (`read_npz` adds which file)."""


def read_npz(path: Path, specs: Mapping[str, ArraySpec]) -> dict[str, np.ndarray]:
    """The arrays `specs` names, read from the `.npz` at `path` and checked against them; any
    problem is a `UserError` "cannot load <path>: <what is wrong>"."""
    if not path.is_file():
        raise UserError(f"model file not found: {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            return {key: _read_array(archive, key, spec) for key, spec in specs.items()}
    except _Refused as exc:
        raise UserError(f"cannot load {path}: {exc}") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise UserError(f"cannot load {path}: not a readable .npz ({first_line(exc)})") from None


def _read_array(archive: zipfile.ZipFile, key: str, spec: ArraySpec) -> np.ndarray:
    name = f"{key}.npy"
    if name not in archive.namelist():
        raise _Refused(f"it has no {key!r} array")
    with archive.open(name) as fh:
        version = np.lib.format.read_magic(fh)
        if version not in ((1, 0), (2, 0)):
            raise _Refused(f"{key!r} is in an unknown .npy format {version}")
        read_header = (
            np.lib.format.read_array_header_1_0
            if version == (1, 0)
            else np.lib.format.read_array_header_2_0
        )
        shape, _, dtype = read_header(fh)
    if dtype.hasobject:
        raise _Refused(f"{key!r} holds Python objects, which are never loaded (they can run code)")
    if dtype.kind not in spec.kinds:
        wanted = " or ".join(sorted({KIND_NAMES[k] for k in spec.kinds}))
        raise _Refused(f"{key!r} must hold {wanted}, got {dtype}")
    if len(shape) != spec.ndim or (spec.width is not None and shape[-1] != spec.width):
        axes = ["n"] * spec.ndim
        if spec.width is not None:
            axes[-1] = str(spec.width)
        raise _Refused(f"{key!r} must have shape [{', '.join(axes)}], got {list(shape)}")
    if math.prod(shape) > spec.max_items:
        raise _Refused(f"{key!r} holds {math.prod(shape):,} values, more than {spec.max_items:,}")
    with archive.open(name) as fh:
        arr = np.lib.format.read_array(fh, allow_pickle=False)
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise _Refused(f"{key!r} holds non-finite values (NaN or inf)")
    return arr
