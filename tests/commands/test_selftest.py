"""`aisdati selftest` end to end on tiny runs (Table 1's methods and the Table 2 ablation
among them), and its one-line errors on bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from aisdati.selftest.paper import PAPER_TABLE1
from aisdati.selftest.settings import ABLATION

TINY = ("--seeds", "2", "--episodes", "2", "--steps", "20", "--references", "2")
FILES = ("results.csv", "results.json", "scores.csv", "families.png", "rollouts.png")


def selftest(cli, out, *args):
    return cli("selftest", "--out", out, *args)


def check_outputs(out, families, seeds, references):
    for name in FILES:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # no temporary files
    doc = json.loads((out / "results.json").read_text())
    rows = doc["results"]
    assert [r["family"] for r in rows] == list(families)
    for r in rows:
        assert math.isfinite(r["best"]) and r["best"] >= 0
        assert r["best"] <= r["median"] and r["iqm_ci_low"] <= r["iqm"] <= r["iqm_ci_high"]
        assert r["n_scores"] == seeds * references
        assert 1 <= r["mean_episodes"] <= 2
    csv = pd.read_csv(out / "results.csv")
    assert list(csv["family"]) == list(families)
    scores = pd.read_csv(out / "scores.csv")
    assert len(scores) == len(families) * seeds * references
    assert set(scores["family"]) == set(families)
    assert scores["score"].notna().all()
    for r in rows:
        mine = scores[scores["family"] == r["family"]]
        assert r["best"] == pytest.approx(mine["score"].min())
    assert (out / "families.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return doc


def test_tiny_selftest_writes_its_files(cli, tmp_path):
    out = tmp_path / "run"
    result = selftest(cli, out, "--family", "circles", *TINY, "--workers", "1")
    assert result.exit_code == 0, result.output
    doc = check_outputs(out, ["circles"], seeds=2, references=2)
    assert len(doc["results"]) == 1
    settings = doc["settings"]
    assert settings["families"] == ["circles"] and settings["seeds"] == 2
    assert settings["steps"] == 20 and settings["references"] == 2
    net = settings["config"]["network"]
    assert net["time_embedding"] is True and net["reward_input"] is True
    assert settings["config"]["episodes"] == 2


def test_tiny_selftest_json_on_stdout(cli, tmp_path):
    out = tmp_path / "run"
    result = cli(
        "selftest", "--family", "ushaped", "--seeds", "1", "--episodes", "1", "--steps", "10",
        "--references", "2", "--workers", "1", "--out", out, "--json",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert doc["out"] == str(out) and doc["results"][0]["family"] == "ushaped"
    assert math.isfinite(doc["results"][0]["best"])


def test_two_workers_two_families(cli, tmp_path):
    out = tmp_path / "run"
    result = selftest(
        cli, out, "--family", "circles,ushaped", "--seeds", "1", "--episodes", "2",
        "--steps", "20", "--references", "2", "--workers", "2",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    check_outputs(out, ["circles", "ushaped"], seeds=1, references=2)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--family", "nosuchfamily"), "unknown family"),
        (("--family", "circles,nosuchfamily"), "unknown family"),
        (("--family", "circles", "--seeds", "0"), "--seeds"),
        (("--family", "circles", "--episodes", "0"), "--episodes"),
        (("--family", "circles", "--references", "0"), "--references"),
        (("--family", "circles", "--workers", "0"), "--workers"),
        (("--family", "circles", "--steps", "1"), "--steps"),
    ],
    ids=[
        "family",
        "one-bad-family",
        "seeds",
        "episodes",
        "references",
        "workers",
        "steps",
    ],
)
def test_bad_options_are_one_line_errors(cli, tmp_path, args, message):
    out = tmp_path / "run"
    result = selftest(cli, out, *args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), result.stderr
    assert message in lines[0]
    assert not out.exists()  # checked before anything is written


def test_unwritable_out_is_a_one_line_error(cli, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    result = selftest(cli, blocker / "run", "--family", "circles", *TINY)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "cannot write to output folder" in lines[0], result.stderr
    assert blocker.read_text() == "not a folder"


def test_two_workers_end_without_a_traceback(tmp_path):
    """Run as a user runs it (a real process, its workers forked): finished workers are joined,
    not terminated, so no worker prints a traceback when it is stopped."""
    import subprocess
    import sys

    run = subprocess.run(
        [
            sys.executable, "-c", "from aisdati.cli import app; app()", "selftest",
            "--family", "circles,ushaped", "--seeds", "1", "--episodes", "1", "--steps", "10",
            "--references", "2", "--workers", "2", "--out", str(tmp_path / "run"),
        ],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr + run.stdout
    assert (tmp_path / "run" / "results.csv").exists()


@pytest.mark.parametrize(
    "args",
    [
        ("--methods", "bogus"),
        ("--methods", ","),
        ("--methods", "table2,bc"),
    ],
)
def test_bad_methods_are_one_line_errors(cli, tmp_path, args):
    result = cli("selftest", "--out", tmp_path / "o", *args)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:")


TINY_BASELINES = ("--seeds", "1", "--references", "2", "--workers", "1")


def test_table1_methods_end_to_end(cli, tmp_path):
    out = tmp_path / "t1"
    result = cli(
        "selftest", "--methods", "dati,bc,ddpg-ti", "--family", "circles",
        "--episodes", "2", "--steps", "20", "--out", out, *TINY_BASELINES,
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "Table 1" in result.output and "DDPG-TI" in result.output
    rows = pd.read_csv(out / "results.csv")
    assert list(rows["method"]) == ["dati", "bc", "ddpg-ti"]
    assert list(rows["paper_best"]) == [PAPER_TABLE1[m]["circles"] for m in rows["method"]]
    assert (rows["best"] <= rows["second_best"]).all() and (rows["mean_episodes"] == 2).all()
    scores = pd.read_csv(out / "scores.csv")
    assert sorted(scores["method"].unique()) == ["bc", "dati", "ddpg-ti"]
    assert len(scores) == 3 * 2 and np.isfinite(scores["score"]).all()
    doc = json.loads((out / "results.json").read_text())
    assert doc["settings"]["methods"] == ["dati", "bc", "ddpg-ti"]
    assert doc["settings"]["bc"]["episodes"] == doc["settings"]["ddpg"]["episodes"] == 2
    assert (out / "rollouts.png").stat().st_size > 0


def test_ablation_end_to_end(cli, tmp_path):
    out = tmp_path / "t2"
    result = cli("selftest", "--methods", "table2", "--episodes", "1", "--steps", "10",
                 "--out", out, *TINY_BASELINES)
    assert result.exit_code == 0, result.output
    assert "ablation" in result.output and "top-2" in result.output
    rows = pd.read_csv(out / "results.csv")
    assert tuple(rows["method"]) == ABLATION and set(rows["family"]) == {"circles"}
    assert list(rows["paper_best"]) == [0.058, 1.829, 0.305]
    assert list(rows["paper_second_best"]) == [0.074, 1.976, 0.451]
