"""Hardening (issue 13), piece by piece: the option ranges, the line guard against pyarrow's own
CSV reader and numeric times in every unit (the model card validator: tests/test_model_card.py)."""

from __future__ import annotations

import io

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pytest

from aisdati.errors import UserError
from aisdati.options import check_option
from aisdati.preprocess.convert import time_us
from aisdati.preprocess.lineguard import LineGuard

ROWS = b"".join(b"%d,x%d,z\n" % (i, i) for i in range(200))


@pytest.mark.parametrize(
    "name, value, ok",
    [
        ("--near-km", 10.0, True),
        ("--near-km", float("nan"), False),
        ("--near-km", 0.0, False),
        ("--threshold", 1.0, True),
        ("--threshold", 1.0000001, False),
        ("--min-sog", -1.0, True),  # negative keeps every SOG, even 0, as before
        ("--min-sog", float("-inf"), False),
        ("--top-percent", None, True),  # an option left unset
        ("--seed", 0, True),
        ("--seed", 2**32, False),
        ("--anything-else", float("inf"), False),  # any float must at least be finite
    ],
)
def test_option_ranges(name, value, ok):
    if ok:
        check_option(name, value)
    else:
        with pytest.raises(UserError, match=f"^{name} must be"):
            check_option(name, value)


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
