"""reports.parquet (`aisdati.preprocess.reports`): every report judged, the slow ones too, each
with the track whose point it is; the tracks themselves (points.parquet, tracks.parquet) just as
without it, and the counts still balanced. On FRIO's real drift (the DMA's recording) and the
New York Harbor hour."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from aisdati.preprocess.reports import track_of
from aisdati.tracks.schema import REPORTS_SCHEMA, VESSEL_COLUMNS
from tests.helpers.ingest import NY_HOUR, SETTINGS, ingest, ny_table

FRIO = Path(__file__).parents[1] / "data" / "events" / "538004030_drift_1.ais"
NY_TRACKS = [
    (338133288, 40), (338317251, 40), (366516370, 29), (366939790, 50), (366999618, 22),
    (367000190, 20), (367341190, 33), (367351520, 44), (367370920, 32), (367531710, 31),
    (367531730, 22), (367596760, 37), (367597240, 38), (367614410, 28), (367639120, 29),
    (367639130, 35), (367668450, 20), (367740750, 26), (367782880, 38), (367784630, 44),
    (367796040, 42), (368009360, 20), (368026140, 21), (368130050, 21), (368564000, 35),
    (369990373, 36), (636013289, 24), (896876500, 48),
]  # fmt: skip
"""The NY hour's tracks (`--roi none --min-points 20`) by id: (MMSI, reports), as ingest made
them before reports.parquet existed."""
NY_LENGTHS_KM = [
    20.493, 20.341, 10.785, 20.945, 5.211, 7.938, 9.865, 12.077, 12.508, 33.674, 15.925, 6.098,
    9.556, 5.493, 5.164, 9.103, 4.274, 7.921, 25.695, 31.839, 10.117, 3.912, 8.906, 17.447,
    14.235, 21.714, 4.577, 14.059,
]  # fmt: skip


def read(out: Path, name: str) -> pd.DataFrame:
    return pq.read_table(out / name).to_pandas()


def assert_reports_hold_the_points(out: Path, report: dict) -> pd.DataFrame:
    """reports.parquet's contract: its schema and row count, sorted by vessel and time in each
    part, every point a report of its track at its time, every other report of none."""
    reports = read(out, "reports.parquet")
    assert pq.read_schema(next((out / "reports.parquet").iterdir())).equals(REPORTS_SCHEMA)
    assert len(reports) == report["reports_kept"] > report["kept_points"]
    assert report["rows_read"] == report["rejected_total"] + report["kept_points"]
    for part in sorted((out / "reports.parquet").iterdir()):
        rows = pq.read_table(part).to_pandas()
        key = rows[["mmsi", "time"]]
        assert not key.duplicated().any() and key.equals(key.sort_values(["mmsi", "time"]))
    points = read(out, "points.parquet")
    joined = points.merge(reports, on=["mmsi", "time"], suffixes=("", "_report"))
    assert len(joined) == len(points)
    assert (joined["track_id"] == joined["track_id_report"]).all()
    assert reports["track_id"].notna().sum() == len(points)
    return reports


@pytest.fixture(scope="module")
def frio(tmp_path_factory) -> tuple[Path, dict]:
    from typer.testing import CliRunner

    from aisdati.cli import app

    out = tmp_path_factory.mktemp("frio")
    args = ["ingest", "--input", str(FRIO), "--roi", "none", "--min-points", "5"]
    result = CliRunner().invoke(app, [*args, "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    return out, json.loads(result.stdout)


def test_frio_drifting_is_in_its_reports_though_not_in_its_tracks(frio):
    """The drift the DMA's tests know (from 16:50 UTC, 1-5 kn) is slow: rejected from the tracks
    as `slow`, every such report but the copies of other receivers is in reports.parquet, with
    no track, its heading and navigational status given."""
    out, report = frio
    reports = assert_reports_hold_the_points(out, report)
    assert (reports["mmsi"] == 538004030).all()
    slow = reports[reports["sog"] <= 3]
    assert len(slow) == 484 and slow["track_id"].isna().all()
    assert report["rejected"]["slow"] == 800  # their copies from other receivers: duplicates
    drift = slow[slow["time"] >= pd.Timestamp("2014-09-28 16:50:04", tz="UTC")]
    assert len(drift) > 300 and drift["sog"].between(0.5, 3).mean() > 0.9
    assert reports["heading"].notna().all() and reports["status"].notna().all()
    assert not (read(out, "points.parquet")["sog"] <= 3).any()  # what a model learns from


def test_the_ny_hour_makes_the_tracks_it_made_before(cli, data, tmp_path):
    """The tracks (ids, vessels, reports, lengths) as ingest made them before reports.parquet
    and the new columns; and a copy of the hour without those columns gives the same points
    and tracks, its heading and status none."""
    result, report = ingest(cli, tmp_path / "all", data / NY_HOUR)
    assert result.exit_code == 0, result.output
    tracks = read(tmp_path / "all", "tracks.parquet")
    assert tracks["track_id"].tolist() == list(range(len(NY_TRACKS)))
    assert list(zip(tracks["mmsi"], tracks["n_points"], strict=True)) == NY_TRACKS
    assert np.round(tracks["length_km"], 3).tolist() == NY_LENGTHS_KM
    assert report["kept_points"] == 905 and report["rejected"]["slow"] == 6954
    bare = tmp_path / "bare.csv"
    bare_table = ny_table(data).drop(columns=["Heading", "Status", "VesselName", "VesselType"])
    bare_table.drop(columns=["Length"]).to_csv(bare, index=False)
    result, bare_report = ingest(cli, tmp_path / "bare", bare)
    assert result.exit_code == 0, result.output
    new = {"points.parquet": ["heading", "status"], "tracks.parquet": VESSEL_COLUMNS}
    for name, columns in new.items():
        got, want = (read(tmp_path / run, name).drop(columns=columns) for run in ("bare", "all"))
        assert got.equals(want), name
    points = read(tmp_path / "bare", "points.parquet")
    assert points["heading"].isna().all() and points["status"].isna().all()
    assert bare_report["reports_kept"] == report["reports_kept"]


def test_the_ny_hour_reports_every_vessel_whatever_its_speed(cli, data, tmp_path):
    """8,689 rows: 6,954 slow ones out of the tracks but in reports.parquet, 2 rows rejected
    by the cleaning of every report; with --keep-rejects the slow rows are still listed as
    what made no track."""
    result, report = ingest(cli, tmp_path, data / NY_HOUR, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0, result.output
    reports = assert_reports_hold_the_points(tmp_path, report)
    assert report["reports_kept"] == 8687
    assert reports["mmsi"].nunique() == ny_table(data)["MMSI"].nunique()
    assert (reports["sog"] <= 3).sum() >= report["rejected"]["slow"] - 2
    rejects = read(tmp_path, "rejects.parquet")
    assert (rejects["reason"] == "slow").sum() == report["rejected"]["slow"]
    assert "reports" in report["outputs"] and "vessels" in report["outputs"]


def test_a_report_takes_the_track_of_the_point_at_its_vessel_and_time():
    """The merge of two (MMSI, time)-sorted sequences, from the reports' first vessel on (a
    piece of a partition starts anywhere among its points)."""
    mmsi = np.array([2, 2, 2, 3, 5, 5])
    time_us = np.array([10, 20, 30, 10, 5, 6])
    points = (np.array([1, 2, 2, 3, 4, 5]), np.array([10, 20, 30, 11, 1, 6]))
    tracks = np.array([7, 8, 8, 9, 10, 11])
    assert track_of(mmsi, time_us, *points, tracks).tolist() == [-1, 8, 8, -1, -1, 11]
    assert track_of(mmsi[:0], time_us[:0], *points, tracks).tolist() == []
