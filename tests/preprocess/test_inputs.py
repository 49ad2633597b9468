"""Finding the inputs (`aisdati.preprocess.inputs`): zip members in every method, those
zipfile cannot read one line, and thousands of small members read as the one file (issue 27,
items 9 and 19)."""

from __future__ import annotations

import struct
import zipfile
from pathlib import Path

import pytest

from tests.helpers.cli import one_line_error
from tests.helpers.ingest import NY_HOUR, NY_ROWS, ingest, ingest_ny_hour, ny_lines, ny_table


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """The clean NY hour, ingested once: what every hostile copy is compared with."""
    return ingest_ny_hour(tmp_path_factory.mktemp("baseline"))


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
