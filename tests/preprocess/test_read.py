"""Reading (`aisdati.preprocess.read`): column matching, type coercion, per-row rejection of
bad values. Through the real command line, on the New York Harbor hour made hostile the way a
careless or unlucky analyst would (issue 13; issue 27, items 5, 6 and 20): joined exports and
repeated headers, NaN and infinity in any spelling, long headers, blank lines, UTF-16 and UTF-32,
binary files and Parquet columns of the wrong type. The optional heading and status read where
a file has them, rejecting no row, and who each vessel is tallied as the rows are read."""

from __future__ import annotations

import codecs
import gzip
import re
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aisdati.errors import UserError
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.inputs import Source, sources_of
from aisdati.preprocess.layouts import resolve_columns
from aisdati.preprocess.lineguard import LineGuard
from aisdati.preprocess.read import SourceReader
from aisdati.preprocess.report import CODE
from aisdati.preprocess.vessels import winners
from tests.helpers.cli import one_line_error
from tests.helpers.ingest import (
    NY_HOUR,
    NY_ROWS,
    SETTINGS,
    ingest,
    ingest_ny_hour,
    ny_lines,
    ny_table,
    points,
)


def test_columns_match_case_underscores_and_spellings():
    cols = resolve_columns(
        ["base_date_time", "Latitude", "LONGITUDE", "mmsi", "SOG", "cog", "TranscieverClass"], "x"
    )
    assert cols == {
        "time": "base_date_time",
        "lat": "Latitude",
        "lon": "LONGITUDE",
        "mmsi": "mmsi",
        "sog": "SOG",
        "cog": "cog",
    }


def test_missing_required_column_is_named():
    with pytest.raises(UserError, match="LAT"):
        resolve_columns(["MMSI", "BaseDateTime", "LON", "SOG", "COG"], "f.csv")


def test_positions_only_columns_are_enough():
    assert set(resolve_columns(["MMSI", "BaseDateTime", "LAT", "LON"], "x")) == {
        "mmsi",
        "time",
        "lat",
        "lon",
    }


def _batch(**cols):
    return pa.record_batch({k: pa.array(v, pa.string()) for k, v in cols.items()})


def test_bad_values_are_rejected_per_row_with_their_reason():
    batch = _batch(
        MMSI=["367000001", "367000002", "367000003", "367000004.0", None, "x1"],
        BaseDateTime=["2022-01-03T00:00:00", "not a time", "2022-01-03 00:01:00"]
        + ["2022-01-03T00:00:00"] * 3,
        LAT=["25.1", "25.1", "north", "25.1", "25.1", "25.1"],
        LON=["-80.1"] * 6,
        SOG=["10.0"] * 6,
        COG=["-60.6"] * 6,
    )
    cols = {
        "mmsi": "MMSI",
        "time": "BaseDateTime",
        "lat": "LAT",
        "lon": "LON",
        "sog": "SOG",
        "cog": "COG",
    }
    table, codes = to_canonical(batch, cols, src=0)
    assert list(codes) == [
        0,
        CODE["bad_time"],
        CODE["bad_number"],
        0,
        CODE["missing_value"],
        CODE["bad_mmsi"],
    ]
    assert table.column("mmsi")[3].as_py() == 367000004  # "367000004.0" is an integer
    assert table.schema.field("time").type == pa.timestamp("us", tz="UTC")


def test_floats_in_integer_fields_2023_sample(data):
    reader = SourceReader(Source(data / "noaa_2023-01-11_1000rows.csv"))
    batches = list(reader.batches())
    table, codes = to_canonical(batches[0], reader.columns, 0)
    assert sum(b.num_rows for b in batches) == 1000
    assert (codes == 0).sum() > 990
    assert table.column("mmsi").to_numpy().min() > 0


def test_reordered_columns_and_misspelt_header_ny_hour(data):
    reader = SourceReader(Source(data / "NYHarbor_2020_06_30_first_hour.csv"))
    assert reader.columns["lon"] == "LON" and reader.columns["mmsi"] == "MMSI"
    table, _ = to_canonical(next(iter(reader.batches())), reader.columns, 0)
    assert np.nanmin(table.column("cog").to_numpy()) < 0  # raw negative COG, normalised later


@pytest.mark.parametrize(
    ("name", "kind", "compression"),
    [
        ("AIS_2022_01_03.csv", "csv", None),
        ("ais-2025-01-01.csv.zst", "csv", "zstd"),
        ("points.csv.gz", "csv", "gzip"),
        ("day.parquet", "parquet", None),
        ("log.nmea", "nmea", None),
        ("log.ais.gz", "nmea", "gzip"),
        ("receiver.txt.zst", "nmea", "zstd"),
    ],
)
def test_file_kinds_and_compression_come_from_the_name(name, kind, compression):
    source = Source(Path(name))
    assert (source.kind, source.compression) == (kind, compression)


def test_zip_members_are_csv(data):
    (source,) = sources_of(data / "AIS_2022_01_03_head.zip")
    assert (source.kind, source.compression, source.label) == (
        "csv",
        None,
        "AIS_2022_01_03_head.zip:AIS_2022_01_03.csv",
    )


@pytest.mark.parametrize("kind", ["csv", "gz", "zip"])
def test_the_guard_gives_blocks_of_the_size_asked_and_every_line_once(data, tmp_path, kind):
    """The start of a line that a chunk cuts goes in front of the next chunk (read in behind it,
    without a copy of the chunk), not into a block of one line: every block but the last is
    nearly the size asked, and the lines are the file's, in order."""
    text = (data / "noaa_2023-01-11_1000rows.csv").read_bytes()
    path = tmp_path / f"rows.{kind}"
    if kind == "csv":
        path.write_bytes(text)
    elif kind == "gz":
        path.write_bytes(gzip.compress(text))
    else:
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("rows.csv", text)
    stream, _ = Source(path, "rows.csv" if kind == "zip" else None).open()
    guard = LineGuard(stream, pytest.fail)
    blocks = [bytes(b) for b in iter(lambda: guard.read(8192), b"")]
    assert b"".join(blocks) == text.split(b"\n", 1)[1]
    assert all(8192 - 400 < len(b) <= 8192 and b.endswith(b"\n") for b in blocks[:-1])


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every damaged copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


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


def test_a_binary_file_named_csv_is_one_line(cli, data, tmp_path):
    src = tmp_path / "photo.csv"
    src.write_bytes(bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8)))
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "photo.csv: the first line is not CSV text")


NY_COLUMNS = ["BaseDateTime", "LON", "LAT", "MMSI", "SOG", "COG"]  # the hour's first six


# --------------------------------------------------- 5: a second header with another order
def test_joined_exports_are_read_under_each_ones_header(cli, data, tmp_path, baseline):
    """Two exports joined with `cat`, the second with LAT and LON swapped and MMSI first: the
    rows after the second header are read under it, not with latitude and longitude swapped."""
    table = ny_table(data)
    half = len(table) // 2
    order = ["MMSI", "LAT", "LON", *[c for c in table.columns if c not in ("MMSI", "LAT", "LON")]]
    src = tmp_path / "joined.csv"
    src.write_text(
        table.iloc[:half].to_csv(index=False) + table.iloc[half:][order].to_csv(index=False)
    )
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS + 1 and report["rejected"]["header_line"] == 1
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    kept = points(tmp_path / "out")
    assert kept["lat"].between(40, 41.5).all() and kept["lon"].between(-75, -73).all()


def test_a_header_repeated_in_the_same_order_is_counted(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    src = tmp_path / "twice.csv"
    src.write_bytes(b"".join([*lines[:4000], lines[0], *lines[4000:]]))
    result, report = ingest(cli, tmp_path / "out", src, extra=(*SETTINGS, "--keep-rejects"))
    assert result.exit_code == 0, result.output
    assert report["rejected"]["header_line"] == 1
    assert report["kept_points"] == baseline["kept_points"]
    rejects = pq.read_table(tmp_path / "out" / "rejects.parquet").to_pandas()
    header = rejects.loc[rejects["reason"] == "header_line", "raw"].tolist()
    assert header == [lines[0].decode().rstrip("\r\n")]


def test_a_second_header_naming_other_columns_is_one_line(cli, data, tmp_path):
    table = ny_table(data)
    src = tmp_path / "joined.csv"
    positions = table.iloc[100:][["MMSI", "BaseDateTime", "LAT", "LON"]]
    src.write_text(table.iloc[:100].to_csv(index=False) + positions.to_csv(index=False))
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "joined.csv: a second header line mid-file names other columns")


# ---------------------------------------------------------- 6: NaN and infinity, any spelling
NAN_SPELLINGS = ["NaN", "NAN", "Nan", "nan", "+nan", "-nan", " nan "]
INF_SPELLINGS = ["inf", "Inf", "INF", "+inf", "-inf", "Infinity", "-Infinity", "+Infinity", "1e400"]


def _complete_rows(lines: list[bytes]) -> list[int]:
    """Lines of the NY hour whose six needed fields are all numbers or times (no blank)."""
    return [i for i in range(1, len(lines)) if all(lines[i].split(b",")[:6])]


def test_nan_and_infinity_in_csv_are_rejected_in_every_spelling(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    rows = _complete_rows(lines)[::50]
    spellings = NAN_SPELLINGS + INF_SPELLINGS
    for k, spelling in enumerate(spellings):
        for j, column in enumerate(("LON", "LAT", "SOG", "COG")):  # each spelling, each column
            i = rows[4 * k + j]
            fields = lines[i].split(b",")
            fields[NY_COLUMNS.index(column)] = spelling.encode()
            lines[i] = b",".join(fields)
    src = tmp_path / "nan.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src)  # route clusters: the default
    assert result.exit_code == 0, result.output
    rejected, before = report["rejected"], baseline["rejected"]
    assert rejected["missing_value"] == before["missing_value"] + 4 * len(NAN_SPELLINGS)
    assert rejected["bad_number"] == before["bad_number"] + 4 * len(INF_SPELLINGS)
    kept = points(tmp_path / "out")
    assert np.isfinite(kept[["lon", "lat", "sog", "cog"]].to_numpy(float)).all()


def test_nan_and_infinity_in_parquet_are_rejected(cli, data, tmp_path, baseline):
    table = pd.read_csv(data / NY_HOUR)
    rows = table.dropna(subset=["LAT", "LON", "SOG", "COG"]).index[::100][:8]
    for k, (column, value) in enumerate(
        [("LAT", np.nan), ("LON", np.inf), ("SOG", -np.inf), ("COG", np.nan)] * 2
    ):
        table.loc[rows[k], column] = value
    src = tmp_path / "nan.parquet"
    pq.write_table(pa.Table.from_pandas(table, preserve_index=False), src)
    result, report = ingest(cli, tmp_path / "out", src, extra=SETTINGS)
    assert result.exit_code == 0, result.output
    rejected, before = report["rejected"], baseline["rejected"]
    assert rejected["missing_value"] == before["missing_value"] + 4
    assert rejected["bad_number"] == before["bad_number"] + 4
    tracks = pq.read_table(tmp_path / "out" / "tracks.parquet").to_pandas()
    assert np.isfinite(tracks["length_km"]).all()


# ----------------------------------------------------------------------- 20: messages
def test_blank_lines_before_the_header_are_skipped(cli, data, tmp_path, baseline):
    src = tmp_path / "blank.csv"
    src.write_bytes(b"\n\r\n   \n" + (data / NY_HOUR).read_bytes())
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be-bom", "utf-32"])
def test_utf16_and_utf32_with_a_bom_read_like_utf8(cli, data, tmp_path, baseline, encoding):
    text = (data / NY_HOUR).read_text()
    raw = (
        codecs.BOM_UTF16_BE + text.encode("utf-16-be")
        if encoding == "utf-16-be-bom"
        else text.encode(encoding)
    )
    src = tmp_path / "wide.csv"
    src.write_bytes(raw)
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]


def test_utf16_without_a_bom_is_one_line(cli, data, tmp_path):
    src = tmp_path / "wide.csv"
    src.write_bytes((data / NY_HOUR).read_text().encode("utf-16-le"))
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "wide.csv: UTF-16 text without a byte-order mark: save it as UTF-8")


def test_a_struct_lat_in_parquet_is_one_line(cli, data, tmp_path):
    table = pa.Table.from_pandas(pd.read_csv(data / NY_HOUR), preserve_index=False)
    at = table.schema.get_field_index("LAT")
    wrapped = pa.StructArray.from_arrays([table.column("LAT").combine_chunks()], ["value"])
    src = tmp_path / "struct.parquet"
    pq.write_table(table.set_column(at, "LAT", wrapped), src)
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(
        result,
        re.escape("struct.parquet: column LAT has type struct<value: double>, expected numbers"),
    )


def test_a_parquet_mmsi_of_booleans_is_one_line(cli, data, tmp_path):
    table = pd.read_csv(data / NY_HOUR)
    table["MMSI"] = table["MMSI"] % 2 == 0
    src = tmp_path / "bool.parquet"
    table.to_parquet(src, index=False)
    result, _ = ingest(cli, tmp_path / "out", src)
    one_line_error(result, "bool.parquet: column MMSI has type bool, expected numbers")


# ------------------------------------------------ the optional heading and status, the vessels
def read_rows(path: Path, member: str | None = None) -> tuple[pa.Table, np.ndarray, pa.Table]:
    """A file's canonical rows, their codes, and its vessels' values (`vessels.winners`)."""
    reader = SourceReader(Source(path, member))
    pieces = list(reader.tables(0))
    codes = np.concatenate([c for _, c in pieces])
    return pa.concat_tables([t for t, _ in pieces]), codes, winners([reader.vessels.table(0)])


def test_heading_and_status_are_read_where_a_file_has_them(data):
    """The NY hour writes `246.0` and `0.0`; Kitimat (MarineCadastre 2018) a heading of 511 and
    a blank status: none, and no row rejected for it."""
    table, _, _ = read_rows(data / NY_HOUR)
    text = ny_table(data)
    heading = pd.to_numeric(text["Heading"], errors="coerce").where(lambda h: h < 360)
    assert np.allclose(table.column("heading").to_numpy(), heading, equal_nan=True)
    assert table.column("status").to_pylist() == [
        None if s in ("", "15.0") else int(float(s)) for s in text["Status"]
    ]
    assert table.column("status").null_count < len(text) // 2  # most rows give a status
    table, codes, _ = read_rows(data / "AIS_2018_07-08_Kitimat.csv.gz")
    assert np.isnan(table.column("heading").to_numpy()).all()
    assert table.column("status").null_count == table.num_rows
    assert not np.isin(codes, [CODE["missing_value"], CODE["bad_number"]]).any()


def test_a_damaged_heading_or_status_rejects_no_row(cli, data, tmp_path, baseline):
    """Every heading and status of the NY hour blank, unreadable or out of range: the same rows
    kept and the same tracks as the clean hour, with none for those values."""
    table = ny_table(data)
    junk = ["", "x", "511", "-5", "360", "NaN", "Moored here", "999"]
    table["Heading"] = [junk[k % len(junk)] for k in range(len(table))]
    table["Status"] = [junk[(k + 3) % len(junk)] for k in range(len(table))]
    src = tmp_path / "junk.csv"
    table.to_csv(src, index=False)
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    for key in ("rejected", "kept_points", "tracks"):
        assert report[key] == baseline[key], key
    got, want = points(tmp_path / "out"), points(Path(baseline["outputs"]["points"]).parent)
    assert got.drop(columns=["heading", "status"]).equals(want.drop(columns=["heading", "status"]))
    assert got["heading"].isna().all() and got["status"].isna().all()


def test_the_vessels_of_a_csv_are_tallied_as_it_is_read(data):
    """Name, type and length per MMSI: MarineCadastre's numeric types become their ITU group
    (60 Passenger, 90 Other, 31 Towing), text types (Kitimat's) stay; a name quoted with a
    doubled quote inside is read unquoted."""
    _, _, ny = read_rows(data / NY_HOUR)
    ny = ny.to_pandas().set_index("mmsi")
    assert ny.loc[367000140].tolist() == ["SAMUEL I NEWHOUSE", "Passenger", 94.0]
    assert ny.loc[366999618].tolist() == ["CG SHRIKE", "Other", 26.0]
    assert 250 < len(ny) < ny_table(data)["MMSI"].nunique() == 295  # 24 give none of them
    _, _, day = read_rows(data / "AIS_2022_01_03_head.zip", "AIS_2022_01_03.csv")
    day = day.to_pandas().set_index("mmsi")
    assert day.loc[367704390].tolist() == ['RAY "CHIEF" TONEY', "Towing", 25.0]
    _, _, kitimat = read_rows(data / "AIS_2018_07-08_Kitimat.csv.gz")
    types = set(kitimat.column("ship_type").to_pylist())
    assert {"Tug", "Fishing"} <= types and kitimat.column("name").null_count == len(kitimat)


def test_optional_parquet_columns_of_other_types_are_left_out(data, tmp_path):
    """A parquet file whose Heading holds booleans and Status structs reads as one without them,
    not refused as a LAT of structs is."""
    table = ny_table(data)[NY_COLUMNS].head(50)
    arrow = pa.Table.from_pandas(table, preserve_index=False)
    arrow = arrow.append_column("Heading", pa.array([True] * 50))
    arrow = arrow.append_column("Status", pa.array([{"a": 1}] * 50))
    pq.write_table(arrow, tmp_path / "odd.parquet")
    reader = SourceReader(Source(tmp_path / "odd.parquet"))
    assert "heading" not in reader.columns and "status" not in reader.columns
    rows, codes, _ = read_rows(tmp_path / "odd.parquet")
    assert rows.num_rows == 50 and not codes.any() and rows.column("status").null_count == 50
