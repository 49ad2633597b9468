"""`--device`: where DATI's networks run. On this machine (no GPU) `auto` is the CPU and a GPU
asked for is one line and exit 2 before anything is written; where torch sees CUDA, the tests
at the end train and score on it and compare with the CPU (run them on a GPU machine:
`pytest tests/execution/test_device.py`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings
from aisdati.errors import UserError
from aisdati.execution import resolve_device
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.selftest.families import get_family
from aisdati.selftest.sources import make_family_env
from tests.helpers.cli import one_line_error, run

GPU = torch.cuda.is_available()
needs_gpu = pytest.mark.skipif(not GPU, reason="torch sees no CUDA device")


@pytest.mark.skipif(GPU, reason="auto picks the GPU here")
def test_auto_is_the_cpu_where_torch_sees_no_gpu():
    assert resolve_device("auto") == "cpu"
    assert resolve_device(" CPU ") == "cpu"
    with pytest.raises(UserError, match="torch sees no CUDA device"):
        resolve_device("cuda:1")


def test_a_device_torch_does_not_know_is_refused():
    with pytest.raises(UserError, match="--device must be auto, cpu, cuda or cuda:N, got 'tpu'"):
        resolve_device("tpu")


@pytest.mark.skipif(GPU, reason="the GPU is there")
@pytest.mark.parametrize(
    "command",
    [
        ("train", "--cluster", "route-4"),
        ("detect", "--cluster", "all"),
        ("evaluate", "--cluster", "route-4"),
        ("selftest", "--quick"),
    ],
)
def test_a_gpu_that_is_not_there_is_one_line_before_any_output(command, kitimat, tmp_path):
    args = [*command, "--device", "cuda", "--out", tmp_path / "out"]
    if command[0] != "selftest":
        args += ["--data", kitimat]
    one_line_error(run(*args), "--device cuda: torch sees no CUDA device .*use --device cpu")
    assert not (tmp_path / "out").exists()


def test_the_cpu_device_trains_what_the_default_trains():
    """`device="cpu"` is the default path itself: the same weights after a few steps."""

    def envs():
        return [make_family_env(replace(get_family("circles"), steps=12)) for _ in range(2)]

    cfg = DATIConfig(batch_size=16)
    default, cpu = DATITrainer(envs(), [0, 1], cfg), DATITrainer(envs(), [0, 1], cfg, device="cpu")
    for _ in range(3):
        default.step()
        cpu.step()
    for (name, a), b in zip(default.nets.named_parameters(), cpu.nets.parameters(), strict=True):
        assert torch.equal(a, b), name


# ------------------------------------------------------------------------- where there is one
@needs_gpu
def test_dati_steps_on_the_gpu_as_on_the_cpu():
    """Same seeds, same draws (taken on the CPU): after a few steps with a member leaving, the
    GPU's networks equal the CPU's to float rounding."""

    def trained(device: str) -> DATITrainer:
        envs = [make_family_env(replace(get_family("circles"), steps=12)) for _ in range(3)]
        trainer = DATITrainer(envs, [0, 1, 2], DATIConfig(batch_size=16), device=device)
        for step in range(6):
            trainer.step()
            if step == 2:
                trainer.remove_members([1])
        return trainer

    cpu, gpu = trained("cpu"), trained("cuda:0")
    assert next(gpu.nets.parameters()).is_cuda
    for (name, a), b in zip(cpu.nets.named_parameters(), gpu.nets.parameters(), strict=True):
        torch.testing.assert_close(a, b.cpu(), atol=1e-4, rtol=1e-3, msg=name)


@needs_gpu
def test_a_route_trains_and_scores_on_the_gpu_close_to_the_cpu(kitimat, tmp_path):
    """`train --device cuda:0` writes a model that loads anywhere; its scores on the GPU equal
    the CPU's to float rounding."""
    from aisdati.detectors import load_detectors
    from aisdati.detectors.scoring import ScoreSettings
    from aisdati.detectors.train import train_routes
    from aisdati.tracks.store import load_tracks, read_track_table

    lane = lane_config("lanes", ("pretrain=1", "members=1"))
    settings = TrainSettings(
        data_dir=kitimat, cluster="route-4", out_dir=tmp_path, lane=lane, episodes=1,
        max_tracks=5, device="cuda:0",
    )  # fmt: skip
    train_routes("dati", [settings])
    (model,) = load_detectors(tmp_path, ["route-4"])
    ids = read_track_table(kitimat)["track_id"].to_numpy()[:12]
    tracks = load_tracks(kitimat, [int(i) for i in ids])
    how = replace(ScoreSettings(), lane_rollouts=4, rollouts=2, lane_traffic=False)
    on_cpu = model.score(tracks, how).score
    model.to_device("cuda:0")
    on_gpu = model.score(tracks, how).score
    np.testing.assert_allclose(on_gpu, on_cpu, rtol=1e-3, atol=1.0)
