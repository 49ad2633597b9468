"""What the commands print (`aisdati.commands.tables`): paths that hold rich markup are printed
as they are (issue 27, item 14)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers.cli import run
from tests.helpers.models import INGEST, detect_args, evaluate_args, train_ny_nearest

NY_HOUR = Path(__file__).parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"


def printed(result, text: str) -> bool:
    """Whether `text` (a path) is in what the command printed, however rich wrapped it."""
    return text in result.output.replace("\n", "")


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """The NY hour ingested (tracks of >= 30 reports) and a `nearest` model of its `down`."""
    return train_ny_nearest(tmp_path_factory.mktemp("outputs"))


# --------------------------------------------------------------------------------- item 14
@pytest.mark.parametrize("name", ["a[/]b", "r[x]", "[bold]c"])
def test_paths_with_rich_markup_are_printed_as_they_are(world, tmp_path, name):
    out = tmp_path / name
    result = run(*detect_args(world, out))
    assert result.exit_code == 0, result.output
    assert printed(result, str(out)), result.output
    models = tmp_path / f"models{name}"
    result = run(
        "train", "--cluster", "down", "--method", "nearest", "--data", world["proc"],
        "--out", models,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert printed(result, str(models / "down-nearest")), result.output
    proc = tmp_path / f"proc{name}"
    result = run("ingest", "--input", NY_HOUR, *INGEST, "--out", proc)
    assert result.exit_code == 0, result.output
    assert printed(result, str(proc / "points.parquet")), result.output


def test_an_evaluate_folder_with_rich_markup_is_printed_as_it_is(kitimat, tmp_path):
    out = tmp_path / "e[/]v[x]"
    result = run(*evaluate_args(kitimat, out))
    assert result.exit_code == 0, result.output
    assert printed(result, str(out)), result.output
