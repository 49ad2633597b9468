"""The fast path of CSV reading (`aisdati.preprocess.fastcsv`) gives the rows, values, rejection
codes and skipped lines of the usual path (pyarrow's reader, then `convert.to_canonical`), bit
for bit, on the shipped real files and on the odd rows real exports hold."""

from __future__ import annotations

import gzip
import zipfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pytest

from aisdati.preprocess.fastcsv import TYPICAL_ROW_BYTES, ColumnSlots, parse_block
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.read import SourceReader

HEADER = "MMSI,BaseDateTime,LAT,LON,SOG,COG,Heading,VesselName"
ODD_ROWS = [
    '367000001,2022-01-03T00:00:00,40.5,-74.1,10.2,90.0,511,"QUOTED, NAME"',
    '367000002,2022-01-03T00:00:01,40.5,-74.1,10.2,90.0,511,O"BRIEN',
    "367000003,2022-01-03T00:00:02,,-74.1,10.2,90.0,511,BLANK LAT",
    "367000004,2022-01-03T00:00:03,+40.5,-74.1,10.2,90.0,511,PLUS",
    "367000005,2022-01-03T00:00:04,40.,-74.1,10.2,90.0,511,TRAILING POINT",
    "367000006,2022-01-03T00:00:05,4.05e1,-74.1,10.2,90.0,511,EXPONENT",
    "367000007,2022-01-03T00:00:06,40.5000000000000001,-74.1,10.2,90.0,511,LONG NUMBER",
    "367000008,2022-02-30T00:00:07,40.5,-74.1,10.2,90.0,511,NO SUCH DAY",
    "367000009,2022-01-03 25:00:08,40.5,-74.1,10.2,90.0,511,NO SUCH HOUR",
    "367000010,2022-01-03T00:00:09Z,40.5,-74.1,10.2,90.0,511,ZONE",
    "367000011,2022-01-03 00:00:10,40.5,-74.1,10.2,90.0,511,SPACE",
    "367000012,2022-01-03T00:00:11.5,40.5,-74.1,10.2,90.0,511,FRACTION",
    "1234567890123456789,2022-01-03T00:00:12,40.5,-74.1,10.2,90.0,511,19 DIGITS",
    "0,2022-01-03T00:00:13,40.5,-74.1,10.2,90.0,511,ZERO",
    "-367000015,2022-01-03T00:00:14,40.5,-74.1,10.2,90.0,511,NEGATIVE",
    "367000016,2022-01-03T00:00:15,-0.0,-74.1,-0.0,90.0,511,NEGATIVE ZERO",
    "367000017,2022-01-03T00:00:16,40.5,-74.1,10.2",
    "367000018,2022-01-03T00:00:17,40.5,-74.1,10.2,90.0,511,NAME,EXTRA",
    "",
    "   ",
    "367000019,1980-01-03T00:00:18,40.5,-74.1,10.2,90.0,511,BEFORE AIS",
    "367000020,2022-01-03T00:00:19,NA,-74.1,10.2,90.0,511,NA",
    "367000021,2022-01-03T00:00:20,nan,-74.1,10.2,90.0,511,NAN",
    "367000022,2022-01-03T00:00:21,40.5,-74.1,inf,90.0,511,INF",
    "3.67E+08,2022-01-03T00:00:22,40.5,-74.1,10.2,90.0,511,SPREADSHEET",
    "367000024,2024-02-29T23:59:59,40.5,-74.1,10.2,90.0,511,LEAP DAY",
    "367000025,2023-02-29T00:00:00,40.5,-74.1,10.2,90.0,511,NO LEAP DAY",
    "367000026,2022-01-03T00:00:60,40.5,-74.1,10.2,90.0,511,LEAP SECOND",
    "367000027,2022-01-03T00:00:23,40.5,-74.1,10.2,90.0,511,PLAIN",
    "367000028,2022-01-03T00:00:24,40.5,- 74.1,10.2,90.0,511,SPACED SIGN",
    '"367000029","2022-01-03T00:00:25","40.5","-74.1","10.2","90.0","511","ALL QUOTED"',
    '367000030,"",40.5,-74.1,10.2,90.0,511,EMPTY QUOTED TIME',
    '367000031,2022-01-03T00:00:27,"40.5"1,-74.1,10.2,90.0,511,TEXT AFTER THE QUOTES',
    '367000032,2022-01-03T00:00:28,"40""5",-74.1,10.2,90.0,511,ESCAPED QUOTE',
    '367000034,2022-01-03T00:00:30,40.5,-74.1,10.2,90.0,511,"RAY ""CHIEF"" TONEY"',
    '367000035,2022-01-03T00:00:31,40.5,-74.1,10.2,90.0,511,""""',
    '367000036,2022-01-03T00:00:32,40.5,-74.1,10.2,90.0,"5""11","""LEADING"',
    '367000037,2022-01-03T00:00:33,40.5,-74.1,10.2,90.0,511,"DOUBLED"" THEN UNENDED',
    '367000038,2022-01-03T00:00:34,40.5,-74.1,10.2,90.0,511,"DOUBLED ""AT THE END"""',
    "367000039,2022-01-03T00:00:35,-.5,-74.1,10.2,90.0,511,POINT FIRST",
    "367000040,2022-01-03T00:00:36,40.5,-74.1,1.2.3,90.0,511,TWO POINTS",
    "367000041,2022-01-03T00:00:37,40.5,-74.1,--5,90.0,511,TWO SIGNS",
    "0367000042,2022-01-03T00:00:38,40.5,-74.1,10.2,90.0,511,ZERO FIRST MMSI",
    "367000043,2022-01-03T00:00:3,40.5,-74.1,10.2,90.0,511,SHORT TIME",
    "367000044,2022-01-03T00:00:39,-,-74.1,10.2,90.0,-,A SIGN ALONE",
    "367000045,2022-01-03T00:00:40,0040.50,-74.1,10.2,90.0,511,ZEROS FIRST",
    "367000046,2022-01-03T00:00:41,40.5,-74.1,10.2,90.0,511.,HEADING WITH A POINT",
    '367000033,2022-01-03T00:00:29,40.5,-74.1,10.2,90.0,511,"UNENDED',
]


def both_ways(path: Path, member: str | None = None) -> tuple[tuple, tuple]:
    """(table, codes, skipped, vessel tally) of the fast path and of the usual path."""
    fast, usual = SourceReader(Source(path, member)), SourceReader(Source(path, member))
    got = list(fast.tables(3))
    want = list(usual.usual_tables(3))

    def joined(pieces: list) -> tuple[pa.Table, np.ndarray]:
        if not pieces:
            return None, np.empty(0, np.uint8)
        return pa.concat_tables([t for t, _ in pieces]), np.concatenate([c for _, c in pieces])

    return (
        (*joined(got), fast.skipped, fast.vessels.table(3)),
        (*joined(want), usual.skipped, usual.vessels.table(3)),
    )


def assert_same(path: Path, member: str | None = None, places: bool = True) -> int:
    """The fast path reads `path` as the usual path does, and tallies the same vessels (where
    each was last seen too, with `places`: a malformed row, which pyarrow skips, shifts
    them)."""
    fast, usual = both_ways(path, member)
    (table, codes, skipped, tally), (table_u, codes_u, skipped_u, tally_u) = fast, usual
    assert table.schema.equals(table_u.schema)
    for name in table.column_names:  # bit for bit (NaN included: SOG and COG not in a file)
        got, want = (t.column(name).combine_chunks() for t in (table, table_u))
        width = {8: pa.int64(), 4: pa.int32(), 2: pa.int16()}[got.type.bit_width // 8]
        assert got.view(width).equals(want.view(width)), name
    assert np.array_equal(codes, codes_u)
    assert {k: sorted(map(str, v)) for k, v in skipped.items()} == {
        k: sorted(map(str, v)) for k, v in skipped_u.items()
    }
    keys = ["mmsi", "name", "ship_type", "length_m"]
    columns = [c for c in tally.column_names if places or c != "last"]
    got, want = (t.select(columns).to_pandas().sort_values(keys, ignore_index=True)
                 for t in (tally, tally_u))  # fmt: skip
    assert got.equals(want)
    return table.num_rows


@pytest.mark.parametrize(
    ("name", "member"),
    [
        ("AIS_2018_07-08_Kitimat.csv.gz", None),
        ("NYHarbor_2020_12_first_week_points.csv.gz", None),
        ("VirginiaBeach_2020_06_04_to_06_filtered_points.csv.gz", None),
        ("AIS_2022_01_03_head.zip", "AIS_2022_01_03.csv"),
        ("noaa_2023-01-11_1000rows.csv", None),
    ],
)
def test_the_shipped_files_read_the_same_both_ways(data, name, member):
    assert assert_same(data / name, member) > 900


def test_odd_rows_read_the_same_both_ways_between_plain_ones(data, tmp_path):
    with zipfile.ZipFile(data / "AIS_2022_01_03_head.zip") as zf:
        real = zf.read("AIS_2022_01_03.csv").decode().splitlines()
    plain = [",".join([*line.split(",")[:7], "REAL"]) for line in real[1:400]]
    lines = [HEADER]
    for k, odd in enumerate(ODD_ROWS):
        lines += [*plain[k * 10 : k * 10 + 10], odd]
    path = tmp_path / "odd.csv"
    path.write_text("\r\n".join(lines))  # CRLF, and the last line without its end
    rows = sum(1 for row in lines[1:] if row.strip())
    # too few fields, too many, two quotes never closed
    assert assert_same(path, places=False) == rows - 4
    with gzip.open(tmp_path / "odd.csv.gz", "wt") as out:
        out.write("\n".join([*lines, "MMSI,LAT,LON,BaseDateTime,SOG,COG", *lines[1:3]]))
    assert_same(tmp_path / "odd.csv.gz", places=False)  # a header mid-file, another column order


def test_quoted_fields_take_the_fast_path_and_a_mostly_odd_file_reads_the_same(data, tmp_path):
    """pyarrow's and pandas' writers quote text: such rows are plain to the fast path. A file
    whose rows the fast path mostly cannot parse (fields with quotes inside) reads the same."""
    reader = SourceReader(Source(data / "AIS_2018_07-08_Kitimat.csv.gz"))
    rows = pa.Table.from_batches(list(reader.batches()))
    quoted = tmp_path / "quoted.csv"
    pcsv.write_csv(rows, quoted)  # every text field quoted
    assert b'"' in quoted.read_bytes()[:200]
    slots = ColumnSlots.of(rows.column_names, reader.columns)
    body = quoted.read_bytes().split(b"\n", 1)[1]
    assert not parse_block(body, slots).slow.any()
    assert assert_same(quoted) == rows.num_rows
    odd = tmp_path / "odd-quotes.csv"
    lines = quoted.read_text().splitlines()
    odd.write_text("\n".join([lines[0], *(line.replace('"', '""', 2) + '"' if k % 2 else line
                                            for k, line in enumerate(lines[1:2000]))]))  # fmt: skip
    assert_same(odd, places=False)


def test_a_doubled_quote_in_a_text_field_is_plain_and_in_a_needed_one_goes_the_usual_way():
    """MarineCadastre writes a quote in a vessel's name doubled ("RAY ""CHIEF"" TONEY"): such
    rows are plain; a needed value with one inside is left to pyarrow, which unquotes it."""
    names = HEADER.split(",")
    canonical = ["mmsi", "time", "lat", "lon", "sog", "cog"]
    slots = ColumnSlots.of(names, dict(zip(canonical, names[:6], strict=True)))
    rows = [r for r in ODD_ROWS if "DOUBLED" in r or "CHIEF" in r or '""""' in r or "LEADING" in r]
    parsed = parse_block(("\n".join(rows) + "\n").encode(), slots)
    assert parsed.slow.tolist() == [False, False, False, True, False]  # the unended one: usual
    escaped = parse_block(b'367000032,2022-01-03T00:00:28,"40""5",-74.1,10.2,90.0,511,X\n', slots)
    assert escaped.slow.tolist() == [True]


def test_numbers_are_the_correctly_rounded_floats_of_their_text():
    rng = np.random.default_rng(7)
    signs = np.where(rng.random(5000) < 0.5, "-", "")
    sizes = rng.integers(1, 8, size=(5000, 2))
    texts = [
        f"{sign}{rng.integers(0, 10**i)}.{rng.integers(0, 10**j):0{j}d}"
        for sign, (i, j) in zip(signs, sizes, strict=True)
    ]
    block = "".join(f"1,2022-01-03T00:00:00,{t},0,0,0\n" for t in texts).encode()
    names = ["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG"]
    canonical = ["mmsi", "time", "lat", "lon", "sog", "cog"]
    slots = ColumnSlots.of(names, dict(zip(canonical, names, strict=True)))
    parsed = parse_block(block, slots)
    assert not parsed.slow.any()
    want = np.array([float(t) for t in texts])
    assert np.array_equal(parsed.numbers[0].view(np.int64), want.view(np.int64))


def test_full_float_reprs_are_exact_where_their_digits_are_and_else_go_the_usual_way():
    """A shifted coordinate written as its shortest repr has 15-17 digits (-73.43350000000001):
    below 2**53 as an integer, it is parsed here, bit for bit; above, the usual way reads it."""
    rng = np.random.default_rng(3)
    values = rng.uniform(-180, 180, 5000) + 0.3
    texts = [repr(float(v)) for v in values]
    block = "".join(f"1,2022-01-03T00:00:00,{t},0,0,0\n" for t in texts).encode()
    names = ["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG"]
    canonical = ["mmsi", "time", "lat", "lon", "sog", "cog"]
    parsed = parse_block(block, ColumnSlots.of(names, dict(zip(canonical, names, strict=True))))
    digits = np.array([sum(c.isdigit() for c in t) for t in texts])
    exact = np.array([int("".join(c for c in t if c.isdigit())) <= 2**53 for t in texts])
    fast = ~parsed.slow
    assert np.array_equal(fast, exact) and fast[digits <= 15].all()
    assert 0.2 < fast[digits == 16].mean() < 1.0 and fast[digits == 17].mean() < 0.2
    want = np.array([float(t) for t in texts])
    assert np.array_equal(parsed.numbers[0][fast].view(np.int64), want[fast].view(np.int64))


def test_a_block_of_rows_shorter_than_the_outputs_expect_is_parsed_whole():
    """The kernel's outputs are first sized for rows of `TYPICAL_ROW_BYTES`; a block of shorter
    rows (here 14 bytes: malformed ones, as the usual way will find) is scanned again into
    outputs sized for them."""
    names = ["MMSI", "BaseDateTime", "LAT", "LON"]
    slots = ColumnSlots.of(names, dict(zip(["mmsi", "time", "lat", "lon"], names, strict=True)))
    block = b"".join(b"%09d,x,1,2\n" % k for k in range(1, 5001))
    assert len(block) // 5000 < TYPICAL_ROW_BYTES
    parsed = parse_block(block, slots)
    assert parsed.rows == 5000 and parsed.slow.all()
    assert parsed.mmsi.tolist() == list(range(1, 5001))


def test_the_columns_after_the_needed_ones_are_skipped_as_the_usual_way_reads_them(tmp_path):
    """The fields after the last needed one are passed over eight bytes at a time; rows whose
    text fields hold commas in quotes, doubled quotes, a quote mid-field, empty fields, or too
    few or too many fields, at every offset from a word's start, read as pyarrow reads them."""
    rng = np.random.default_rng(11)
    pieces = ["", "A", "BC", "SEA STAR", '"A, B"', '"RAY ""CHIEF"" T"', 'O"B', '""', "1.5", ","]
    weights = np.array([20, 20, 10, 10, 5, 3, 1, 2, 10, 1]) / 82
    header = "MMSI,BaseDateTime,LAT,LON,SOG,COG," + ",".join(f"X{k}" for k in range(9))
    lines = [header]
    for k in range(3000):
        fields = rng.choice(pieces, size=int(rng.choice([9, 9, 9, 8, 10])), p=weights)
        lead = (
            f"{367000000 + k},2022-01-03T00:{k // 60 % 60:02d}:{k % 60:02d},40.5,-74.{k},1.{k % 10}"
        )
        lines.append(f"{lead},{rng.integers(0, 360)}.{rng.integers(0, 10)}," + ",".join(fields))
    path = tmp_path / "tails.csv"
    path.write_text("\n".join(lines) + "\n")
    assert assert_same(path, places=False) > 1500
