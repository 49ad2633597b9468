"""The README's train-on-July, detect-on-August workflow, run as the README writes it, on the
shipped Kitimat sample (issue 69, item 2): the commands are read from README.md, so a change to
them there is what is tested."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from tests.helpers.cli import run

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
MONTHS = ("july", "august")
QUICK = ("--method", "nearest")
"""Added to `train` only, to keep the test near 30 s: the README's line trains the area's default
(behaviour cloning, 170 episodes: minutes). `detect` takes whichever model the folder holds."""


def readme_command(command: str, data: str) -> list[str]:
    """The arguments of the README's `aisdati COMMAND` line that names `data` (comment dropped)."""
    lines = [
        line.split("#", 1)[0]
        for line in README.read_text(encoding="utf-8").splitlines()
        if line.startswith(f"aisdati {command} ") and re.search(rf"\s{re.escape(data)}(\s|$)", line)
    ]
    assert len(lines) == 1, f"README.md should hold one `aisdati {command}` line with {data}"
    return shlex.split(lines[0])[1:]


def test_readme_trains_on_july_and_detects_on_august(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(ROOT / "tests" / "data")
    monkeypatch.chdir(tmp_path)
    commands = [
        readme_command("ingest", "data/july"),
        readme_command("ingest", "data/august"),
        [*readme_command("train", "data/july"), *QUICK],
        readme_command("detect", "data/august"),
    ]
    for args in commands:
        result = run(*args)
        assert result.exit_code == 0, f"aisdati {shlex.join(args)}:\n{result.output}"
    cut = pd.Timestamp("2018-08-01", tz="UTC")
    july, august = (pq.read_table(f"data/{m}/tracks.parquet").to_pandas() for m in MONTHS)
    assert len(july) > 100 and (july["end"] < cut).all()
    assert len(august) > 20 and (august["start"] >= cut).all()
    for month in MONTHS:
        report = json.loads(Path(f"data/{month}/ingest_report.json").read_text())
        assert report["rejected"]["outside_period"] > 0
        assert report["rows_read"] == report["rejected_total"] + report["kept_points"]
    detected = json.loads(Path("reports/august/report.json").read_text())
    assert detected["coverage"]["judged"] == len(august)
    assert Path("reports/august/map.html").is_file()


@pytest.mark.parametrize("data", ["data/july", "data/august"])
def test_readme_makes_the_folders_it_trains_and_detects_on(data: str) -> None:
    """Every folder a README command reads is one an `ingest` line of the README writes."""
    assert readme_command("ingest", data)[-2:] == ["--out", data]
