"""What every figure shares (`aisdati.plots`): user strings (an input's or a model's name)
are drawn as they are, not read as mathtext (issue 27, item 15)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.helpers.cli import run
from tests.helpers.models import INGEST, train_ny_nearest

NY_HOUR = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """The NY hour ingested (tracks of >= 30 reports) and a `nearest` model of its `down`."""
    return train_ny_nearest(tmp_path_factory.mktemp("outputs"))


# --------------------------------------------------------------------------------- item 15
def test_mathtext_in_an_input_name_is_drawn_as_it_is(tmp_path):
    src = tmp_path / "$\\q$.csv"
    shutil.copy(NY_HOUR, src)
    out = tmp_path / "processed"
    result = run("ingest", "--input", src, *INGEST, "--out", out)
    assert result.exit_code == 0, result.output
    assert (out / "routes.png").stat().st_size > 10_000
    assert sorted(p.name for p in out.iterdir()) == [
        "identities.parquet", "ingest_report.json", "points.parquet", "reports.parquet",
        "routes.geojson",
        "routes.parquet", "routes.png", "tracks.parquet", "vessels.parquet",
    ]  # fmt: skip


def test_mathtext_in_a_model_name_is_drawn_as_it_is(world, tmp_path):
    models = tmp_path / "models"
    models.mkdir()
    for f in world["models"].glob("down-nearest.*"):
        shutil.copy(f, models / f.name.replace("down-nearest", "$\\q$"))
    out = tmp_path / "report"
    result = run(
        "detect", "--data", world["proc"], "--models", models, "--model", "$\\q$",
        "--method", "nearest", "--out", out, "--near-km", 20, "--top-percent", 50,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert list((out / "evidence").glob("track-*.png"))
