"""An interrupted `aisdati train` resumed with --resume ends exactly like an uninterrupted run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from aisdati.ais import DEFAULT_PRESET
from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings, train_ais
from aisdati.cli import app

DATA = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    out = tmp_path_factory.mktemp("processed")
    args = ["ingest", "--input", str(DATA), "--roi", "none", "--min-points", "30", "--out"]
    result = CliRunner().invoke(app, [*args, str(out)])
    assert result.exit_code == 0, result.output
    return out


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
