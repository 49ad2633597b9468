"""Hardening of `aisdati ingest` (issue 13): the real sample files, made bad inside each test the
way a careless or unlucky analyst would, through the real CLI. Numbers in comments are the
issue's items."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hardening import one_line_error

NY_HOUR = "NYHarbor_2020_06_30_first_hour.csv"
NY_ROWS = 8689
SETTINGS = ("--roi", "none", "--min-points", "20")


def ingest(cli, out: Path, *inputs, extra=SETTINGS):
    args = ["ingest", *[a for i in inputs for a in ("--input", i)], "--out", out, *extra]
    result = cli(*args, "--json")
    return result, (json.loads(result.stdout) if result.exit_code == 0 else None)


def leftovers(folder: Path) -> list[str]:
    names = [p.name for p in folder.iterdir()]
    return sorted(n for n in names if ".tmp" in n or n.startswith(".ingest-"))


def ingest_ny_hour(out: Path) -> dict:
    """The clean NY hour ingested into `out`: its report."""
    from typer.testing import CliRunner

    from aisdati.cli import app

    src = Path(__file__).parent / "data" / NY_HOUR
    args = ["ingest", "--input", str(src), "--out", str(out), *SETTINGS, "--json"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    assert report["rows_read"] == NY_ROWS and report["tracks"]["total"] > 20
    return report


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every damaged copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


def ny_lines(data: Path) -> list[bytes]:
    return (data / NY_HOUR).read_bytes().splitlines(keepends=True)


# ------------------------------------------------------------------- 3: parquet epoch seconds
@pytest.mark.parametrize("unit", ["s", "ms"])
def test_parquet_epoch_numbers_are_read_in_their_unit(cli, data, tmp_path, baseline, unit):
    table = pd.read_csv(data / NY_HOUR)
    stamps = pd.to_datetime(table["BaseDateTime"], utc=True)
    table["BaseDateTime"] = (stamps - pd.Timestamp(0, tz="UTC")) // pd.Timedelta(1, unit)
    src = tmp_path / "ny.parquet"
    pq.write_table(pa.Table.from_pandas(table, preserve_index=False), src)
    assert pq.read_schema(src).field("BaseDateTime").type == pa.int64()
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    times = pq.read_table(tmp_path / "out" / "points.parquet", columns=["time"]).column("time")
    assert str(pa.compute.min(times).as_py().date()) == "2020-06-30"


def test_times_outside_the_ais_era_are_bad_times(cli, data, tmp_path):
    """A time column read in the wrong unit lands in 1970: those rows are rejected, not kept."""
    lines = ny_lines(data)
    lines[1] = re.sub(rb"^2020-06-30T", b"1970-01-01T", lines[1])
    src = tmp_path / "old.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rejected"]["bad_time"] == 1


# -------------------------------------------------------------- 4, 11: ROI polygons
def _shifted_ny(data: Path, tmp_path: Path) -> tuple[Path, float]:
    """The NY hour moved in longitude so that its traffic straddles the antimeridian."""
    table = pd.read_csv(data / NY_HOUR)
    shift = 180.0 - float(table["LON"].median())
    table["LON"] = (table["LON"] + shift + 180.0) % 360.0 - 180.0
    assert (table["LON"] > 170).any() and (table["LON"] < -170).any()
    src = tmp_path / "antimeridian.csv"
    table.to_csv(src, index=False)
    return src, shift


def test_roi_across_the_antimeridian_is_not_its_complement(cli, data, tmp_path, baseline):
    src, _ = _shifted_ny(data, tmp_path)
    roi = tmp_path / "dateline.geojson"
    ring = [[170, 35], [-170, 35], [-170, 45], [170, 45], [170, 35]]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    result, report = ingest(cli, tmp_path / "out", src, extra=("--roi", roi, "--min-points", "20"))
    assert result.exit_code == 0, result.output
    assert report["rejected"]["outside_roi"] == 0  # every report lies within 10 deg of 180
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    assert "antimeridian" in result.stderr and "warning:" in result.stderr
    # the same area written with longitudes beyond 180 reads the same
    beyond = [[x % 360, y] for x, y in ring]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [beyond]}))
    result, again = ingest(cli, tmp_path / "out2", src, extra=("--roi", roi, "--min-points", "20"))
    assert result.exit_code == 0 and again["kept_points"] == baseline["kept_points"]


@pytest.mark.parametrize("bad", ["NaN", "Infinity"])
def test_roi_with_nan_coordinates_is_one_line(cli, data, tmp_path, bad):
    roi = tmp_path / "nan.geojson"
    ring = f"[[-75, 40], [{bad}, 40], [-73, 41], [-75, 40]]"
    roi.write_text('{"type": "Polygon", "coordinates": [' + ring + "]}")
    result, _ = ingest(cli, tmp_path / "out", data / NY_HOUR, extra=("--roi", roi))
    one_line_error(result, "NaN or infinite coordinates")


def test_roi_latitudes_off_the_earth_are_one_line(cli, data, tmp_path):
    roi = tmp_path / "far.geojson"
    ring = [[0, 0], [1, 95], [2, 0], [0, 0]]
    roi.write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    result, _ = ingest(cli, tmp_path / "out", data / NY_HOUR, extra=("--roi", roi))
    one_line_error(result, r"lat in \[-90, 90\]")


# ------------------------------------------------------------------ 5, 18: float options
@pytest.mark.parametrize(
    "option, value, needle",
    [
        ("--min-sog", "nan", "--min-sog must be a finite number < 102.2, got nan"),
        ("--min-sog", "inf", "--min-sog must be a finite number"),
        ("--max-speed", "nan", "--max-speed must be a finite number > 0, got nan"),
        ("--max-speed", "-5", "--max-speed must be a finite number > 0, got -5"),
        ("--stop-gap", "9" * 400 + "h", "--stop-gap must be a finite number"),
    ],
)
def test_float_options_must_be_finite_and_in_range(cli, data, tmp_path, option, value, needle):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=("--roi", "none", option, value))
    one_line_error(result, re.escape(needle))
    assert not out.exists()  # checked before any work


# ------------------------------------------------------------------------ 6: zero tracks
def test_a_run_that_keeps_no_track_fails_and_says_where_the_rows_went(cli, data, tmp_path):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=("--roi", "none", "--min-points", "100000"))
    one_line_error(result, f"no track kept: {NY_ROWS:,} rows read, rejected: slow 6,954, ")
    where = re.search(r"rejected: (.*); nothing written", result.stderr.replace("\n", " "))[1]
    counts = {r: int(n.replace(",", "")) for r, n in (p.split() for p in where.split(", "))}
    assert sum(counts.values()) == NY_ROWS and "short_segment" in counts  # every row, by reason
    assert not (out / "points.parquet").exists() and not (out / "tracks.parquet").exists()
    assert leftovers(out) == []


# ------------------------------------------------------------------------ 8: output folder
def test_out_is_a_file_or_under_a_file(cli, data, tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("not a folder")
    result, _ = ingest(cli, a_file, data / NY_HOUR)
    one_line_error(
        result, "cannot write to output folder .*file.txt \\(--out\\): it is a file, not a folder"
    )
    # Under a regular file: what a folder without write permission gives a non-root user (the
    # tests run as root, whom permissions do not stop), through the same check.
    result, _ = ingest(cli, a_file / "sub", data / NY_HOUR)
    one_line_error(
        result,
        r"cannot write to output folder .* \(--out\): cannot create it, a part of the path is a "
        "file",
    )
    assert a_file.read_text() == "not a folder"


def test_an_output_name_taken_by_a_folder_leaves_nothing_behind(cli, data, tmp_path):
    out = tmp_path / "out"
    (out / "tracks.parquet").mkdir(parents=True)  # points.parquet is a folder (of parts) itself
    result, _ = ingest(cli, out, data / NY_HOUR)
    one_line_error(result, "tracks.parquet there is a folder")
    assert leftovers(out) == [] and sorted(p.name for p in out.iterdir()) == ["tracks.parquet"]


# ----------------------------------------------------------------- 9: line ends, long header
def test_old_mac_cr_line_endings(cli, data, tmp_path, baseline):
    src = tmp_path / "cr.csv"
    src.write_bytes(b"".join(line.rstrip(b"\r\n") + b"\r" for line in ny_lines(data)))
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]
    assert report["rejected"]["malformed_row"] == 0


def test_header_and_field_longer_than_the_csv_modules_limit(cli, data, tmp_path, baseline):
    import csv

    big = csv.field_size_limit() + 1000
    lines = [line.rstrip(b"\r\n") for line in ny_lines(data)]
    lines[0] += b"," + b"Notes" * (big // 5)
    lines[1:] = [line + b"," for line in lines[1:]]
    lines[5] += b"y" * big
    src = tmp_path / "wide.csv"
    src.write_bytes(b"\n".join(lines) + b"\n")
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]


def test_a_first_line_without_end_is_one_line(cli, tmp_path):
    src = tmp_path / "blob.csv"
    src.write_bytes(b"MMSI," * 300_000)
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "no line break in the first 1 MiB")


# ---------------------------------------------------------------- 10: random bytes mid-file
def test_random_bytes_mid_file_cost_their_rows_only(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    rng = np.random.default_rng(13)
    noise = bytes(b for b in rng.integers(0, 256, 400, dtype=np.uint8) if b not in b'\r\n",')
    middle = len(lines) // 2
    lines[middle] = lines[middle][:30] + noise + lines[middle][30:]  # inside a row's fields
    lines[middle + 1] = lines[middle + 1].replace(b"CG ", b"C\xff\xfeG ")  # a column not read
    src = tmp_path / "noise.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS
    lost = report["rejected_total"] - baseline["rejected_total"]
    assert 0 <= lost <= 1  # the row with the noise in its fields, nothing else
    assert baseline["kept_points"] - report["kept_points"] <= 1
    assert all(c.isprintable() or c in "\n\t" for c in result.output)  # no raw bytes printed
    rejects = pq.read_table(tmp_path / "out" / "rejects.parquet").to_pandas()
    assert len(rejects) == report["rejected_total"]


# -------------------------------------------------------------- 13: an unterminated quote
def test_an_unterminated_quote_costs_one_row(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    lines[100] = lines[100].replace(b",", b',"', 7)  # opens a quote in the vessel name
    src = tmp_path / "quote.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS
    assert report["rejected"]["malformed_row"] == 1
    assert baseline["kept_points"] - report["kept_points"] <= 1
    raw = pq.read_table(tmp_path / "out" / "rejects.parquet").column("raw").to_pylist()
    assert [r for r in raw if r] == [lines[100].decode().rstrip("\r\n")]


def test_quoted_fields_with_commas_still_parse(cli, data, tmp_path):
    """Kitimat's vessel types are quoted and hold commas: not one row is malformed."""
    result, report = ingest(
        cli, tmp_path / "out", data / "AIS_2018_07-08_Kitimat.csv.gz",
        extra=("--roi", "none", "--min-points", "100"),
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == 134_758 and report["rejected"]["malformed_row"] == 0


# ----------------------------------------------------------------------- 14: a 60 MB line
def test_a_60_mb_line_among_good_rows(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    src = tmp_path / "huge_line.csv"
    with src.open("wb") as f:
        f.writelines(lines[:4000])
        f.write(b"367000999,2020-06-30T00:10:00," + b"9" * (60 << 20) + b",1,2\n")
        f.writelines(lines[4000:])
    result, report = ingest(cli, tmp_path / "out", src, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS + 1
    assert report["rejected"]["malformed_row"] == 1
    assert report["kept_points"] == baseline["kept_points"]
    raw = pq.read_table(tmp_path / "out" / "rejects.parquet").column("raw").to_pylist()
    raw = [r for r in raw if r]
    assert len(raw) == 1 and len(raw[0]) < 2000 and "62,914,5" in raw[0]


# ------------------------------------------------------------- 16: stale rejects.parquet
def test_rejects_of_an_earlier_run_do_not_stay(cli, data, tmp_path):
    out = tmp_path / "out"
    result, _ = ingest(cli, out, data / NY_HOUR, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0 and (out / "rejects.parquet").is_dir()  # a Parquet dataset
    result, report = ingest(cli, out, data / NY_HOUR)
    assert result.exit_code == 0, result.output
    assert not (out / "rejects.parquet").exists()
    assert "rejects" not in report["outputs"]
    assert sorted(p.name for p in out.iterdir()) == sorted(
        Path(f).name for f in report["outputs"].values()
    )


def test_a_binary_file_named_csv_is_one_line(cli, data, tmp_path):
    src = tmp_path / "photo.csv"
    src.write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8)))
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "photo.csv: the first line is not CSV text")
