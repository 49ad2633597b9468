"""DATI training on real AIS tracks (`aisdati.ais.training`): an interrupted `aisdati train`
resumed with --resume ends exactly like an uninterrupted run; resuming beside a damaged card
trains, and resuming without the checkpoint's lane options or from a damaged checkpoint is one
line (issue 13, item 8; issue 27, item 11)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from aisdati.ais import DEFAULT_PRESET
from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings, train_ais
from aisdati.cli import app
from tests.helpers.cli import one_line_error, run
from tests.helpers.models import card_of, not_an_archive, truncate

DATA = Path(__file__).parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"


@pytest.mark.parametrize("lane", [()], ids=["live-actor"])
def test_resume_equals_uninterrupted(processed, tmp_path, lane):
    def settings(out: str, resume: bool = False) -> TrainSettings:
        return TrainSettings(
            processed,
            "down",
            tmp_path / out,
            episodes=3,
            max_tracks=2,
            seed=4,
            resume=resume,
            lane=lane_config(DEFAULT_PRESET, lane),
        )

    full = train_ais(settings("a"))

    done_at_interrupt: list[int] = []

    def interrupt(trainer, logs):
        # the first episode end: the other members of the seed ensemble are mid-episode
        if logs and logs[-1].episode == 1:
            done_at_interrupt.append(len(trainer.history))
            assert any(env.t > 0 for env in trainer.envs)
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_ais(settings("b"), interrupt)
    assert (tmp_path / "b" / "down.ckpt").is_file()
    assert (tmp_path / "b" / "down.pt").is_file()  # usable model after Ctrl-C
    resumed = train_ais(settings("b", resume=True))
    assert resumed.resumed_from == done_at_interrupt[0]
    assert [h.mean_loss for h in resumed.history] == [h.mean_loss for h in full.history]
    a = torch.load(tmp_path / "a" / "down.pt", weights_only=True)
    b = torch.load(tmp_path / "b" / "down.pt", weights_only=True)
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    log_a = [json.loads(x) for x in (tmp_path / "a" / "down.log.jsonl").read_text().splitlines()]
    log_b = [json.loads(x) for x in (tmp_path / "b" / "down.log.jsonl").read_text().splitlines()]
    assert [r["mean_loss"] for r in log_a] == [r["mean_loss"] for r in log_b]
    assert not (tmp_path / "b" / "down.ckpt").exists()  # finished runs leave no checkpoint


def test_resume_of_another_run_is_refused(processed, tmp_path):
    def interrupt(trainer, logs):
        if logs:
            raise KeyboardInterrupt

    first = TrainSettings(processed, "down", tmp_path, episodes=3, max_tracks=2, seed=4)
    with pytest.raises(KeyboardInterrupt):
        train_ais(first, interrupt)
    args = ["train", "--cluster", "down", "--data", str(processed), "--out", str(tmp_path)]
    result = CliRunner().invoke(app, [*args, "--max-tracks", "2", "--seed", "5", "--resume"])
    assert result.exit_code == 2
    assert "belongs to another run" in result.output


def test_resume_beside_a_damaged_card_trains_without_a_traceback(ny_dati, tmp_path):
    models = tmp_path / "models"
    shutil.copytree(ny_dati["models"], models)
    (models / "down.json").write_text("[1, 2]")  # valid JSON, no card
    result = run(
        "train", "--cluster", "down", "--data", ny_dati["proc"], "--out", models,
        "--episodes", 1, "--max-tracks", 3, "--seed", 1, "--resume",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert card_of(models)["training"]["finished"] is True


RESUME_LANE = ("fourier=0", "pretrain=0", "members=1")
"""The checkpoint's lane settings (small and fast); a run without them has the preset's."""


def _reshaped(state, key):
    state[key] = torch.zeros(*state[key].shape[:-1], state[key].shape[-1] + 1)


# ----------------------------------------------------------------------------- item 11
@pytest.fixture(scope="module")
def checkpoint(ny_models, tmp_path_factory):
    """A model folder whose training (--lane fourier=0 pretrain=0 members=1) was interrupted
    after its first episode: it holds the checkpoint `train --resume` continues from."""
    out = tmp_path_factory.mktemp("interrupted")
    settings = TrainSettings(
        ny_models["proc"], "down", out, episodes=3, max_tracks=2, seed=4,
        lane=lane_config("lanes", RESUME_LANE),
    )  # fmt: skip

    def interrupt(trainer, logs):
        if logs:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_ais(settings, interrupt)
    assert (out / "down.ckpt").is_file()
    return out


def resume(ny_models, models: Path, *lane: str):
    options = [x for item in lane for x in ("--lane", item)]
    return run(
        "train", "--cluster", "down", "--data", ny_models["proc"], "--out", models,
        "--episodes", 3, "--max-tracks", 2, "--seed", 4, "--resume", *options,
    )  # fmt: skip


def test_resume_without_the_lane_options_names_the_ones_that_differ(
    ny_models, checkpoint, tmp_path
):
    models = tmp_path / "m"
    shutil.copytree(checkpoint, models)
    result = resume(ny_models, models)
    one_line_error(
        result,
        r"the checkpoint .*down\.ckpt was written with --lane members=1 pretrain=0 fourier=0, "
        r"this run has members=3 pretrain=50 fourier=6: pass the same --lane options or drop "
        r"--resume",
    )
    result = resume(ny_models, models, "fourier=0", "pretrain=0")
    one_line_error(result, r"written with --lane members=1, this run has members=3")
    # a checkpoint from before a lane setting existed ran as its default does: it resumes
    edit_checkpoint(lambda d: d["identity"]["lane"].pop("validate_by"))(models / "down.ckpt")
    result = resume(ny_models, models, *RESUME_LANE)
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
def test_resume_from_a_damaged_checkpoint_is_one_line(ny_models, checkpoint, tmp_path, damage,
                                                      needle):  # fmt: skip
    models = tmp_path / "m"
    shutil.copytree(checkpoint, models)
    damage(models / "down.ckpt")
    one_line_error(resume(ny_models, models, *RESUME_LANE), needle)
