"""Downloading against a real HTTP server on 127.0.0.1: names per layout, resume after a dropped
connection (HTTP Range), corrupt archives refused, nothing partial under a final name."""

from __future__ import annotations

import io
import re
import threading
import zipfile
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import ClassVar

import pytest
import zstandard

from aisdati.errors import UserError
from aisdati.preprocess.download import (
    DownloadSettings,
    RemoteFile,
    download,
    fetch,
    marinecadastre_files,
    utm_zones,
)

FAST = DownloadSettings(retries=3, backoff_s=0.01, timeout_s=5, chunk_bytes=4096)


class AisServer(BaseHTTPRequestHandler):
    """Serves `files` (path -> bytes) with Range support; the first `drop_first` responses are
    cut after `drop_at` bytes by closing the connection."""

    files: ClassVar[dict[str, bytes]] = {}
    drop_first = 0
    drop_at = 0
    requests: ClassVar[list[tuple[str, str | None]]] = []

    def do_GET(self):
        cls = type(self)
        rng = self.headers.get("Range")
        cls.requests.append((self.path, rng))
        body = cls.files.get(self.path)
        if body is None:
            self.send_error(404)
            return
        start = int(re.fullmatch(r"bytes=(\d+)-", rng)[1]) if rng else 0
        if start >= len(body):
            self.send_response(416)
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        self.send_response(206 if rng else 200)
        if rng:
            self.send_header("Content-Range", f"bytes {start}-{len(body) - 1}/{len(body)}")
        self.send_header("Content-Length", str(len(body) - start))
        self.end_headers()
        payload = body[start:]
        if cls.drop_first > 0:
            cls.drop_first -= 1
            self.wfile.write(payload[: cls.drop_at])
            self.wfile.flush()
            self.close_connection = True
            return
        self.wfile.write(payload)

    def log_message(self, *args):
        pass


@pytest.fixture
def server():
    handler = type("Handler", (AisServer,), {"files": {}, "requests": [], "drop_first": 0})
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield handler, f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture
def fixture_zip(data) -> bytes:
    """A real daily zip, cut to 20,000 rows (about 0.7 MB): big enough to drop mid-file."""
    with zipfile.ZipFile(data / "AIS_2022_01_03_head.zip") as zf:
        lines = zf.read("AIS_2022_01_03.csv").splitlines(keepends=True)[:20_001]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("AIS_2022_01_03.csv", b"".join(lines))
    return buf.getvalue()


def test_file_names_follow_each_years_layout():
    assert marinecadastre_files("2015-01..2015-02", zones=[17]) == [
        RemoteFile(2015, "AIS_2015_01_Zone17.zip"),
        RemoteFile(2015, "AIS_2015_02_Zone17.zip"),
    ]
    assert [f.name for f in marinecadastre_files("2016-03", zones=[17, 18])] == [
        "AIS_2016_03_Zone17.zip",
        "AIS_2016_03_Zone18.zip",
    ]
    assert [f.name for f in marinecadastre_files("2022-02-27..2022-03-01")] == [
        "AIS_2022_02_27.zip",
        "AIS_2022_02_28.zip",
        "AIS_2022_03_01.zip",
    ]
    assert len(marinecadastre_files("2020-02")) == 29
    assert len(marinecadastre_files("2019")) == 365
    assert marinecadastre_files("2025-01-01")[0].name == "ais-2025-01-01.csv.zst"
    assert utm_zones(-83.5, -79.0) == [17]  # the paper's Florida Straits
    assert utm_zones(-125.0, -119.0) == [10, 11]
    assert (
        RemoteFile(2015, "AIS_2015_01_Zone17.zip").url(
            "https://coast.noaa.gov/htdata/CMSP/AISDataHandler/"
        )
        == "https://coast.noaa.gov/htdata/CMSP/AISDataHandler/2015/AIS_2015_01_Zone17.zip"
    )


@pytest.mark.parametrize(
    "spec, message",
    [
        ("2014", "File Geodatabases"),
        ("2015-03", "per UTM zone, chosen by --roi"),
        ("2016-03-01", "files of 2015-2017 are monthly"),
        ("2022-13", "is no date"),
        ("2022-02-30", "is no date"),
        ("July 2022", "expected YYYY"),
        ("2022-03..2022-02", "ends before it starts"),
        ("2022-03..2022-03-05", "both ends of a range are days, or both months"),
    ],
)
def test_a_wrong_period_is_a_user_error(spec, message):
    with pytest.raises(UserError, match=message):
        marinecadastre_files(spec)


def test_interrupted_download_resumes_with_range(server, fixture_zip, tmp_path):
    handler, base = server
    handler.files["/2022/AIS_2022_01_03.zip"] = fixture_zip
    handler.drop_first, handler.drop_at = 2, len(fixture_zip) // 3
    (path,) = download([RemoteFile(2022, "AIS_2022_01_03.zip")], tmp_path, base, settings=FAST)
    assert path.read_bytes() == fixture_zip
    ranges = [r for _, r in handler.requests]
    assert ranges[0] is None and len(ranges) == 3
    resumed_at = [int(re.fullmatch(r"bytes=(\d+)-", r)[1]) for r in ranges[1:]]
    assert 0 < resumed_at[0] < resumed_at[1] < len(fixture_zip)
    assert not list(tmp_path.rglob("*.part"))


def test_download_that_keeps_failing_leaves_only_a_part_file_and_resumes_later(
    server, fixture_zip, tmp_path
):
    handler, base = server
    handler.files["/2022/AIS_2022_01_03.zip"] = fixture_zip
    handler.drop_first, handler.drop_at = 100, 50_000
    dest = tmp_path / "AIS_2022_01_03.zip"
    with pytest.raises(UserError, match="run again to resume"):
        fetch(f"{base}/2022/AIS_2022_01_03.zip", dest, settings=FAST)
    assert not dest.exists()
    part = tmp_path / "AIS_2022_01_03.zip.part"
    assert 0 < part.stat().st_size < len(fixture_zip)
    handler.drop_first = 0
    handler.requests.clear()
    have = part.stat().st_size
    assert fetch(f"{base}/2022/AIS_2022_01_03.zip", dest, settings=FAST)
    assert dest.read_bytes() == fixture_zip
    assert handler.requests == [("/2022/AIS_2022_01_03.zip", f"bytes={have}-")]
    assert not part.exists()


def test_corrupt_zip_is_refused(server, fixture_zip, tmp_path):
    handler, base = server
    corrupt = bytearray(fixture_zip)
    corrupt[len(corrupt) // 2] ^= 0xFF
    handler.files["/2022/AIS_2022_01_03.zip"] = bytes(corrupt)
    dest = tmp_path / "AIS_2022_01_03.zip"
    with pytest.raises(UserError, match="corrupt archive"):
        fetch(f"{base}/2022/AIS_2022_01_03.zip", dest, settings=FAST)
    assert not dest.exists() and not list(tmp_path.iterdir())


def test_truncated_zst_is_refused_and_a_whole_one_accepted(server, tmp_path):
    handler, base = server
    whole = zstandard.ZstdCompressor().compress(
        b"mmsi,base_date_time\n" + b"1,2025-01-01 00:00:00\n" * 5000
    )
    handler.files["/2025/ais-2025-01-01.csv.zst"] = whole[: len(whole) // 2]
    handler.files["/2025/ais-2025-01-02.csv.zst"] = whole
    with pytest.raises(UserError, match="truncated zstd"):
        fetch(f"{base}/2025/ais-2025-01-01.csv.zst", tmp_path / "a.csv.zst", settings=FAST)
    assert fetch(f"{base}/2025/ais-2025-01-02.csv.zst", tmp_path / "b.csv.zst", settings=FAST)


def test_complete_files_are_skipped(server, fixture_zip, tmp_path):
    handler, base = server
    handler.files["/2022/AIS_2022_01_03.zip"] = fixture_zip
    dest = tmp_path / "AIS_2022_01_03.zip"
    assert fetch(f"{base}/2022/AIS_2022_01_03.zip", dest, settings=FAST)
    n = len(handler.requests)
    assert not fetch(f"{base}/2022/AIS_2022_01_03.zip", dest, settings=FAST)
    assert len(handler.requests) == n


def test_missing_remote_file_is_a_user_error(server, tmp_path):
    _, base = server
    with pytest.raises(UserError, match="HTTP 404"):
        fetch(f"{base}/2022/AIS_2022_01_04.zip", tmp_path / "x.zip", settings=FAST)


def test_cli_downloads_then_ingests(server, fixture_zip, tmp_path, cli, monkeypatch):
    handler, base = server
    handler.files["/2022/AIS_2022_01_03.zip"] = fixture_zip
    handler.drop_first, handler.drop_at = 1, 100_000
    args = ["ingest", "--download", "2022-01-03", "--data-dir", tmp_path / "raw"]
    args += ["--out", tmp_path / "out", "--roi", "none"]
    monkeypatch.setenv("AISDATI_BASE_URL", base)
    result = cli(*args, "--min-points", "5")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "raw" / "2022" / "AIS_2022_01_03.zip").read_bytes() == fixture_zip
    assert (tmp_path / "out" / "tracks.parquet").exists()
