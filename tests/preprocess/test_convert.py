"""Conversion to the canonical frame (`aisdati.preprocess.convert`): times in every unit and
outside the AIS era, MMSIs as integers whatever their text, through the real command line where
a user meets them (issues 13 and 27) and piece by piece; the optional heading and navigational
status, which reject no row."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aisdati.preprocess.convert import STATUS_NAMES, heading_of, status_of, time_us, to_canonical
from aisdati.preprocess.report import CODE
from tests.helpers.ingest import NY_HOUR, NY_ROWS, ingest, ingest_ny_hour, ny_lines, points


def test_numeric_times_in_every_unit():
    t = 1_593_475_200  # 2020-06-30T00:00:00Z
    arr = pa.array([t, t * 1_000, t * 1_000_000, t * 1_000_000_000, 5, None], pa.int64())
    us, bad = time_us(arr)
    assert list(us[:4]) == [t * 1_000_000] * 4
    assert list(bad) == [False, False, False, False, True, False]  # 1970 is no AIS time
    us, bad = time_us(pa.array([str(t), "2020-06-30T00:00:00", "20200630", "soon"]))
    assert list(us[:3]) == [t * 1_000_000] * 3 and list(bad) == [False, False, False, True]
    us, bad = time_us(pa.array([t + 0.5, float("nan")]))
    assert us[0] == t * 1_000_000 + 500_000 and list(bad) == [False, True]


def test_epoch_text_alone_reads_as_it_reads_among_other_times():
    """A column of epoch seconds or milliseconds as text (receivers' tag blocks) is read at once
    as numbers: the same microseconds and bad times as where ISO times share the column."""
    texts = ["1593475200", "1593475200123", "1593475200999", "100000000", "9999999999999"]
    alone = time_us(pa.array(texts))
    mixed = time_us(pa.array([*texts, "2020-06-30T00:00:00"]))
    assert alone[1].tolist() == mixed[1][:-1].tolist() == [False, False, False, True, True]
    assert alone[0][:3].tolist() == mixed[0][:3].tolist()  # (a bad time's value is not read)
    assert alone[0][:3].tolist() == [1593475200_000_000, 1593475200_123_000, 1593475200_999_000]


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every damaged copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


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


# ------------------------------------------------------------- 7: MMSIs beyond float64
def test_mmsis_beyond_float_precision_stay_two_vessels(cli, data, tmp_path, baseline):
    """9007199254740992 and ...993 are one number to float64: read as integers they are two."""
    base = points(Path(baseline["outputs"]["points"]).parent)
    first, second = (str(m).encode() for m in base["mmsi"].value_counts().index[:2])
    lines = ny_lines(data)
    big = {first: b"9007199254740993", second: b"9007199254740992"}
    for i in range(1, len(lines)):
        fields = lines[i].split(b",")
        fields[3] = big.get(fields[3], fields[3])
        lines[i] = b",".join(fields)
    src = tmp_path / "big.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    kept = points(tmp_path / "out")["mmsi"].value_counts()
    for old, new in big.items():
        assert kept[int(new)] == (base["mmsi"] == int(old)).sum()


def test_mmsi_text_forms():
    """Digits (perhaps with `.0`, a sign or blanks) are MMSIs up to 18 digits; exponents,
    fractions, hex, zero, negatives and 19 digits or more are bad_mmsi."""
    good = {"367000004": 367000004, "367000004.0": 367000004, " +367000001 ": 367000001}
    good |= {"1072211352": 1072211352, "9" * 18: int("9" * 18)}
    bad = ["3.67E+08", "367000004.5", "0x10", "0", "-5", "9" * 19, "1" + "0" * 20, "nan", "inf"]
    mmsi = list(good) + bad
    batch = pa.record_batch(
        {
            "MMSI": pa.array(mmsi),
            "T": pa.array(["2020-06-30T00:00:00"] * len(mmsi)),
            "LAT": pa.array(["40.5"] * len(mmsi)),
            "LON": pa.array(["-74.0"] * len(mmsi)),
        }
    )
    table, codes = to_canonical(batch, {"mmsi": "MMSI", "time": "T", "lat": "LAT", "lon": "LON"}, 0)
    assert table.column("mmsi").to_pylist()[: len(good)] == list(good.values())
    assert codes.tolist() == [0] * len(good) + [CODE["bad_mmsi"]] * len(bad)


def test_a_60_digit_time_is_a_bad_time_without_warnings(cli, data, tmp_path, baseline):
    lines = ny_lines(data)
    lines[100] = b"1" * 60 + lines[100][lines[100].index(b",") :]
    src = tmp_path / "long_time.csv"
    src.write_bytes(b"".join(lines))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rejected"]["bad_time"] == baseline["rejected"]["bad_time"] + 1
    assert [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)] == []


# ------------------------------------------------------------- the optional heading and status
def test_a_heading_is_degrees_in_0_360_and_else_none():
    texts = ["246.0", "0", "359.9", "511", "360", "-1", "", None, "north", "nan"]
    got = heading_of(pa.array(texts, pa.string()))
    assert got.dtype == "float32"
    assert got[:3].tolist() == pytest.approx([246.0, 0.0, 359.9])
    assert pd.isna(got[3:]).all()
    assert heading_of(pa.array([511, 12, None], pa.int16())).tolist()[1] == 12.0


def test_a_status_is_a_code_of_0_to_14_as_number_or_dma_name():
    """MarineCadastre writes codes (`0.0`), the DMA names (`Under way using engine`); 15 (not
    defined), 'Unknown value', other numbers and text are none."""
    texts = ["0.0", "5", "14", "15", "2.5", "-1", "", None, "Moored", "At anchor", "Unknown value"]
    got = status_of(pa.array(texts, pa.string()))
    assert got.type == pa.int16()
    assert got.to_pylist() == [0, 5, 14, None, None, None, None, None, 5, 1, None]
    numbers = status_of(pa.array([0.0, 8.0, 15.0, float("nan"), None]))
    assert numbers.to_pylist() == [0, 8, None, None, None]


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ("Under way using engine", 0),
        ("At anchor", 1),
        ("Not under command", 2),
        ("Restricted maneuverability", 3),
        ("Restricted manoeuvrability", 3),
        ("Constrained by her draught", 4),
        ("Moored", 5),
        ("Aground", 6),
        ("Engaged in fishing", 7),
        ("Under way sailing", 8),
        ("Reserved for future amendment [HSC]", 9),
        ("Reserved for future amendment [WIG]", 10),
        ("Power-driven vessel towing astern", 11),
        ("Power-driven vessel pushing ahead or towing alongside", 12),
        ("AIS-SART", 14),
        ("Reserved for future use", None),
        ("Unknown value", None),
        ("Not defined", None),
    ],
)
def test_the_dma_status_names_map_to_their_codes(text, code):
    assert status_of(pa.array([text, text.upper()])).to_pylist() == [code, code]
    assert len(set(STATUS_NAMES.values())) == 14  # 0-12 and 14: 13 has no name of its own


def test_a_blank_or_bad_heading_or_status_rejects_no_row():
    """Only the required columns reject a row as missing: a row without a heading or status
    is kept, with none (NaN, null)."""
    batch = pa.record_batch(
        {
            "MMSI": ["367000001", "367000002", "367000003", "367000004"],
            "BaseDateTime": ["2020-06-30T00:00:00"] * 4,
            "LAT": ["40.5", "40.5", "40.5", None],  # (a CSV blank)
            "LON": ["-74.1"] * 4,
            "SOG": ["10.2"] * 4,
            "COG": ["90.0"] * 4,
            "Heading": ["", "x", "511", "246"],
            "Status": ["", "Moored", "99", "0"],
        }
    )
    columns = {"mmsi": "MMSI", "time": "BaseDateTime", "lat": "LAT", "lon": "LON", "sog": "SOG"}
    columns |= {"cog": "COG", "heading": "Heading", "status": "Status"}
    table, codes = to_canonical(batch, columns, 0)
    assert codes.tolist() == [0, 0, 0, CODE["missing_value"]]  # the blank LAT only
    assert pd.isna(table.column("heading").to_numpy()[:3]).all()
    assert table.column("status").to_pylist() == [None, 5, None, 0]
    del columns["heading"], columns["status"]  # a file without them: none, as before
    table, codes = to_canonical(batch, columns, 0)
    assert codes.tolist() == [0, 0, 0, CODE["missing_value"]]
    assert table.column("status").null_count == 4
