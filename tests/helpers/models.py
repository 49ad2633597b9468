"""Real models of the New York Harbor hour's `down` cluster, built once and then copied,
damaged or judged with by the tests: how each is trained, how `detect` runs with it, and the
damage a disk, a transfer or a hand edit does to a model's files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from tests.helpers.cli import run

NY_HOUR = Path(__file__).resolve().parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"
INGEST = ("--roi", "none", "--min-points", "30")


# ----------------------------------------------------------------- one dati model (ny_dati)
def train_ny_dati(base: Path) -> dict:
    """NY hour ingested (tracks of >= 30 reports), a 2-episode model of its `down` cluster."""
    proc, models = base / "processed", base / "models"
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 30, "--out", proc)
    assert r.exit_code == 0, r.output
    r = run(
        "train", "--cluster", "down", "--data", proc, "--out", models,
        "--episodes", 2, "--max-tracks", 3, "--seed", 1,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    return {"base": base, "proc": proc, "models": models}


def card_of(models: Path) -> dict:
    return json.loads((models / "down.json").read_text())


def detect_dati(ny_dati, models: Path, out: Path, *extra, data: Path | None = None):
    return run(
        "detect", "--data", data or ny_dati["proc"], "--models", models, "--out", out,
        "--near-km", 20, *extra,
    )  # fmt: skip


def card_edit(path: str, value):
    """An edit of a card (a JSON dict) that sets the dotted `path` to `value`."""

    def edit(card):
        node = card
        *parents, last = path.split(".")
        for p in parents:
            node = node[p]
        node[last] = value

    return edit


# ------------------------------------------------ dati, bc and nearest models (ny_models)
def train_ny_models(base: Path) -> dict:
    """NY hour ingested (tracks of >= 30 reports) and 2-episode dati, bc and nearest models of
    its `down` cluster (the lanes preset without pretraining: corridors beside the policies)."""
    proc, models = base / "processed", base / "models"
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 30, "--out", proc)
    assert r.exit_code == 0, r.output
    for method in ("dati", "bc", "nearest"):
        r = run(
            "train", "--cluster", "down", "--method", method, "--data", proc, "--out", models,
            "--episodes", 2, "--max-tracks", 3, "--seed", 1, "--lane", "pretrain=0",
        )  # fmt: skip
        assert r.exit_code == 0, r.output
    return {"proc": proc, "models": models}


def copy_of(ny_models, tmp_path: Path, digests: bool = True) -> Path:
    """A copy of the trained models; `digests=False`: their cards without the digests of their
    files (`ModelCard.files`), as cards from before them were, so that a damaged file reaches
    the reader that checks it instead of being refused as not the card's own."""
    models = tmp_path / "models"
    shutil.copytree(ny_models["models"], models)
    if not digests:
        for card in models.glob("*.json"):
            doc = json.loads(card.read_text())
            doc.pop("files", None)
            card.write_text(json.dumps(doc))
    return models


def detect_with(ny_models, models: Path, out: Path, method: str, *extra):
    return run(
        "detect", "--data", ny_models["proc"], "--models", models, "--out", out, "--method",
        method, "--near-km", 20, *extra,
    )  # fmt: skip


def card_text(models: Path, stem: str) -> str:
    return (models / f"{stem}.json").read_text()


def rewrite_npz(path: Path, edit) -> None:
    with np.load(path) as z:
        arrays = dict(z)
    edit(arrays)
    np.savez_compressed(path, **arrays)


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def not_an_archive(path: Path) -> None:
    path.write_text("positions,offsets\n1,2\n")


def object_array(key: str):
    def damage(path: Path) -> None:
        with np.load(path) as z:
            arrays = dict(z)
        arrays[key] = np.array([{"x": 1}] * 3, dtype=object)
        np.savez(path, **arrays)  # pickles the objects; loading them could run code

    return damage


def edit_npz(edit):
    return lambda path: rewrite_npz(path, edit)


# --------------------------------------------------------- a nearest model (world, per file)
def train_ny_nearest(base: Path) -> dict:
    """The NY hour ingested (tracks of >= 30 reports) and a `nearest` model of its `down`."""
    proc, models = base / "processed", base / "models"
    r = run("ingest", "--input", NY_HOUR, *INGEST, "--out", proc)
    assert r.exit_code == 0, r.output
    r = run("train", "--cluster", "down", "--method", "nearest", "--data", proc, "--out", models)
    assert r.exit_code == 0, r.output
    return {"proc": proc, "models": models}


def detect_args(world, out: Path, *extra) -> list:
    return [
        "detect", "--data", world["proc"], "--models", world["models"], "--method", "nearest",
        "--out", out, "--near-km", 20, *extra,
    ]  # fmt: skip


def evaluate_args(kitimat: Path, out: Path) -> list:
    return ["evaluate", "--cluster", "route-1", "--data", kitimat, "--detectors", "nearest",
            "--fleet-kinds", "none", "--out", out]  # fmt: skip
