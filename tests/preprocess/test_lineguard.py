"""The line guard (`aisdati.preprocess.lineguard`): one bad line costs one counted row, never
the file. Against pyarrow's own CSV reader, at every offset, and through the real command line
on the New York Harbor hour made bad the way a careless or unlucky analyst would (issue 13,
items 9, 10, 13 and 14; issue 27); a quoted field holding a line end read as the CSV it is
(issue 66, item 8)."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from aisdati.preprocess.lineguard import LineGuard, Multiline
from tests.helpers.ingest import NY_ROWS, SETTINGS, ingest, ingest_ny_hour, ny_lines

ROWS = b"".join(b"%d,x%d,z\n" % (i, i) for i in range(200))


def _pyarrow_rows(data: bytes) -> tuple[int, int]:
    """(rows, malformed rows) as pyarrow reads `data` (three columns, no header)."""
    bad: list[str] = []

    def skip(row):
        bad.append(row.text)
        return "skip"

    table = pcsv.read_csv(
        io.BytesIO(data),
        read_options=pcsv.ReadOptions(column_names=["a", "b", "c"]),
        parse_options=pcsv.ParseOptions(invalid_row_handler=skip),
        convert_options=pcsv.ConvertOptions(column_types={k: pa.string() for k in "abc"}),
    )
    return table.num_rows, len(bad)


TRICKY = [
    b'1,"unterminated,z',
    b'1,"a""b,z',  # an escaped quote, then no closing one
    b'1,"a"",z',
    b'1,x"y,"z',  # a literal quote, then one that opens the last field
    b'"a"x","b',  # after a closing quote, a quote is literal
    b'1,"ok""",z',
    b'1,"ab"c"d,z',
    b'1,"x,y",z',
    b'1,ab"c,z',
    b'1,"",z',
    b'1,""",z',
]


@pytest.mark.parametrize("line", TRICKY)
def test_the_guard_cuts_exactly_the_lines_pyarrow_would_run_on_with(line):
    """pyarrow carries an open quote over the following lines (rows vanish); the guard must cut
    those lines, and only those, so that every other row stays."""
    data = line + b"\n" + ROWS
    rows, malformed = _pyarrow_rows(data)
    swallows = rows + malformed < 201
    cut: list[str] = []
    guard = LineGuard(io.BytesIO(b"h1,h2,h3\n" + data), cut.append)
    cleaned = b"".join(iter(lambda: guard.read(1 << 16), b""))
    assert (cut == [line.decode()]) == swallows
    rows_after, malformed_after = _pyarrow_rows(cleaned)
    assert rows_after + malformed_after + len(cut) == 201
    assert rows_after >= 200


def test_the_guard_passes_clean_files_unchanged(data):
    raw = (data / "noaa_2023-01-11_1000rows.csv").read_bytes()
    guard = LineGuard(io.BytesIO(raw), pytest.fail)
    assert b"".join(iter(lambda: guard.read(4096), b"")) == raw.split(b"\n", 1)[1]


def test_the_guard_finds_every_header_line_at_every_offset_in_any_case():
    """A header met mid-file ends the stream there, wherever `mmsi` falls among the eight-byte
    words the search reads, whatever its case; `mmsi` inside a row's text ends nothing."""
    rng = np.random.default_rng(5)
    for trial in range(200):
        spelling = "".join(c.upper() if rng.random() < 0.5 else c for c in "mmsi")
        pad = "x" * int(rng.integers(0, 17))
        header = f"{pad}{spelling},LAT"
        rows = [f"{k},{'MMS' if k % 3 else 'MMSX'}{pad}" for k in range(int(rng.integers(1, 9)))]
        text = "\n".join(["h", *rows, header, "1,2", ""]).encode()
        met: list[bytes] = []

        def header_of(line: bytes, met: list[bytes] = met, pad: str = pad) -> list[str] | None:
            met.append(line)
            return line.decode().split(",") if line.lower().startswith(pad.encode()) else None

        guard = LineGuard(io.BytesIO(text), pytest.fail, 1, header_of)
        before = b"".join(iter(lambda guard=guard: guard.read(int(rng.integers(1, 64))), b""))
        assert before.decode().splitlines() == rows, trial
        assert guard.next_header().names == [f"{pad}{spelling}", "LAT"]
        assert met == [header.encode()]


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every damaged copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


# ----------------------------------------------------------------- 9: line ends, long header
def test_old_mac_cr_line_endings(cli, data, tmp_path, baseline):
    src = tmp_path / "cr.csv"
    src.write_bytes(b"".join(line.rstrip(b"\r\n") + b"\r" for line in ny_lines(data)))
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]
    assert report["rejected"]["malformed_row"] == 0


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


class _Trickle(io.BytesIO):
    """A stream that gives a few bytes per read, so lines and headers straddle the reads."""

    def read(self, n: int = -1) -> bytes:
        return super().read(7)


def test_the_guard_stops_at_a_header_that_straddles_reads(data):
    header, *rows = ny_lines(data)[:40]
    swapped = b"LAT,LON,BaseDateTime,MMSI\r\n"
    raw = b"".join([header, *rows[:20], swapped, *rows[20:]])
    guard = LineGuard(_Trickle(raw), pytest.fail, 1, lambda line: line.decode().split(","))
    first = b"".join(iter(lambda: guard.read(1 << 16), b""))
    found = guard.next_header()
    rest = b"".join(iter(lambda: guard.read(1 << 16), b""))
    assert found is not None and found.names == ["LAT", "LON", "BaseDateTime", "MMSI"]
    assert guard.next_header() is None
    assert first.split() == b"".join(rows[:20]).split()
    assert rest.split() == b"".join(rows[20:]).split()


# ------------------------------------------------- issue 66, item 8: a quoted line end is CSV
def test_a_record_whose_quoted_field_holds_a_line_end_stays_whole_across_every_read():
    """`1,"two\\nlines",z` is one valid record (pandas and pyarrow's `newlines_in_values` read
    it): the guard keeps it whole, held over from one read to the next wherever they cut it,
    and marks the piece holding it; a stray quote beside it is still cut alone."""
    record = b'7,"two\nlines ""quoted""",z\n'
    stray = b'8,"stray,z\n'
    data = ROWS + record + ROWS + stray + ROWS
    for size in (7, 64, 1 << 16):
        cut: list[str] = []
        guard = LineGuard(io.BytesIO(b"h1,h2,h3\n" + data), cut.append, fields=3)
        pieces = list(iter(lambda guard=guard, size=size: guard.read(size), b""))
        assert b"".join(pieces) == ROWS + record + ROWS + ROWS, size
        assert cut == [stray.decode().rstrip("\n")]
        marked = b"".join(p for p in pieces if isinstance(p, Multiline))
        assert record in marked and len(marked) <= len(ROWS + record) + size
    table = pcsv.read_csv(
        io.BytesIO(b"".join(pieces)),
        read_options=pcsv.ReadOptions(column_names=["a", "b", "c"]),
        parse_options=pcsv.ParseOptions(newlines_in_values=True),
        convert_options=pcsv.ConvertOptions(column_types={k: pa.string() for k in "abc"}),
    )
    assert table.num_rows == 601 and table.column("b")[200].as_py() == 'two\nlines "quoted"'


def test_a_quoted_line_end_in_a_vessel_name_costs_nothing(cli, data, tmp_path, baseline):
    """A MarineCadastre file whose VesselName holds a quoted line end (pandas reads it): every
    row was read twice, both halves malformed, and the vessel's reports were lost."""
    lines = ny_lines(data)
    mmsi = b"367000140"
    changed = 0
    for k, line in enumerate(lines):
        fields = line.split(b",")
        if fields[3] == mmsi:
            fields[7] = b'"SAMUEL I\nNEWHOUSE"'
            lines[k], changed = b",".join(fields), changed + 1
    src = tmp_path / "names.csv"
    src.write_bytes(b"".join(lines))
    result, report = ingest(cli, tmp_path / "out", src)
    assert result.exit_code == 0, result.output
    assert changed > 50 and report["rows_read"] == NY_ROWS
    assert report["rejected"]["malformed_row"] == 0
    assert report["kept_points"] == baseline["kept_points"]
    vessels = pq.read_table(tmp_path / "out" / "vessels.parquet").to_pandas()
    (name,) = vessels.loc[vessels["mmsi"] == int(mmsi), "name"]
    assert name == pd.read_csv(src, dtype=str).query(f"MMSI == '{mmsi.decode()}'").iloc[0, 7]
