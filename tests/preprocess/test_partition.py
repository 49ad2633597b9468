"""Hardening of reading (issue 27, a hostile-input probe): the real sample files, made hostile
inside each test, through the real CLI where a user would meet the fault. Numbers in comments
are the issue's items."""

from __future__ import annotations

import codecs
import io
import itertools
import math
import re
import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from test_hardening_ingest import (
    NY_HOUR,
    NY_ROWS,
    SETTINGS,
    ingest,
    ingest_ny_hour,
    ny_lines,
    one_line_error,
)

import aisdati.preprocess.partition as partition
import aisdati.preprocess.pipeline as pipeline
from aisdati.preprocess.convert import PARTITION_SCHEMA, to_canonical
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.lineguard import LineGuard
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings

KITIMAT = "AIS_2018_07-08_Kitimat.csv.gz"
NY_COLUMNS = ["BaseDateTime", "LON", "LAT", "MMSI", "SOG", "COG"]  # the hour's first six


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every hostile copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


def ny_table(data: Path) -> pd.DataFrame:
    """The NY hour as text, exactly as written (blanks stay blank)."""
    return pd.read_csv(data / NY_HOUR, dtype=str, keep_default_na=False)


def points(out: Path) -> pd.DataFrame:
    return pq.read_table(out / "points.parquet").to_pandas()


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


def test_non_finite_times_in_an_nmea_log_are_bad_times(tmp_path):
    sentence = "!AIVDM,1,1,,B,15NBj>PP1gG>1PVKTDTUJOv00<0M,0*09"  # real, tests/data/nmea
    stamps = ["2020-12-01T00:00:00Z", "nan", "NaN", "inf", "-Infinity", "1e400", "9" * 60]
    log = tmp_path / "log.nmea"
    log.write_text("".join(f"{stamp},{sentence}\n" for stamp in stamps))
    reader = open_reader(Source(log))
    (batch,) = reader.batches()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table, codes = to_canonical(batch, reader.columns, 0, reader.time_format)
    assert codes.tolist() == [0] + [CODE["bad_time"]] * (len(stamps) - 1)
    assert np.isfinite(table.column("lat").to_numpy()).all()


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


# ------------------------------------------------------ 9: zip members zipfile cannot read
def _zip_with_patched_header(data: Path, path: Path, method: int | None, flags: int) -> Path:
    """The NY hour as the one member of a zip, its method (and flag bits) rewritten in both
    the local and the central header, as an archiver using another method would write them."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.write(data / NY_HOUR, NY_HOUR)
    raw = bytearray(path.read_bytes())
    for signature, flag_at, method_at in ((b"PK\x03\x04", 6, 8), (b"PK\x01\x02", 8, 10)):
        at = raw.find(signature)
        (old,) = struct.unpack_from("<H", raw, at + flag_at)
        struct.pack_into("<H", raw, at + flag_at, old | flags)
        if method is not None:
            struct.pack_into("<H", raw, at + method_at, method)
    path.write_bytes(bytes(raw))
    return path


@pytest.mark.parametrize(
    ("method", "flags", "needle"),
    [
        (9, 0, "compression method Deflate64 not supported: unzip it first"),
        (98, 0, "compression method PPMd not supported: unzip it first"),
        (None, 0x1, "the member is encrypted: unzip it \\(with its password\\) first"),
        (99, 0x1, "the member is encrypted"),
    ],
)
def test_zip_members_zipfile_cannot_read_are_one_line(cli, data, tmp_path, method, flags, needle):
    archive = _zip_with_patched_header(data, tmp_path / "day.zip", method, flags)
    result, _ = ingest(cli, tmp_path / "out", archive)
    one_line_error(result, f"day.zip:{NY_HOUR}: {needle}")


@pytest.mark.parametrize("method", [zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA])
def test_bzip2_and_lzma_members_read_like_the_csv(cli, data, tmp_path, baseline, method):
    archive = tmp_path / "day.zip"
    with zipfile.ZipFile(archive, "w", method) as zf:
        zf.write(data / NY_HOUR, NY_HOUR)
    result, report = ingest(cli, tmp_path / "out", archive)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS and report["kept_points"] == baseline["kept_points"]


# ----------------------------------------- 18: one vessel's partition split by time, bounded
def test_a_large_partition_split_by_time_gives_the_same_outputs(data, tmp_path, monkeypatch):
    """Kitimat in one partition, read whole and split into pieces of 3,000 rows (one vessel
    cut at a time, in a gap): the points, tracks and counts are the same."""
    monkeypatch.setattr(pipeline, "MAX_PARTITIONS", 1)
    plans, plan_pieces = [], partition.plan_pieces

    def spy(*args):
        plans.append(plan_pieces(*args))
        return plans[-1]

    monkeypatch.setattr(partition, "plan_pieces", spy)
    outs = {}
    for rows in (2_000_000, 12_000):  # split: pieces of 3,000
        out = tmp_path / f"rows-{rows}"
        settings = IngestSettings(min_points=100, rows_per_bucket=rows)
        result = pipeline.ingest([data / KITIMAT], out, settings, None, "none")
        outs[rows] = (out, result.counts.as_dict())
    (whole, counts), (split, split_counts) = outs.values()
    (plan,) = plans
    assert plan.count > 10 and plan.cuts  # vessels packed into pieces, and one cut at times
    assert split_counts == counts
    for name in ("points.parquet", "tracks.parquet"):
        assert pq.read_table(split / name).equals(pq.read_table(whole / name)), name


def _kitimat_rows(data: Path) -> pa.Table:
    reader = open_reader(Source(data / KITIMAT))
    tables = [to_canonical(b, reader.columns, 0, reader.time_format)[0] for b in reader.batches()]
    return pa.concat_tables(tables)


def test_a_vessel_without_gaps_is_cut_into_bounded_time_ordered_pieces(data, tmp_path):
    """The busiest Kitimat vessel's reports, with every gap closed up to a minute: no safe cut
    anywhere, so the pieces are cut at times; each is bounded, and together, in order, they
    are the vessel's reports sorted by time (reports at one time never split up)."""
    rows = _kitimat_rows(data)
    mmsi = rows.column("mmsi").to_numpy()
    busiest = np.bincount(mmsi - mmsi.min()).argmax() + mmsi.min()
    vessel = rows.filter(pa.array(mmsi == busiest))
    time_us = np.sort(vessel.column("time").to_numpy().view(np.int64))
    steps = np.minimum(np.diff(time_us), 60_000_000)
    closed = time_us[0] + np.r_[0, np.cumsum(steps)]
    shuffled = np.random.default_rng(27).permutation(len(closed))  # spilled out of order
    at = PARTITION_SCHEMA.get_field_index("time")
    vessel = vessel.set_column(
        at, "time", pa.array(closed[shuffled]).view(PARTITION_SCHEMA.field("time").type)
    )
    bound = len(vessel) // 2  # pieces of a quarter of that: about 8
    parts = partition.VesselPartitions(tmp_path, 1, PARTITION_SCHEMA, bound, 3600.0)
    for chunk in vessel.to_batches(max_chunksize=500):
        parts.write(pa.Table.from_batches([chunk]))
    parts.close()
    pieces = list(parts)
    piece_rows = bound // partition.PIECES_PER_BOUND
    assert len(vessel) / piece_rows <= len(pieces) <= len(vessel) / piece_rows + 2
    assert all(p.num_rows <= piece_rows for p in pieces)
    times = [np.sort(p.column("time").to_numpy().view(np.int64)) for p in pieces]
    assert all(a[-1] < b[0] for a, b in itertools.pairwise(times))
    assert np.array_equal(np.concatenate(times), np.sort(closed))
    assert list(tmp_path.iterdir()) == []  # every spill file deleted


def test_many_vessels_pack_into_pieces_in_mmsi_order(data, tmp_path):
    rows = _kitimat_rows(data)
    parts = partition.VesselPartitions(tmp_path, 2, PARTITION_SCHEMA, 5_000, math.inf)
    parts.write(rows)
    parts.close()
    pieces = [p for p in parts if p.num_rows]
    assert len(pieces) > 2 and sum(p.num_rows for p in pieces) == rows.num_rows
    for a, b in itertools.pairwise(pieces):
        # pieces of one partition follow in MMSI order (a piece starts a new partition or goes on)
        ma, mb = a.column("mmsi").to_numpy(), b.column("mmsi").to_numpy()
        same_part = partition.partition_of(ma[:1], 2) == partition.partition_of(mb[:1], 2)
        assert not same_part[0] or ma.max() <= mb.min()


# --------------------------------------------------------------- 19: thousands of members
def test_thousands_of_small_members_read_as_the_one_file(cli, data, tmp_path, baseline):
    """2,000 members of a few rows each (CRLF, blank lines before the header, a UTF-8 BOM, no
    final line end, one with its columns reordered): the rows of the one file, and the small
    members read together, so the report lists three tables, not 2,000."""
    header, *lines = ny_lines(data)
    table = ny_table(data)
    per = -(-len(lines) // 2000)
    archive = tmp_path / "many.zip"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
        for k in range(2000):
            body = b"".join(lines[k * per : (k + 1) * per])
            text = header + body
            if k == 7:
                text = b"\n\r\n" + text
            elif k == 8:
                text = b"\xef\xbb\xbf" + text
            elif k == 9:
                text = text.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n")
            elif k == 1999:
                text = text.rstrip(b"\r\n")
            elif k == 1000:
                rows = table.iloc[k * per : (k + 1) * per]
                text = rows[list(reversed(table.columns))].to_csv(index=False).encode()
            zf.writestr(f"part-{k:05d}.csv", text)
    result, report = ingest(cli, tmp_path / "out", archive)
    assert result.exit_code == 0, result.output
    assert report["rows_read"] == NY_ROWS
    assert report["kept_points"] == baseline["kept_points"]
    assert report["tracks"] == baseline["tracks"]
    assert [f["source"] for f in report["files"]] == [
        "many.zip:part-00000.csv..part-00999.csv (1,000 members)",
        "many.zip:part-01000.csv",
        "many.zip:part-01001.csv..part-01999.csv (999 members)",
    ]


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
