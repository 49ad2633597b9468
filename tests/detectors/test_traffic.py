"""Hardening of the files a model is made of (issue 27, items 8, 10, 11, 12 and part of 20): real
models trained on the real New York Harbor hour, then damaged the ways a disk, a transfer or a
hand edit damages files. Every damage must be a one-line error naming the file and what is
wrong (exit 2), never a traceback, a MemoryError or a crash of the process."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hardening import card_edit, one_line_error, run

from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings, train_ais

NY_HOUR = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"
RESUME_LANE = ("fourier=0", "pretrain=0", "members=1")
"""The checkpoint's lane settings (small and fast); a run without them has the preset's."""


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """NY hour ingested (tracks of >= 30 reports) and 2-episode dati, bc and nearest models of
    its `down` cluster (the lanes preset without pretraining: corridors beside the policies)."""
    base = tmp_path_factory.mktemp("models")
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


def copy_of(trained, tmp_path: Path) -> Path:
    models = tmp_path / "models"
    shutil.copytree(trained["models"], models)
    return models


def detect(trained, models: Path, out: Path, method: str, *extra):
    return run(
        "detect", "--data", trained["proc"], "--models", models, "--out", out, "--method",
        method, "--near-km", 20, *extra,
    )  # fmt: skip


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


def _set(arrays, key, value):
    arrays[key] = value


# ------------------------------------------------------------------------------ item 8
@pytest.mark.parametrize("bad", [np.nan, np.inf], ids=["nan", "inf"])
def test_nearest_positions_of_nan_or_inf_are_refused_not_a_segfault(trained, tmp_path, bad):
    """NaN costs made the DTW back-track leave its matrix and write past its path (rc 139):
    run in a process of its own, so that a crash fails this test instead of the session."""
    models = copy_of(trained, tmp_path)
    rewrite_npz(models / "down-nearest.npz", lambda z: z["positions"].fill(bad))
    proc = subprocess.run(
        [sys.executable, "-m", "aisdati.cli", "detect", "--data", str(trained["proc"]),
         "--models", str(models), "--out", str(tmp_path / "r"), "--method", "nearest",
         "--score", "rollout", "--near-km", "20"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert re.search(
        r"cannot load .*down-nearest\.npz: 'positions' holds non-finite values", proc.stderr
    ), proc.stderr


def test_non_finite_numbers_reaching_a_kernel_are_one_line_naming_the_model(trained, tmp_path):
    """The kernels refuse NaN themselves; the detector says which model was scoring."""
    from aisdati.detectors import load_detector
    from aisdati.errors import UserError
    from aisdati.tracks.store import load_tracks

    det = load_detector(trained["models"] / "down-nearest")
    (track,) = load_tracks(trained["proc"], det.card.data.track_ids[:1])
    positions = track.positions.copy()
    positions[3] = np.nan
    with pytest.raises(UserError, match=r"cannot score with .*down-nearest\.json: .*non-finite"):
        det.score([replace(track, positions=positions)])


# ----------------------------------------------------------------------------- item 10
NEAREST_DAMAGE = [
    ("truncated", truncate, "not a readable .npz"),
    ("not-a-zip", not_an_archive, "not a readable .npz"),
    ("descending-offsets", edit_npz(lambda z: _set(z, "offsets", z["offsets"][::-1].copy())),
     "the offsets must rise from 0 to"),
    ("offsets-past-the-end", edit_npz(lambda z: z["offsets"].__setitem__(-1, 10**9)),
     "the offsets must rise from 0 to"),
    ("uint-offsets-descending", edit_npz(lambda z: _set(
        z, "offsets", np.array([0, 90, 40, z["offsets"][-1]], np.uint64))),
     "the offsets must rise from 0 to"),
    ("float-offsets", edit_npz(lambda z: _set(z, "offsets", z["offsets"] + 0.5)),
     "'offsets' must hold integers, got float64"),
    ("positions-of-3", edit_npz(lambda z: _set(z, "positions", np.ones((len(z["positions"]), 3)))),
     r"'positions' must have shape \[n, 2\], got \[\d+, 3\]"),
    ("missing-mmsi", edit_npz(lambda z: z.pop("mmsi")), "it has no 'mmsi' array"),
    ("object-array", object_array("mmsi"), "'mmsi' holds Python objects"),
    ("fewer-tracks", edit_npz(lambda z: (_set(z, "offsets", z["offsets"][:-1]),
                                         _set(z, "mmsi", z["mmsi"][:-1]))),
     "it holds 2 tracks and 2 vessels, the card 3"),
    ("fewer-positions", edit_npz(lambda z: _set(z, "positions", z["positions"][:-1])),
     r"it holds \d+ positions, the card says \d+"),
    ("not-degrees", edit_npz(lambda z: z["positions"].__setitem__(0, [500.0, 40.0])),
     r"positions must be \(lon, lat\) in degrees"),
]  # fmt: skip


@pytest.mark.parametrize("damage, needle", [d[1:] for d in NEAREST_DAMAGE],
                         ids=[d[0] for d in NEAREST_DAMAGE])  # fmt: skip
def test_a_damaged_nearest_npz_is_one_line(trained, tmp_path, damage, needle):
    models = copy_of(trained, tmp_path)
    damage(models / "down-nearest.npz")
    result = detect(trained, models, tmp_path / "r", "nearest", "--score", "rollout")
    one_line_error(result, r"cannot load .*down-nearest\.npz: " + needle)


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
def test_damaged_weights_are_one_line_with_the_reason(trained, tmp_path, method, damage, needle):
    """Item 10, and item 20's reason: which entries are missing or unexpected, or the first size
    that differs with both shapes (it was cut to "Error(s) in loading state_dict for X:")."""
    models = copy_of(trained, tmp_path)
    out = OUTPUT_LAYER[method]
    damage(models / ("down.pt" if method == "dati" else "down-bc.pt"), out)
    result = detect(trained, models, tmp_path / "r", method)
    one_line_error(result, needle.replace("{out}", re.escape(out)))


CORRIDOR_DAMAGE = [
    ("truncated", truncate, "not a readable .npz"),
    ("not-a-zip", not_an_archive, "not a readable .npz"),
    ("missing-mask", edit_npz(lambda z: z.pop("mask")), "it has no 'mask' array"),
    ("flat-mask", edit_npz(lambda z: _set(z, "mask", z["mask"].ravel())),
     r"'mask' must have shape \[n, n\], got \[\d+\]"),
    ("nan-origin", edit_npz(lambda z: z["origin"].__setitem__(0, np.nan)),
     "'origin' holds non-finite values"),
    ("zero-step", edit_npz(lambda z: z["step"].__setitem__(1, 0.0)),
     r"the cell size \('step'\) must be > 0"),
    ("object-mask", object_array("mask"), "'mask' holds Python objects"),
]  # fmt: skip


@pytest.mark.parametrize("method", ["dati", "bc"])
@pytest.mark.parametrize("damage, needle", [d[1:] for d in CORRIDOR_DAMAGE],
                         ids=[d[0] for d in CORRIDOR_DAMAGE])  # fmt: skip
def test_a_damaged_corridor_is_one_line(trained, tmp_path, method, damage, needle):
    models = copy_of(trained, tmp_path)
    stem = "down" if method == "dati" else "down-bc"
    damage(models / f"{stem}.corridor.npz")
    result = detect(trained, models, tmp_path / "r", method)
    one_line_error(result, rf"{stem}\.corridor\.npz is not the one its card records")
    card = json.loads((models / f"{stem}.json").read_text())
    card.pop("files")  # a card from before the digests: the corridor's reader refuses it
    (models / f"{stem}.json").write_text(json.dumps(card))
    result = detect(trained, models, tmp_path / "r", method)
    one_line_error(result, rf"cannot load .*{stem}\.corridor\.npz: " + needle)


# ----------------------------------------------------------------------------- item 12
def card_text(models: Path, stem: str) -> str:
    return (models / f"{stem}.json").read_text()


def test_a_deeply_nested_card_is_one_line(trained, tmp_path):
    models = copy_of(trained, tmp_path)
    text = card_text(models, "down")
    deep = '"preset": ' + "[" * 100_000 + "]" * 100_000
    (models / "down.json").write_text(re.sub(r'"preset": "[^"]*"', deep, text, count=1))
    result = detect(trained, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is nested too deeply")
    (models / "down.json").write_text(re.sub(r'"preset": "[^"]*"', '"preset": ' + "[" * 40
                                             + "]" * 40, text, count=1))  # fmt: skip
    result = detect(trained, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is nested more than 32 levels deep")


def test_a_huge_card_is_refused_before_it_is_read(trained, tmp_path):
    models = copy_of(trained, tmp_path)
    with (models / "down.json").open("a") as fh:
        fh.truncate(65 << 20)  # 65 MiB: a sparse file of NUL bytes after the card
    result = detect(trained, models, tmp_path / "r", "dati")
    one_line_error(result, r"model card .*down\.json is 68,157,440 bytes, more than any holds")


COUNTS = [
    ("dati", "data.points", 10**12, r"data\.points must be an integer in \[3, 300000\]"),
    ("bc", "data.points", 10**12, r"data\.points must be an integer in \[3, 300000\]"),
    ("dati", "config.network.hidden_units", 10**6,
     r"config\.network\.hidden_units must be an integer in \[1, 256\]"),
    ("dati", "config.network.hidden_layers", 10**6,
     r"config\.network\.hidden_layers must be an integer in \[1, 16\]"),
    ("dati", "config.network.latent_dim", 10**9,
     r"config\.network\.latent_dim must be an integer in \[1, 256\]"),
    ("bc", "config.hidden_units", 10**6, r"config\.hidden_units must be an integer in \[1, 256\]"),
    ("bc", "config.state_features", 10**6, r"config\.state_features must be an integer in"),
    ("dati", "seeds", [2**70, 1, 2], r"seeds\[0\] must be an integer in \[0, "),
    ("dati", "lane_config.validation_rollouts", 10**9,
     r"lane_config\.validation_rollouts must be an integer in \[1, 1000\]"),
    ("dati", "training.episodes_run", 10**18, r"training\.episodes_run must be an integer in"),
    ("nearest", "data.tracks_used", 10**18, r"data\.tracks_used must be an integer in"),
]  # fmt: skip


@pytest.mark.parametrize("method, field, value, needle", COUNTS,
                         ids=[f"{c[0]}-{c[1]}" for c in COUNTS])  # fmt: skip
def test_counts_in_a_card_have_upper_bounds(trained, tmp_path, method, field, value, needle):
    models = copy_of(trained, tmp_path)
    stem = {"dati": "down", "bc": "down-bc", "nearest": "down-nearest"}[method]
    card = json.loads(card_text(models, stem))
    if field == "seeds":
        value = value[: len(card["seeds"])]
    card_edit(field, value)(card)
    (models / f"{stem}.json").write_text(json.dumps(card))
    result = detect(trained, models, tmp_path / "r", method)
    one_line_error(result, rf"model card .*{stem}\.json: " + needle)


# ----------------------------------------------------------------------------- item 11
@pytest.fixture(scope="module")
def checkpoint(trained, tmp_path_factory):
    """A model folder whose training (--lane fourier=0 pretrain=0 members=1) was interrupted
    after its first episode: it holds the checkpoint `train --resume` continues from."""
    out = tmp_path_factory.mktemp("interrupted")
    settings = TrainSettings(
        trained["proc"], "down", out, episodes=3, max_tracks=2, seed=4,
        lane=lane_config("lanes", RESUME_LANE),
    )  # fmt: skip

    def interrupt(trainer, logs):
        if logs:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_ais(settings, interrupt)
    assert (out / "down.ckpt").is_file()
    return out


def resume(trained, models: Path, *lane: str):
    options = [x for item in lane for x in ("--lane", item)]
    return run(
        "train", "--cluster", "down", "--data", trained["proc"], "--out", models,
        "--episodes", 3, "--max-tracks", 2, "--seed", 4, "--resume", *options,
    )  # fmt: skip


def test_resume_without_the_lane_options_names_the_ones_that_differ(trained, checkpoint, tmp_path):
    models = tmp_path / "m"
    shutil.copytree(checkpoint, models)
    result = resume(trained, models)
    one_line_error(
        result,
        r"the checkpoint .*down\.ckpt was written with --lane members=1 pretrain=0 fourier=0, "
        r"this run has members=3 pretrain=50 fourier=6: pass the same --lane options or drop "
        r"--resume",
    )
    result = resume(trained, models, "fourier=0", "pretrain=0")
    one_line_error(result, r"written with --lane members=1, this run has members=3")
    # a checkpoint from before a lane setting existed ran as its default does: it resumes
    edit_checkpoint(lambda d: d["identity"]["lane"].pop("validate_by"))(models / "down.ckpt")
    result = resume(trained, models, *RESUME_LANE)
    assert result.exit_code == 0, result.output


def edit_checkpoint(edit):
    def damage(path: Path) -> None:
        doc = torch.load(path, weights_only=True)
        edit(doc)
        torch.save(doc, path)

    return damage


OUT_BIAS = "forward_actor.out.bias"


def _first_dtw(doc):
    return doc["trainer"]["env_episodes"][0]["dtw"]


CHECKPOINT_DAMAGE = [
    ("truncated", truncate,
     r"cannot read checkpoint .*down\.ckpt: damaged or not a checkpoint \(.*PytorchStreamReader"),
    ("not-a-torch-file", not_an_archive,
     r"cannot read checkpoint .*down\.ckpt: damaged or not a checkpoint \("),
    ("no-identity", edit_checkpoint(lambda d: d.pop("identity")),
     r"checkpoint .*down\.ckpt is damaged: it has no identity"),
    ("no-buffer", edit_checkpoint(lambda d: d["trainer"].pop("buffer")),
     r"checkpoint .*down\.ckpt is damaged \(it has no 'buffer' entry\): delete it or drop"),
    ("missing-weight", edit_checkpoint(lambda d: d["trainer"]["nets"].pop(OUT_BIAS)),
     r"is damaged \(Missing key\(s\) in state_dict: \"forward_actor\.out\.bias\"\."),
    ("wrong-size", edit_checkpoint(lambda d: _reshaped(d["trainer"]["nets"],
                                                       "forward_actor.out.weight")),
     r"is damaged \(size mismatch for forward_actor\.out\.weight: copying a param with shape "
     r"\[1, 32, 4\] from checkpoint, the shape in current model is \[1, 32, 3\]"),
    ("nan-weight", edit_checkpoint(lambda d: d["trainer"]["nets"]["forward_actor.out.weight"]
                                   .fill_(np.nan)),
     r"is damaged: trainer\.nets\.forward_actor\.out\.weight holds NaN or inf"),
    ("dtw-state-too-long", edit_checkpoint(lambda d: _first_dtw(d).__setitem__("n", 10**6)),
     r"is damaged \(DTW state: _a must have shape \(1000000, 3\)"),
    ("foreign-order", edit_checkpoint(lambda d: d["source"][0].__setitem__("order", [7, 9])),
     r"is damaged \(episode order \[7, 9\] is not one of 2 tracks\)"),
    ("foreign-track", edit_checkpoint(lambda d: d.__setitem__("current", [99999])),
     r"is damaged: its episodes run on tracks \[99999\] this run does not train on"),
]  # fmt: skip


@pytest.mark.parametrize("damage, needle", [d[1:] for d in CHECKPOINT_DAMAGE],
                         ids=[d[0] for d in CHECKPOINT_DAMAGE])  # fmt: skip
def test_resume_from_a_damaged_checkpoint_is_one_line(trained, checkpoint, tmp_path, damage,
                                                      needle):  # fmt: skip
    models = tmp_path / "m"
    shutil.copytree(checkpoint, models)
    damage(models / "down.ckpt")
    one_line_error(resume(trained, models, *RESUME_LANE), needle)
