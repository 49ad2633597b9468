"""`aisdati ingest` end to end on the real sample files, and on bad input."""

from __future__ import annotations

import gzip
import json
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import zstandard

from aisdati.preprocess.roi import florida_straits, in_roi
from aisdati.tracks.schema import POINTS_SCHEMA
from tests.helpers.cli import one_line_error, run

HEAD_ZIP = "AIS_2022_01_03_head.zip"
HEADER = "MMSI,BaseDateTime,LAT,LON,SOG,COG,Heading,VesselName"
ROW = "367000001,2022-01-03T00:{m:02d}:00,25.{lat:04d},-80.1,10.0,0.0,0.0,SHIP"


def ingest(cli, out: Path, *inputs, extra=("--roi", "none", "--min-points", "5")):
    args = ["ingest", *[a for i in inputs for a in ("--input", i)], "--out", out, *extra]
    result = cli(*args, "--json")
    return result, (json.loads(result.stdout) if result.exit_code == 0 else None)


def check_contract(out: Path, report: dict) -> tuple[pa.Table, pa.Table]:
    """The DESIGN.md data contract and the row accounting."""
    points = pq.read_table(out / "points.parquet")
    tracks = pq.read_table(out / "tracks.parquet")
    assert points.schema.equals(POINTS_SCHEMA)
    assert tracks.column_names[:9] == [
        "track_id", "mmsi", "start", "end", "n_points", "length_km", "cluster", "lon0", "lat0",
    ]  # fmt: skip
    assert (
        json.loads(pq.read_schema(out / "tracks.parquet").metadata[b"geo"])["primary_column"]
        == "geometry"
    )
    tid = points.column("track_id").to_numpy()
    t = points.column("time").to_numpy().view(np.int64)
    assert np.all((np.diff(tid) > 0) | ((np.diff(tid) == 0) & (np.diff(t) > 0)))
    assert report["rows_read"] == report["rejected_total"] + report["kept_points"]
    assert report["kept_points"] == points.num_rows == sum(tracks.column("n_points").to_pylist())
    assert report["tracks"]["total"] == tracks.num_rows
    cog = points.column("cog").to_numpy()
    assert cog.min() >= 0 and cog.max() < 360 and points.column("sog").to_numpy().min() > 3
    # clusters agree with the paper's rule, recomputed here
    up = (cog <= 90) | (cog >= 270)
    n_up = np.bincount(tid, weights=up)
    n = np.bincount(tid)
    expected = np.where(n_up == n, "up", np.where(n_up == 0, "down", "other"))
    ids = tracks.column("track_id").to_numpy()
    assert list(tracks.column("cluster").to_pylist()) == list(expected[ids])
    return points, tracks


def test_daily_head_zip(cli, data, tmp_path):
    result, report = ingest(cli, tmp_path, data / HEAD_ZIP)
    assert result.exit_code == 0, result.output
    check_contract(tmp_path, report)
    assert report["rows_read"] == 99_999
    assert report["rejected"]["sentinel_cog"] > 10_000 and report["rejected"]["slow"] > 60_000
    assert 900 <= report["tracks"]["total"] <= 1_100
    assert min(report["tracks"][c] for c in ("up", "down", "other")) > 200


def test_default_roi_keeps_only_the_florida_straits(cli, data, tmp_path):
    result, report = ingest(cli, tmp_path, data / HEAD_ZIP, extra=("--min-points", "5"))
    assert result.exit_code == 0, result.output
    points, _ = check_contract(tmp_path, report)
    assert report["roi"] == "florida-straits" and report["rejected"]["outside_roi"] > 10_000
    lon, lat = points.column("lon").to_numpy(), points.column("lat").to_numpy()
    assert points.num_rows > 0 and in_roi(florida_straits(), lon, lat).all()


def test_2023_sample_with_floats_in_integer_fields(cli, data, tmp_path):
    result, _ = ingest(
        cli,
        tmp_path,
        data / "noaa_2023-01-11_1000rows.csv",
        extra=("--roi", "none", "--min-points", "2"),
    )
    # one report per vessel: no track of two points, but every report kept to judge, none of
    # them rejected as a bad number or MMSI
    assert result.exit_code == 0, result.output
    assert "no track kept" in " ".join(result.stderr.split())
    report = json.loads(result.stdout)
    assert report["tracks"]["total"] == 0 and report["rejected"]["short_segment"] > 0
    assert report["rejected"]["bad_number"] == report["rejected"]["bad_mmsi"] == 0
    assert report["reports_kept"] == len(pd.read_parquet(tmp_path / "reports.parquet")) > 0


def test_ny_harbor_hour_reordered_misspelt_negative_cog(cli, data, tmp_path):
    result, report = ingest(
        cli,
        tmp_path,
        data / "NYHarbor_2020_06_30_first_hour.csv",
        extra=("--roi", "none", "--min-points", "20"),
    )
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == 8689 and report["files"][0]["columns"]["lon"] == "LON"
    check_contract(tmp_path, report)
    assert report["tracks"]["total"] > 20


def test_positions_only_week_gets_derived_sog_cog(cli, data, tmp_path):
    result, report = ingest(
        cli,
        tmp_path,
        data / "NYHarbor_2020_12_first_week_points.csv.gz",
        extra=("--roi", "none", "--min-points", "100", "--dwell-time", "0"),
    )
    assert result.exit_code == 0, result.output
    points, _ = check_contract(tmp_path, report)
    assert report["files"][0]["derived"] == ["sog", "cog"]
    # the paper's segmentation (gaps > 1 h only); the data README counts 275
    assert 200 <= report["tracks"]["total"] <= 350
    assert not np.isnan(points.column("sog").to_numpy()).any()


def contents(path: Path) -> dict[str, bytes]:
    """The bytes of a file, or of each part of a folder (points.parquet, a Parquet dataset)."""
    if path.is_dir():
        return {p.name: p.read_bytes() for p in sorted(path.iterdir())}
    return {path.name: path.read_bytes()}


def test_ingesting_twice_gives_identical_outputs(cli, data, tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    for out in (first, second, first):
        result, _ = ingest(cli, out, data / HEAD_ZIP, data / "NYHarbor_2020_06_30_first_hour.csv")
        assert result.exit_code == 0, result.output
    names = ("points.parquet", "tracks.parquet", "reports.parquet", "vessels.parquet",
             "identities.parquet")  # fmt: skip
    for name in (*names, "routes.parquet", "routes.geojson"):
        assert contents(first / name) == contents(second / name), name
    assert sorted(p.name for p in first.iterdir()) == [
        "identities.parquet",
        "ingest_report.json",
        "points.parquet",
        "reports.parquet",
        "routes.geojson",
        "routes.parquet",
        "routes.png",
        "tracks.parquet",
        "vessels.parquet",
    ]


def test_keep_rejects_accounts_for_every_row(cli, data, tmp_path):
    src = tmp_path / "in.csv"
    rows = [ROW.format(m=m, lat=m * 28) for m in range(50)]
    rows += ["367000002,2022-01-03T00:00:00,25.0,-80.1,10.0", "1,2,3,4,5,6,7,8,9,10"]
    src.write_text(HEADER + "\n" + "\n".join(rows) + "\n")
    result, report = ingest(
        cli,
        tmp_path / "out",
        src,
        data / HEAD_ZIP,
        extra=("--roi", "none", "--min-points", "5", "--keep-rejects"),
    )
    assert result.exit_code == 0, result.output
    rejects = pq.read_table(tmp_path / "out" / "rejects.parquet")
    assert rejects.num_rows == report["rejected_total"]
    by_reason = dict(
        zip(*np.unique(rejects.column("reason").to_numpy(False), return_counts=True), strict=True)
    )
    assert by_reason == {k: v for k, v in report["rejected"].items() if v}
    assert by_reason["malformed_row"] == 2
    assert "1,2,3,4,5,6,7,8,9,10" in rejects.column("raw").to_pylist()


def _cut(path: Path, fraction: float) -> bytes:
    data = path.read_bytes()
    return data[: int(len(data) * fraction)]


def _flip(path: Path) -> bytes:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    return bytes(data)


def _zst(data_dir: Path, truncate: bool) -> bytes:
    with zipfile.ZipFile(data_dir / HEAD_ZIP) as zf:
        raw = zf.read("AIS_2022_01_03.csv")[:500_000]
    blob = zstandard.ZstdCompressor().compress(raw)
    return blob[: len(blob) // 2] if truncate else blob


BAD_FILES = {
    "missing_lat.csv": (
        lambda d: b"MMSI,BaseDateTime,LON,SOG,COG\n1,2022-01-03T00:00:00,-80,10,0\n",
        "LAT",
    ),
    "empty.csv": (lambda d: b"", "empty"),
    "header_only.csv": (lambda d: (HEADER + "\n").encode(), "no data rows"),
    "corrupt.zip": (lambda d: _flip(d / HEAD_ZIP), "corrupt or truncated"),
    "truncated.zip": (lambda d: _cut(d / HEAD_ZIP, 0.5), "not a readable zip"),
    "truncated.csv.zst": (lambda d: _zst(d, truncate=True), "corrupt or truncated"),
    "truncated.csv.gz": (
        lambda d: gzip.compress((HEADER + "\n" + ROW.format(m=1, lat=1) + "\n").encode() * 50)[
            :-12
        ],
        "corrupt or truncated",
    ),
    "notes.txt": (lambda d: b"hello", "unsupported file type|no .zip"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_files_give_one_clear_error_and_no_output(cli, data, tmp_path, name):
    make, message = BAD_FILES[name]
    src = tmp_path / name
    src.write_bytes(make(data))
    out = tmp_path / "out"
    result, _ = ingest(cli, out, src)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert result.stderr.startswith("error:")
    assert re.search(message, " ".join(result.stderr.split())), result.stderr
    assert not out.exists() or not list(out.iterdir())


def test_bad_rows_are_counted_not_fatal(cli, tmp_path):
    rows = [ROW.format(m=m, lat=m * 28) for m in range(30)]
    rows[3] = rows[3] + ",extra,fields"
    rows[4] = "367000001,2022-01-03T00:04:00,25.0"
    rows[5] = rows[5].replace("25.0140", "north")
    rows[6] = rows[6].replace("2022-01-03T00:06:00", "yesterday")
    src = tmp_path / "rows.csv"
    src.write_text(HEADER + "\n" + "\n".join(rows) + "\n")
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rejected"]["malformed_row"] == 2
    assert report["rejected"]["bad_number"] == 1 and report["rejected"]["bad_time"] == 1
    assert report["kept_points"] == 26 and report["tracks"]["total"] == 1


def test_failure_after_a_good_file_leaves_no_output(cli, data, tmp_path):
    """A corrupt second file is found mid-run: the first file's work must not be written."""
    out = tmp_path / "out"
    bad = tmp_path / "b_corrupt.zip"
    bad.write_bytes(_flip(data / HEAD_ZIP))
    result, _ = ingest(cli, out, data / "NYHarbor_2020_06_30_first_hour.csv", bad)
    assert result.exit_code == 2
    assert not out.exists()  # the folder it made for the run is removed again, empty


def test_bad_options_are_user_errors(cli, data, tmp_path):
    roi = tmp_path / "line.geojson"
    roi.write_text(json.dumps({"type": "LineString", "coordinates": [[0, 0], [1, 1]]}))
    for args, message in [
        (["--roi", roi], "Polygon or MultiPolygon"),
        (["--roi", "none", "--stop-gap", "soon"], "--stop-gap"),
        (["--roi", "none", "--min-points", "1"], "--min-points"),
    ]:
        result = cli("ingest", "--input", data / HEAD_ZIP, "--out", tmp_path / "o", *args)
        assert result.exit_code == 2 and message in " ".join(result.stderr.split()), result.stderr
    result = cli("ingest", "--download", "2016-03-01", "--out", tmp_path / "o")
    assert result.exit_code == 2 and "files of 2015-2017 are monthly" in result.stderr
    result = cli("ingest", "--out", tmp_path / "o")
    assert result.exit_code == 2 and "nothing to ingest" in result.stderr


def test_zst_and_directory_inputs(cli, data, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "ais-2025-01-01.csv.zst").write_bytes(_zst(data, truncate=False))
    shutil.copy(data / "NYHarbor_2020_06_30_first_hour.csv", folder)
    result, report = ingest(cli, tmp_path / "out", folder)
    assert result.exit_code == 0, result.output
    assert len(report["files"]) == 2 and report["rows_read"] > 8689
    check_contract(tmp_path / "out", report)


def test_since_until_take_a_period_on_every_reader(cli, data, tmp_path):
    """--since (inclusive) and --until (exclusive) take a period; the rows outside are counted
    as outside_period, not dropped unseen, whether the CSV goes by the fast path or the same
    rows are read the usual way (parquet) (issue 69, item 2)."""
    csv = data / "NYHarbor_2020_06_30_first_hour.csv"
    parquet = tmp_path / "hour.parquet"
    pd.read_csv(csv, dtype=str).to_parquet(parquet)
    since, until = pd.Timestamp("2020-06-30T00:10Z"), pd.Timestamp("2020-06-30T00:40Z")
    period = ("--since", "2020-06-30T00:10", "--until", "2020-06-30 00:40:00Z")
    extra = ("--roi", "none", "--min-points", "5", *period)
    reports = {}
    for source in (csv, parquet):
        out = tmp_path / source.suffix[1:]
        result, reports[source.suffix] = ingest(cli, out, source, extra=extra)
        assert result.exit_code == 0, result.output
        check_contract(out, reports[source.suffix])
        for name in ("points", "reports"):
            times = pq.read_table(out / f"{name}.parquet").column("time").to_pandas()
            assert times.min() >= since and times.max() < until
    first = reports[".csv"]
    assert first["rejected"]["outside_period"] == 4_205  # 8,689 rows, these outside
    assert first["rejected"] == reports[".parquet"]["rejected"]
    assert first["settings"]["since"] == "2020-06-30T00:10:00+00:00"


@pytest.mark.parametrize(
    "period, needle",
    [
        (("--since", "yesterday"), "--since 'yesterday': expected a date or an ISO 8601 time"),
        (("--until", "30/06/2020"), "--until '30/06/2020': expected a date"),
        (("--since", "2020-07-01", "--until", "2020-07-01"), "--since 2020-07-01 is not before"),
    ],
)
def test_a_bad_period_is_a_one_line_error(data, tmp_path, period, needle):
    out = tmp_path / "out"
    result = run("ingest", "--input", data / HEAD_ZIP, "--roi", "none", "--out", out, *period)
    one_line_error(result, needle)
    assert not out.exists()
