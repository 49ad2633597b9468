"""The third hostile probe's defects of `detect` and of its output folder (issue 61), each on
the shipped Kitimat and NY Harbor tracks, through the CLI where a user meets them."""

from __future__ import annotations

import json
import os
import shutil
import socket
from pathlib import Path

import pandas as pd
import pytest

from aisdati.ais.training import TrainSettings
from aisdati.detection.labels import read_labels
from aisdati.detection.routing import NOT_JUDGED_OUTSIDE, route_test_tracks
from aisdati.detectors.nearest import NearestDetector
from aisdati.errors import UserError
from aisdati.tracks.store import load_tracks, read_track_table

NY_HOUR = Path(__file__).parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"


@pytest.fixture(scope="module")
def area(kitimat, tmp_path_factory):
    """Kitimat's area model (nearest, fast) trained on July, in a model folder."""
    table = read_track_table(kitimat)
    july = table.loc[table["start"] < pd.Timestamp("2018-08-01", tz="UTC"), "track_id"]
    models = tmp_path_factory.mktemp("models")
    det = NearestDetector(TrainSettings(cluster="all")).fit(load_tracks(kitimat, list(july)))
    det.save(models / det.name)
    return models, det, [int(i) for i in july]


def test_an_area_model_does_not_judge_tracks_of_another_area(area, cli, tmp_path):
    """Item 3: New York tracks beside Kitimat's are listed as not judged, with the reason."""
    models, det, _ = area
    ny = tmp_path / "ny"
    r = cli("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", "30", "--out", ny)
    assert r.exit_code == 0, r.output
    table = read_track_table(ny)
    tracks = load_tracks(ny, [int(i) for i in table["track_id"]])
    owner, coverage = route_test_tracks([det], table, tracks, near_km=10.0)
    assert (owner == -1).all() and coverage.judged == 0
    assert sorted(coverage.not_judged[NOT_JUDGED_OUTSIDE]) == sorted(table["track_id"])
    r = cli("detect", "--data", ny, "--models", models, "--cluster", "all", "--out", tmp_path / "r")
    assert r.exit_code == 2 and "another region" in r.output  # none inside: refused in one line


def test_a_named_track_is_not_judged_by_the_model_it_trained(area, kitimat, cli, tmp_path):
    """Item 4: `--track` of a training track: left out, as by cluster; nothing is scored."""
    models, _, july = area
    r = cli("detect", "--data", kitimat, "--models", models, "--track", july[0],
            "--out", tmp_path / "r")  # fmt: skip
    assert r.exit_code == 2 and "no test track is judged" in r.output


def test_label_times_are_iso_8601_or_refused_naming_the_row(tmp_path):
    """Item 5: day-first, month-first and `now` are refused, naming the row."""
    good = tmp_path / "good.csv"
    good.write_text("mmsi,start,end\n1,2018-08-07,2018-08-12T00:00:00Z\n")
    assert read_labels(good).rows["start"].iloc[0] == pd.Timestamp("2018-08-07", tz="UTC")
    for bad in ("07/08/2018", "now", "today"):
        path = tmp_path / "bad.csv"
        path.write_text(f"mmsi,start,end\n1,2018-08-07,2018-08-12\n2,{bad},2018-08-12\n")
        with pytest.raises(UserError, match=f"row 2: start must be a time .*got '{bad}'"):
            read_labels(path)


def test_a_process_local_model_folder_is_refused(kitimat, cli, tmp_path):
    """Item 9: `--out memory://m` would lose the model when the command exits."""
    r = cli("train", "--method", "nearest", "--cluster", "route-1", "--data", kitimat,
            "--out", "memory://m")  # fmt: skip
    assert r.exit_code == 2 and "memory:// keeps files only while this command runs" in r.output


def test_a_linked_evidence_folder_is_replaced_not_followed(area, kitimat, cli, tmp_path):
    """Item 10: a link `evidence/` inside --out pointing elsewhere: the figures land in a real
    evidence/ folder and the link's target keeps its files."""
    models, _, _ = area
    out, elsewhere = tmp_path / "report", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (elsewhere / "track-1.png").write_bytes(b"not ours")
    os.symlink(elsewhere, out / "evidence")
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all", "--out", out,
            "--top-percent", 20)  # fmt: skip
    assert r.exit_code == 0, r.output
    assert (out / "evidence").is_dir() and not (out / "evidence").is_symlink()
    assert list((out / "evidence").glob("track-*.png"))
    assert [p.name for p in elsewhere.iterdir()] == ["track-1.png"]


def test_model_names_are_names_not_paths(area, kitimat, cli, tmp_path):
    """Item 11: `-m ../x` or an absolute path would load a model from outside --models."""
    models, det, _ = area
    other = tmp_path / "other"
    shutil.copytree(models, other)
    for name in (f"../other/{det.name}", str(other / det.name), "..", f"sub/{det.name}"):
        r = cli("detect", "--data", kitimat, "--models", models, "-m", name,
                "--out", tmp_path / "r")  # fmt: skip
        assert r.exit_code == 2 and "not a path" in r.output, name


def test_the_report_folder_may_not_be_the_model_folder(area, kitimat, cli):
    """Item 14: detect --out --models would make the folder unreadable as models."""
    models, _, _ = area
    r = cli("detect", "--data", kitimat, "--models", models, "--out", models / "." / "")
    assert r.exit_code == 2 and "is the model folder" in r.output
    assert not (models / "report.json").exists()


def test_an_unreachable_cluster_leaves_no_output_folder(kitimat, area, cli, tmp_path):
    """Item 16: the one-line refusal, and no empty --out left behind (ingest and detect)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    out = tmp_path / "ingested"
    r = cli("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", "30", "--out", out,
            "--workers", address)  # fmt: skip
    assert r.exit_code == 2 and "cannot reach the Dask scheduler" in r.output
    assert not out.exists()
    models, _, _ = area
    report = tmp_path / "report"
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all",
            "--out", report, "--workers", address)  # fmt: skip
    assert r.exit_code == 2 and not report.exists()


def test_report_json_names_the_reasons_tracks_were_not_judged(area, kitimat, cli, tmp_path):
    models, _, july = area
    out = tmp_path / "r"
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all", "--out", out)
    assert r.exit_code == 0, r.output
    coverage = json.loads((out / "report.json").read_text())["coverage"]
    assert sorted(coverage["training_track_ids"]) == sorted(july)


def test_a_model_whose_files_do_not_belong_together_refuses_to_load(kitimat, cli, tmp_path):
    """Item 6: a retraining into a folder that held another model, stopped between its files,
    used to leave one run's weights beside another's corridor, and detect scored with both. The
    card records each file's digest; a mixed model refuses in one line."""
    models = tmp_path / "models"
    for seed in ("0", "1"):
        r = cli("train", "--cluster", "route-1", "--data", kitimat, "--out", models / seed,
                "--episodes", "1", "--max-tracks", "4", "--seed", seed, "--lane",
                "validation_tracks=2", "--lane", "validation_rollouts=1")  # fmt: skip
        assert r.exit_code == 0, r.output
    card = json.loads((models / "0" / "route-1.json").read_text())
    assert set(card["files"]) == {".pt", ".corridor.npz"}
    shutil.copy(models / "1" / "route-1.corridor.npz", models / "0" / "route-1.corridor.npz")
    r = cli("detect", "--data", kitimat, "--models", models / "0", "--cluster", "route-1",
            "--out", tmp_path / "r")  # fmt: skip
    assert r.exit_code == 2
    assert "route-1.corridor.npz is not the one its card records" in r.output


def test_a_cluster_without_workers_is_waited_for_then_refused(area, kitimat, cli, tmp_path,
                                                               monkeypatch):  # fmt: skip
    """Item 13: a scheduler with no worker held every task forever, silently."""
    import distributed

    from aisdati.execution import runner

    models, _, _ = area
    monkeypatch.setattr(runner, "WORKER_WAIT_S", 2)
    with distributed.LocalCluster(n_workers=0, dashboard_address=":0") as cluster:
        r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all",
                "--out", tmp_path / "r", "--workers", cluster.scheduler_address)  # fmt: skip
    assert r.exit_code == 2
    assert "waiting up to 2 s for a worker" in r.output and "has no worker (waited 2 s)" in r.output
    assert not (tmp_path / "r").exists()


def test_a_full_disk_is_one_line_wherever_it_strikes(area, kitimat, cli, tmp_path, monkeypatch):
    """Item 12: numpy, pyarrow and torch raise a full disk without a file name: it was a
    traceback. Now one line, exit code 1, and no report that looks complete."""
    import errno

    from aisdati.detection import outputs

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    models, _, _ = area
    monkeypatch.setattr(outputs, "parquet_bytes", full)
    out = tmp_path / "r"
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all", "--out", out)
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert r.output.strip().splitlines()[-1] == "error: No space left on device"
    assert not (out / "report.json").exists()
