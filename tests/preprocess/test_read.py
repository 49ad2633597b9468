"""Reading: column matching, type coercion, per-row rejection of bad values."""

from __future__ import annotations

import gzip
import zipfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from aisdati.errors import UserError
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.inputs import Source, sources_of
from aisdati.preprocess.layouts import resolve_columns
from aisdati.preprocess.lineguard import LineGuard
from aisdati.preprocess.read import SourceReader
from aisdati.preprocess.report import CODE


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
