"""Loading a folder's models (`aisdati.detectors.registry`)."""

from __future__ import annotations

import pytest

from tests.helpers.cli import one_line_error, run


@pytest.mark.parametrize("cluster", ["all", "down"])
def test_detect_before_train_suggests_training_the_cluster_asked_for(processed, tmp_path, cluster):
    """Issue 69, item 6: `--cluster all` was told to `aisdati train --cluster up`."""
    empty = tmp_path / "models"
    empty.mkdir()
    result = run(
        "detect", "--cluster", cluster, "--data", processed, "--models", empty,
        "--out", tmp_path / "report",
    )  # fmt: skip
    one_line_error(result, f"no models in .*run `aisdati train --cluster {cluster}` first")
