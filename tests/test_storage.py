"""Model folders at a URL (`aisdati.storage`), on a real FTP server on 127.0.0.1 (pyftpdlib):
models trained on two Dask workers and copied there are those trained into a local folder, and
judging with them by URL gives the scores of the local folder; a wrong address, a refused login
and a protocol whose package is missing are one line, exit 2."""

from __future__ import annotations

import importlib.util
import json
import logging
import re
import threading
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
import torch

from aisdati.ais.space import lane_config
from aisdati.ais.training import TrainSettings
from aisdati.storage import RemoteFolder
from tests.helpers.cli import one_line_error, run

pytest.importorskip("pyftpdlib")
distributed = pytest.importorskip("distributed")

ROUTES = ("route-3", "route-4")
"""The two smallest Kitimat routes: DATI trains them in seconds."""


@pytest.fixture(scope="module")
def ftp(tmp_path_factory) -> Iterator[tuple[str, Path]]:
    """(the URL of a writable folder, the server's disk root) of an FTP server in a thread."""
    from pyftpdlib.authorizers import DummyAuthorizer
    from pyftpdlib.handlers import FTPHandler
    from pyftpdlib.servers import FTPServer

    quiet = logging.getLogger("pyftpdlib")  # a handler of its own: it then logs nothing to stderr
    quiet.addHandler(logging.NullHandler())
    quiet.setLevel(logging.WARNING)
    root = tmp_path_factory.mktemp("ftp-root")
    users = DummyAuthorizer()
    users.add_user("analyst", "s3cret", str(root), perm="elradfmwMT")
    server = FTPServer(("127.0.0.1", 0), type("Handler", (FTPHandler,), {"authorizer": users}))
    port = server.socket.getsockname()[1]
    thread = threading.Thread(target=server.serve_forever, kwargs={"timeout": 0.2}, daemon=True)
    thread.start()
    yield f"ftp://analyst:s3cret@127.0.0.1:{port}", root
    server.close_all()
    thread.join(timeout=5)


def route_settings(data: Path, out: Path | None, url: str | None) -> list[TrainSettings]:
    lane = lane_config("lanes", ("pretrain=1", "members=1"))
    common = {"out_dir": out, "publish_to": url, "lane": lane, "episodes": 1, "max_tracks": 5}
    return [TrainSettings(data_dir=data, cluster=r, **common) for r in ROUTES]


def test_models_trained_on_two_workers_and_copied_to_a_url_are_the_local_ones(
    kitimat, ftp, tmp_path
):
    """Each task trains into a staging folder on its worker and copies the model to the
    server: the same weights and cards as a training into a local folder, no checkpoint and no
    temporary file left there, and `Trained.model` names the URL without its password."""
    from aisdati.detectors.train import train_routes
    from aisdati.execution.runner import DaskRunner

    url, root = ftp
    local = tmp_path / "local"
    train_routes("dati", route_settings(kitimat, local, None))
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        trained = train_routes(
            "dati", route_settings(kitimat, None, f"{url}/dati"), runner=DaskRunner(client)
        )
    shown = url.replace("s3cret", "***")
    assert [t.model for t in trained] == [f"{shown}/dati/{r}.pt" for r in ROUTES]
    there = root / "dati"
    assert sorted(p.name for p in there.iterdir()) == sorted(
        p.name for p in local.iterdir() if p.suffix != ".ckpt"
    )
    for route in ROUTES:
        a = torch.load(local / f"{route}.pt", weights_only=True)
        b = torch.load(there / f"{route}.pt", weights_only=True)
        for key, value in a.items():
            if isinstance(value, torch.Tensor):
                assert torch.equal(value, b[key]), (route, key)
            assert untimed(local / f"{route}.json") == untimed(there / f"{route}.json")


def untimed(card: Path) -> dict:
    """A model card without what differs between two trainings of the same model: when it was
    made and how long it took."""
    doc = json.loads(card.read_text())
    doc.pop("created")
    for timing in ("wall_seconds", "steps_per_second"):
        doc["training"].pop(timing)
    return doc


def train_nearest_routes(data: Path, out: str | Path) -> None:
    trained = run(
        "train", "--cluster", "routes", "--method", "nearest", "--data", data, "--out", out,
    )  # fmt: skip
    assert trained.exit_code == 0, trained.output


@pytest.fixture(scope="module")
def nearest_url(kitimat, ftp) -> str:
    """The URL of a folder of nearest route models trained with `train --out URL`."""
    train_nearest_routes(kitimat, f"{ftp[0]}/nearest")
    return f"{ftp[0]}/nearest"


def test_train_and_detect_by_url_judge_as_a_local_folder(kitimat, ftp, nearest_url, tmp_path):
    """`train --out URL` then `detect --models URL` (every model, and one named) write the
    scores that the same commands give with a local folder."""
    models, root = nearest_url, ftp[1]
    train_nearest_routes(kitimat, tmp_path / "models")
    assert sorted(p.name for p in (root / "nearest").glob("*.json")) == sorted(
        p.name for p in (tmp_path / "models").glob("*.json")
    )
    for named in ((), ("--model", "route-1-nearest")):
        scores = []
        for source in (models, tmp_path / "models"):
            out = tmp_path / f"detect-{len(scores)}-{len(named)}"
            result = run(
                "detect", "--data", kitimat, "--models", source, *named, "--method", "nearest",
                "--cluster", "all", "--out", out,
            )  # fmt: skip
            assert result.exit_code == 0, result.output
            scores.append(pd.read_parquet(out / "scores.parquet"))
        assert len(scores[0]) > 0
        pd.testing.assert_frame_equal(scores[0], scores[1])


def test_one_model_trained_to_a_url_is_named_by_it(kitimat, ftp):
    url, root = ftp
    result = run(
        "train", "--cluster", "route-3", "--method", "nearest", "--data", kitimat,
        "--out", f"{url}/single", "--json",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    shown = url.replace("s3cret", "***")
    assert json.loads(result.stdout)["model"] == f"{shown}/single/route-3-nearest.json"
    assert "s3cret" not in result.output
    assert (root / "single" / "route-3-nearest.json").is_file()
    assert not [p for p in (root / "single").iterdir() if p.name.endswith(".tmp")]


def test_a_missing_model_at_a_url_is_one_line(kitimat, ftp, nearest_url, tmp_path):
    url, _ = ftp
    result = run(
        "detect", "--data", kitimat, "--models", f"{url}/nothing-here", "--out", tmp_path / "r"
    )
    one_line_error(result, r"--models ftp://analyst:\*\*\*@127\.0\.0\.1:\d+/nothing-here")
    result = run(
        "detect", "--data", kitimat, "--models", nearest_url, "--model", "no-such",
        "--out", tmp_path / "r",
    )  # fmt: skip
    assert "s3cret" not in result.output
    one_line_error(result, "no model 'no-such' at ftp://analyst:\\*\\*\\*@")
    # models there, but none of what was asked: named by the URL, not the local copy
    result = run(
        "detect", "--data", kitimat, "--models", nearest_url, "--method", "dati",
        "--out", tmp_path / "r",
    )  # fmt: skip
    one_line_error(result, r"no dati models in ftp://analyst:\*\*\*@127\.0\.0\.1:\d+/nearest")
    result = run(
        "evaluate", "--data", kitimat, "--cluster", "other", "--detectors", "nearest",
        "--models", nearest_url, "--out", tmp_path / "e",
    )  # fmt: skip
    assert result.exit_code == 2 and "Traceback" not in result.output  # after its progress line
    assert re.search(r"^error: .* for nearest in ftp://analyst:\*\*\*@127\.0\.0\.1:\d+/nearest$",
                     result.stderr.strip().splitlines()[-1]), result.stderr  # fmt: skip


def test_a_url_that_cannot_be_written_is_one_line_before_training(kitimat, ftp, tmp_path):
    url, root = ftp
    refused = url.replace("s3cret", "wrong") + "/m"
    result = run("train", "--cluster", "route-3", "--data", kitimat, "--out", refused)
    one_line_error(result, r"--out ftp://analyst:\*\*\*@.*: cannot connect: 530")
    assert not (root / "m").exists()
    result = run("train", "--cluster", "route-3", "--data", kitimat, "--out", f"{url}/m",
                 "--resume")  # fmt: skip
    one_line_error(result, "--resume needs a local --out folder")


@pytest.mark.skipif(importlib.util.find_spec("s3fs") is not None, reason="s3fs is installed")
def test_a_protocol_whose_package_is_missing_names_it(kitimat, tmp_path):
    result = run("train", "--cluster", "route-3", "--data", kitimat, "--out", "s3://b/models")
    one_line_error(result, r"s3:// needs a package that is not installed \(.*s3fs")


def test_the_shown_url_hides_only_the_password():
    folder = RemoteFolder("ftp://user:pa:ss@host:21/models")
    assert folder.shown == "ftp://user:***@host:21/models"
    assert RemoteFolder("s3://bucket/models").shown == "s3://bucket/models"
