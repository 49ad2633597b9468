"""Shared fixtures of the test suite."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
import torch
import typer
from typer.testing import CliRunner

DATA = Path(__file__).parent / "data"
KITIMAT = DATA / "AIS_2018_07-08_Kitimat.csv.gz"


def pytest_configure(config: pytest.Config) -> None:
    """pytest-xdist's workers ignore SIGINT (the controller takes Ctrl-C), and a child process
    inherits an ignored signal: restore it, so the CLI processes the tests start see Ctrl-C as
    a shell would give it to them."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture
def data() -> Path:
    """Folder of the small real AIS files (see tests/data/PROVENANCE.md)."""
    return DATA


@pytest.fixture
def cli():
    """`cli("ingest", "--input", ...)` runs `aisdati` in-process and returns click's Result."""
    from aisdati.cli import app

    def run(*args: str):
        args_list = [str(a) for a in args]
        # Typer collapses an app with a single command into that command.
        if not hasattr(typer.main.get_command(app), "commands"):
            args_list = args_list[1:]
        return CliRunner().invoke(app, args_list)

    return run


@pytest.fixture(autouse=True)
def one_thread():
    """Two cores, possibly shared with a training job: keep torch to one thread (its OpenMP
    threads spin-wait, and on a busy machine a second thread makes small matmuls 10x slower)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="session")
def kitimat(tmp_path_factory) -> Path:
    """The Kitimat two months ingested once (`--roi none --min-points 100`, the defaults
    otherwise): 158 tracks, the busiest lane as route-1 and route-2."""
    from aisdati.cli import app

    out = tmp_path_factory.mktemp("kitimat")
    args = ["ingest", "--input", str(KITIMAT), "--roi", "none", "--min-points", "100"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="session")
def processed(tmp_path_factory) -> Path:
    """The NY Harbor hour ingested once (`--roi none --min-points 30`): read, never changed."""
    from aisdati.cli import app

    out = tmp_path_factory.mktemp("processed")
    args = ["ingest", "--input", str(DATA / "NYHarbor_2020_06_30_first_hour.csv"), "--roi", "none"]
    result = CliRunner().invoke(app, [*args, "--min-points", "30", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="session")
def months(kitimat) -> tuple[list, list, object]:
    """Kitimat's July tracks (training), August's (judged) and the track table."""
    from aisdati.tracks.store import load_tracks, read_track_table
    from tests.helpers.area import AUGUST

    table = read_track_table(kitimat)
    july = table["start"] < AUGUST
    ids = lambda mask: [int(i) for i in table.loc[mask, "track_id"]]  # noqa: E731
    return load_tracks(kitimat, ids(july)), load_tracks(kitimat, ids(~july)), table


@pytest.fixture(scope="session")
def real(kitimat) -> list:
    """The positions of Kitimat's first 40 tracks, for the kernels' checks on real tracks."""
    from aisdati.tracks.store import load_tracks, read_track_table

    ids = read_track_table(kitimat)["track_id"].tolist()[:40]
    return [t.positions for t in load_tracks(kitimat, ids)]


@pytest.fixture(scope="session")
def ny_dati(tmp_path_factory) -> dict:
    """The NY hour ingested (tracks of >= 30 reports) and a 2-episode dati model of its `down`
    cluster ({"base", "proc", "models"}), built once per worker: tests copy it before they damage
    it."""
    from tests.helpers.models import train_ny_dati

    return train_ny_dati(tmp_path_factory.mktemp("detect"))


@pytest.fixture(scope="session")
def ny_models(tmp_path_factory) -> dict:
    """The NY hour ingested (tracks of >= 30 reports) and 2-episode dati, bc and nearest models
    of its `down` cluster ({"proc", "models"}; the lanes preset without pretraining), built once
    per worker: tests copy them before they damage them."""
    from tests.helpers.models import train_ny_models

    return train_ny_models(tmp_path_factory.mktemp("models"))
