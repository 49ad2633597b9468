"""Tasks on a real Dask cluster of local worker processes (`aisdati.execution`): training and
scoring give what they give in this process, a worker killed mid-training changes nothing and
loses no model, and a scheduler nobody runs is one line and exit 2."""

from __future__ import annotations

import os
import signal
import socket
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings
from aisdati.errors import UserError
from aisdati.execution import Execution, InProcess, InThreads, open_runner
from aisdati.execution.runner import DaskRunner
from tests.helpers.cli import one_line_error, run

distributed = pytest.importorskip("distributed")

ROUTES = ("route-3", "route-4")
"""The two smallest Kitimat routes (7 and 6 tracks): DATI trains them in seconds."""


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes of one thread each, as `--workers 2` starts them."""
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as local,
        distributed.Client(local) as client,
    ):
        yield client


def settings_of(data: Path, out: Path) -> list[TrainSettings]:
    lane = lane_config("lanes", ("pretrain=1", "members=1"))
    return [
        TrainSettings(data_dir=data, cluster=r, out_dir=out, lane=lane, episodes=1, max_tracks=5)
        for r in ROUTES
    ]


def weights(folder: Path) -> dict[str, dict[str, torch.Tensor]]:
    return {p.stem: torch.load(p, weights_only=True) for p in sorted(folder.glob("route-*.pt"))}


def assert_same_models(a: Path, b: Path) -> None:
    wa, wb = weights(a), weights(b)
    assert sorted(wa) == list(ROUTES) and sorted(wb) == list(ROUTES)
    for name in ROUTES:
        for key, value in wa[name].items():
            if isinstance(value, torch.Tensor):
                assert torch.equal(value, wb[name][key]), (name, key)
    assert not list(b.glob("*.ckpt")), "a finished training leaves no checkpoint"


@pytest.fixture(scope="module")
def in_process(kitimat, tmp_path_factory) -> Path:
    """The two routes' DATI models trained here, one task after the other."""
    from aisdati.detectors.train import train_routes

    out = tmp_path_factory.mktemp("in-process")
    train_routes("dati", settings_of(kitimat, out))
    return out


def square(x: int) -> int:
    return x * x


def refuse(x: int) -> int:
    raise UserError(f"task {x} refuses")


def die_once(marker: str, x: int) -> int:
    """Kill this worker process the first time any task runs (a worker lost mid-task)."""
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL)
    except FileExistsError:
        return x + 100
    os.close(fd)
    os.kill(os.getpid(), signal.SIGKILL)
    return -1  # never reached


def test_runners_return_results_in_order_and_say_when_each_ends(cluster):
    for runner in (InProcess(), InThreads(2), DaskRunner(cluster)):
        ended: list[int] = []
        assert runner.map(square, list(range(7)), ended.append) == [x * x for x in range(7)]
        assert sorted(ended) == list(range(7))
    assert DaskRunner(cluster).workers == 2


def started_at(x: int) -> float:
    time.sleep(0.05)
    return time.monotonic()


def test_in_threads_two_tasks_run_at_once_and_an_error_is_raised_here():
    """`InThreads(2)`: a task waiting on another one's start proves both run at once; a task
    that raises raises from `map`, as in one thread."""
    started = threading.Barrier(2, timeout=10)
    assert InThreads(2).map(lambda x: started.wait() * 0 + x, [1, 2]) == [1, 2]
    with pytest.raises(ZeroDivisionError):
        InThreads(2).map(lambda x: 1 // x, [1, 0, 2])


def test_the_costliest_tasks_start_first_and_results_keep_their_order():
    """On one worker the tasks run one at a time: in the order of their costs, largest first
    (so on many workers the last to end is a short one); the results in the items' order."""
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as local,
        distributed.Client(local) as client,
    ):
        runner = DaskRunner(client)
        costs = [3.0, 40.0, 1.0, 12.0, 7.0]
        starts = runner.map(started_at, list(range(5)), costs=costs)
        assert runner.map(square, [1, 2, 3], costs=[1.0, 5.0, 2.0]) == [1, 4, 9]
    assert list(np.argsort(starts)) == [1, 3, 4, 0, 2]


def test_route_tasks_are_costed_by_their_tracks(kitimat):
    from aisdati.detectors.train import training_costs
    from aisdati.tracks.store import read_track_table

    table = read_track_table(kitimat)
    costs = training_costs(settings_of(kitimat, kitimat / "unused"))
    for name, cost in zip(ROUTES, costs, strict=True):
        assert cost == pytest.approx(table.loc[table["route"] == name, "n_points"].mean())
    assert training_costs([TrainSettings(cluster="nowhere")]) == [1.0]


def test_a_task_error_reaches_the_caller_as_itself(cluster):
    with pytest.raises(UserError, match="task 0 refuses"):
        DaskRunner(cluster).map(refuse, [0])


def test_a_task_whose_worker_dies_runs_again_elsewhere(tmp_path):
    import functools

    with open_runner(Execution(workers=2)) as runner:
        task = functools.partial(die_once, str(tmp_path / "died"))
        assert runner.map(task, [1, 2, 3]) == [101, 102, 103]
    assert (tmp_path / "died").exists()


def test_a_worker_killed_during_training_changes_no_model(kitimat, in_process, tmp_path):
    """Two routes on two workers, and SIGKILL the worker that trains one of them while it
    trains: its task runs again on the other (or restarted) worker, and every model is the
    one trained here, in this process."""
    from aisdati.detectors.train import train_routes

    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as local,
        distributed.Client(local) as client,
    ):
        pids = client.run(os.getpid)
        result: dict[str, object] = {}
        ended: list[range] = []

        def train() -> None:
            try:
                result["trained"] = train_routes(
                    "dati", settings_of(kitimat, tmp_path), runner=DaskRunner(client),
                    on_task=ended.append,
                )  # fmt: skip
            except BaseException as exc:  # pragma: no cover - shown by the assert below
                result["error"] = exc

        worker = threading.Thread(target=train)
        worker.start()
        victim = None
        deadline = time.monotonic() + 120
        while victim is None and time.monotonic() < deadline and worker.is_alive():
            busy = [w for w, tasks in client.processing().items() if tasks]
            if busy:
                time.sleep(2.0)  # well into the training (pretraining, the first steps)
                victim = busy[0]
            time.sleep(0.1)
        assert victim is not None, "no task ever ran"
        os.kill(pids[victim], signal.SIGKILL)
        worker.join(timeout=600)
    assert "error" not in result, result.get("error")
    assert [Path(t.model).stem for t in result["trained"]] == list(ROUTES)
    assert sorted(m for r in ended for m in r) == [0, 1]  # one member per route, both ended
    assert_same_models(in_process, tmp_path)


def test_detect_on_two_workers_scores_as_in_process(kitimat, tmp_path):
    """Nearest models of every route (no learning: fast), then `detect --cluster all` in this
    process and on a local cluster of 2 workers: the same scores, row for row, and the same
    map and evidence figures byte for byte (on the cluster, the workers draw them)."""
    models = tmp_path / "models"
    trained = run(
        "train", "--cluster", "routes", "--method", "nearest", "--data", kitimat,
        "--out", models, "--workers", "2",
    )  # fmt: skip
    assert trained.exit_code == 0, trained.output
    assert sorted(p.name for p in models.glob("route-*-nearest.json"))
    scores, figures = {}, {}
    for workers in ("1", "2"):
        out = tmp_path / f"detect-{workers}"
        result = run(
            "detect", "--data", kitimat, "--models", models, "--method", "nearest",
            "--cluster", "all", "--out", out, "--workers", workers,
        )  # fmt: skip
        assert result.exit_code == 0, result.output
        scores[workers] = pd.read_parquet(out / "scores.parquet")
        figures[workers] = {
            p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*.png"))
        }
    assert len(scores["1"]) > 0
    pd.testing.assert_frame_equal(scores["1"], scores["2"])
    assert "map.png" in figures["1"] and any(k.startswith("evidence/") for k in figures["1"])
    assert figures["1"] == figures["2"]


def test_scores_in_chunks_are_the_scores_of_the_whole_set(kitimat, in_process, cluster):
    """More tracks than one scoring task holds: split in chunks on two workers, each track
    scores what it scores in this process."""
    from aisdati.detectors import load_detectors
    from aisdati.detectors.scoring import SCORE_CHUNK, ScoreSettings
    from aisdati.tracks.store import load_tracks, read_track_table

    (model,) = load_detectors(in_process, ["route-4"])
    ids = read_track_table(kitimat)["track_id"].to_numpy()[: SCORE_CHUNK + 3]
    tracks = load_tracks(kitimat, [int(i) for i in ids])
    how = replace(ScoreSettings(), lane_rollouts=2, rollouts=2, lane_traffic=False)
    here = model.score(tracks, how)
    there = model.score(tracks, how, runner=DaskRunner(cluster))
    np.testing.assert_array_equal(here.score, there.score)
    assert len(there.profiles) == len(tracks)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_scheduler_nobody_runs_is_one_line_and_exit_2(kitimat, tmp_path):
    address = f"tcp://127.0.0.1:{free_port()}"
    result = run(
        "detect", "--data", kitimat, "--models", tmp_path, "--out", tmp_path / "r",
        "--workers", address,
    )  # fmt: skip
    one_line_error(result, f"cannot reach the Dask scheduler at {address}")
    assert not (tmp_path / "r" / "report.json").exists()


def test_workers_is_a_count_or_an_address(kitimat, tmp_path):
    result = run("detect", "--data", kitimat, "--models", tmp_path, "--workers", "two")
    one_line_error(result, "--workers 'two': expected a number of processes or a scheduler address")
    assert Execution.parse("3") == Execution(workers=3)
    assert Execution.parse(" tcp://127.0.0.1:1 ") == Execution(scheduler="tcp://127.0.0.1:1")


def test_an_existing_cluster_runs_the_tasks(cluster):
    with open_runner(Execution(scheduler=cluster.scheduler.address)) as runner:
        assert runner.workers == 2
        assert runner.map(square, [3, 4]) == [9, 16]
