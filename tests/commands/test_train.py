"""`aisdati train` stopped by a real signal in its first episode says that no model was saved
(issue 13, item 17)."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest

from tests.helpers.processes import aisdati, wait_for

DATA = Path(__file__).parents[1] / "data"


# --------------------------------------------------------------------------------- item 17
@pytest.fixture(scope="module")
def long_track(tmp_path_factory):
    """One real Kitimat track of 493 reports: a first training episode takes many seconds."""
    from typer.testing import CliRunner

    from aisdati.cli import app

    out = tmp_path_factory.mktemp("kitimat")
    args = ["ingest", "--input", str(DATA / "AIS_2018_07-08_Kitimat.csv.gz"), "--roi", "none"]
    args += ["--dwell-time", "0"]  # keep the 493 reports in one
    result = CliRunner().invoke(app, [*args, "--min-points", "300", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize(
    "sig, rc, word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")]
)
def test_stopping_the_first_training_episode_says_no_model_was_saved(
    long_track, tmp_path, sig, rc, word
):
    models = tmp_path / "models"
    proc = aisdati(
        "train", "--cluster", "other", "--data", long_track, "--out", models,
        "--episodes", "1", "--max-tracks", "1",
    )  # fmt: skip
    wait_for(models.is_dir, proc)  # the output folder is prepared just before training
    time.sleep(1.0)
    assert not (models / "other.pt").exists()  # still in the first episode
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == rc, err
    message = " ".join(err.split())
    assert f"{word}: stopped during the first episode, before any model was saved" in message
    assert "best episode so far" not in message and "Traceback" not in err
    assert sorted(p.name for p in models.iterdir()) == []
