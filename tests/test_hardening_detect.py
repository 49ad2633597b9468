"""Hardening of `aisdati train` and `aisdati detect` (issue 13): model cards edited into nonsense,
data ingested again with other settings, unfinished training, bad label files and options, on a
real model trained on the real New York Harbor hour."""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
from hardening import card_edit, one_line_error, run

NY_HOUR = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """NY hour ingested (tracks of >= 30 reports), a 2-episode model of its `down` cluster."""
    base = tmp_path_factory.mktemp("detect")
    proc, models = base / "processed", base / "models"
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 30, "--out", proc)
    assert r.exit_code == 0, r.output
    r = run(
        "train", "--cluster", "down", "--data", proc, "--out", models,
        "--episodes", 2, "--max-tracks", 3, "--seed", 1,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    return {"base": base, "proc": proc, "models": models}


def card_of(models: Path) -> dict:
    return json.loads((models / "down.json").read_text())


def edited_models(trained, tmp_path: Path, edit) -> Path:
    """A copy of the model folder whose card went through `edit(card)`."""
    models = tmp_path / "models"
    shutil.copytree(trained["models"], models)
    card = card_of(models)
    edit(card)
    (models / "down.json").write_text(json.dumps(card))  # NaN and Infinity as Python writes them
    return models


def detect(trained, models: Path, out: Path, *extra, data: Path | None = None):
    return run(
        "detect", "--data", data or trained["proc"], "--models", models, "--out", out,
        "--near-km", 20, *extra,
    )  # fmt: skip


def training_keys(trained) -> set[tuple[int, pd.Timestamp]]:
    """(mmsi, start) of the model's training tracks, read from the data it was trained on."""
    ids = card_of(trained["models"])["data"]["track_ids"]
    tracks = pq.read_table(trained["proc"] / "tracks.parquet").to_pandas()
    rows = tracks[tracks["track_id"].isin(ids)]
    return set(zip(rows["mmsi"], rows["start"], strict=True))


def test_the_card_stores_stable_track_keys(trained):
    card = card_of(trained["models"])
    keys = {(m, pd.Timestamp(s)) for m, s, _ in card["data"]["track_keys"]}
    assert keys == training_keys(trained) and len(keys) == 3
    assert card["training"]["finished"] is True


# ---------------------------------------------------------------------------------- item 1

CARD_DAMAGE = [
    ("rule.max_sog_kn", -3, "rule.max_sog_kn must be a finite number in \\(0, 1000\\], got -3"),
    ("rule.max_sog_kn", math.nan, "rule.max_sog_kn must be a finite number .*got nan"),
    ("rule.max_sog_kn", "12", "rule.max_sog_kn must be a finite number .*got '12'"),
    ("rule.max_dt_h", 0, "rule.max_dt_h must be a finite number in \\(0, .*got 0"),
    ("rule.max_dt_h", math.inf, "rule.max_dt_h must be a finite number .*got inf"),
    ("rule.cog_center_deg", math.nan, "rule.cog_center_deg must be a finite number"),
    ("region.lat", [41.0, 40.0], "region.lat must be \\[low, high\\] with low < high"),
    ("region.lon", [-74.5, math.nan], "region.lon\\[1\\] must be a finite number"),
    ("epsilon_m", -500, "epsilon_m must be a finite number > 0"),
    ("config.noise_sigma", math.nan, "config.noise_sigma must be a finite number"),
    ("config.noise", "pink", "config.noise must be one of 'gaussian', 'ou'"),
    ("data.start_points", [[math.nan, 40.6]] * 3, "data.start_points\\[0\\]\\[0\\] must be"),
    ("data.start_points", [[-74.0, 40.6]], "data.start_points must be a list of 3, got 1 items"),
    (
        "data.track_ids",
        [1, -2, 10],
        r"data.track_ids\[1\] must be an integer in \[0, [^]]*\], got -2",
    ),
    ("data.points", 2, "data.points must be an integer (>= 3|in \\[3, [^]]*\\]), got 2"),
    ("data.track_keys", [[1, "yesterday"]] * 3, "data.track_keys\\[0\\]\\[1\\] must be an ISO"),
    ("training.finished", "no", "training.finished must be true or false"),
]


@pytest.mark.parametrize("field, value, needle", CARD_DAMAGE, ids=[c[0] for c in CARD_DAMAGE])
def test_a_damaged_card_is_refused_naming_the_field(trained, tmp_path, field, value, needle):
    models = edited_models(trained, tmp_path, card_edit(field, value))
    result = detect(trained, models, tmp_path / "report")
    one_line_error(result, "model card .*down.json: " + needle)
    assert not (tmp_path / "report" / "scores.parquet").exists()


# ---------------------------------------------------------------------------------- item 2
def test_training_tracks_are_found_after_a_reingest_renumbers_them(trained, tmp_path):
    again = tmp_path / "again"  # the same data, other settings: more tracks, other numbers
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 15, "--out", again)
    assert r.exit_code == 0, r.output
    tracks = pq.read_table(again / "tracks.parquet").to_pandas()
    keys = training_keys(trained)
    moved = tracks[[(m, s) in keys for m, s in zip(tracks["mmsi"], tracks["start"], strict=True)]]
    ids = set(card_of(trained["models"])["data"]["track_ids"])
    assert len(moved) == 3 and set(moved["track_id"]) != ids  # renumbered
    result = detect(trained, trained["models"], tmp_path / "r", "--cluster", "all", data=again)
    assert result.exit_code == 0, result.output
    scored = pq.read_table(tmp_path / "r" / "scores.parquet").to_pandas()
    assert not set(scored["track_id"]) & set(moved["track_id"])  # the real training tracks
    assert set(scored["track_id"]) & (ids - set(moved["track_id"]))  # their old numbers: tested


def test_a_card_without_track_keys_falls_back_to_track_ids(trained, tmp_path):
    models = edited_models(trained, tmp_path, lambda card: card["data"].pop("track_keys"))
    result = detect(trained, models, tmp_path / "r", "--cluster", "all")
    assert result.exit_code == 0, result.output
    assert "warning" not in result.stderr
    scored = pq.read_table(tmp_path / "r" / "scores.parquet").to_pandas()
    ids = set(card_of(trained["models"])["data"]["track_ids"])
    assert len(scored) > 0 and not set(scored["track_id"]) & ids


# ---------------------------------------------------------------------------------- item 7
def test_an_unfinished_model_is_used_with_a_warning(trained, tmp_path):
    models = edited_models(trained, tmp_path, card_edit("training.finished", False))
    result = detect(trained, models, tmp_path / "r")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "model down: training did not finish" in warnings[0]
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert len(report["warnings"]) == 1 and "did not finish" in report["warnings"][0]
    finished = detect(trained, trained["models"], tmp_path / "r2")
    assert "warning" not in finished.stderr
    assert json.loads((tmp_path / "r2" / "report.json").read_text())["warnings"] == []


# --------------------------------------------------------------------------------- item 12
LABELS = [
    ("track_id,label\nabc,1\n", "row 1: track_id must be an integer in \\[0, .*got 'abc'"),
    ("track_id,label\n3,1\n,0\n", "row 2: track_id must be an integer .*got ''"),
    ("track_id,label\n99999999999999999999,1\n", "row 1: track_id must be an integer in"),
    ("track_id,label\n3,yes\n", "row 1: label must be 0 or 1, got 'yes'"),
    ("track_id,label\n3,1\n3,0\n", "track_id 3 has both labels 0 and 1"),
    ("mmsi,start,label\n367000140,soon,1\n", "row 1: start must be a time"),
    ("mmsi,start,label\n-5,2020-06-30T00:00:00,1\n", "row 1: mmsi must be an integer in \\[1,"),
    ("track_id,label\n", "the file holds no labels"),
]


@pytest.mark.parametrize("text, needle", LABELS)
def test_bad_label_files_are_refused_before_any_work(trained, tmp_path, text, needle):
    labels = tmp_path / "labels.csv"
    labels.write_text(text)
    result = detect(trained, trained["models"], tmp_path / "r", "--labels", labels)
    one_line_error(result, re.escape(str(labels)) + ": " + needle)
    assert not (tmp_path / "r" / "scores.parquet").exists()  # no rollout ran


# ----------------------------------------------------------------------------- items 5, 18
@pytest.mark.parametrize(
    "extra, needle",
    [
        (("--near-km", "nan"), "--near-km must be a finite number in \\(0, 20037.5\\], got nan"),
        (("--near-km", "inf"), "--near-km must be a finite number .*got inf"),
        (("--threshold", "nan"), "--threshold must be a finite number in \\(0, 1\\], got nan"),
        (("--top-percent", "inf"), "--top-percent must be a finite number .*got inf"),
        (("--top-percent", "-1"), "--top-percent must be a finite number .*got -1"),
    ],
)
def test_detect_float_options(trained, tmp_path, extra, needle):
    result = detect(trained, trained["models"], tmp_path / "r", *extra)
    one_line_error(result, needle)
    assert not (tmp_path / "r").exists()


def test_train_seed_out_of_range(trained, tmp_path):
    result = run("train", "--cluster", "down", "--data", trained["proc"], "--out", tmp_path / "m",
                 "--seed", -1)  # fmt: skip
    one_line_error(result, "--seed must be an integer in \\[0, 4294967295\\], got -1")


# ---------------------------------------------------------------------------------- item 8
def test_train_and_detect_outputs_under_a_file_or_on_a_folder(trained, tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    result = run("train", "--cluster", "down", "--data", trained["proc"], "--out", a_file / "m")
    one_line_error(
        result,
        r"cannot write to output folder .* \(--out\): cannot create it, a part of the path is a "
        "file",
    )
    result = detect(trained, trained["models"], a_file)
    one_line_error(
        result, "cannot write to output folder .*file.txt \\(--out\\): it is a file, not a folder"
    )
    report = tmp_path / "report"
    (report / "scores.parquet").mkdir(parents=True)
    result = detect(trained, trained["models"], report)
    one_line_error(result, "scores.parquet there is a folder")
    models = tmp_path / "models"
    (models / "down.json").mkdir(parents=True)
    result = run("train", "--cluster", "down", "--data", trained["proc"], "--out", models)
    one_line_error(result, "down.json there is a folder")


def test_resume_beside_a_damaged_card_trains_without_a_traceback(trained, tmp_path):
    models = tmp_path / "models"
    shutil.copytree(trained["models"], models)
    (models / "down.json").write_text("[1, 2]")  # valid JSON, no card
    result = run(
        "train", "--cluster", "down", "--data", trained["proc"], "--out", models,
        "--episodes", 1, "--max-tracks", 3, "--seed", 1, "--resume",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert card_of(models)["training"]["finished"] is True
