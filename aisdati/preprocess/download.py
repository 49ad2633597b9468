"""Download MarineCadastre AIS files: names for every layout, resumable transfers, verified
archives.

MarineCadastre (NOAA/BOEM) serves the US Coast Guard's national AIS under
`https://coast.noaa.gov/htdata/CMSP/AISDataHandler/<year>/`:

* 2015-2017: monthly files per UTM zone, `AIS_<y>_<mm>_Zone<zz>.zip` (one CSV inside);
* 2018-2024: daily national files, `AIS_<y>_<mm>_<dd>.zip` (one CSV inside);
* 2025 on: daily national files, `ais-<y>-<mm>-<dd>.csv.zst` (snake_case columns);
* 2009-2014 are File Geodatabases, which aisdati does not read.

HTTP goes through `requests` (connection reuse, chunked transfer decoding, proxy and certificate
settings from the environment). What no library does for us is resuming a file that is half
on disk, so the retry loop is ours: each attempt asks for the missing bytes with an HTTP Range
header, waits longer after each failure (exponential back-off), and only a file whose archive
checks out (every zip CRC via `zipfile.testzip`, every zstd frame decoded to its end by
`zstandard`) is renamed from `<name>.part` to its final name. A file under its final name is
therefore always complete, and is skipped (delete it to fetch it again).
"""

from __future__ import annotations

import calendar
import os
import re
import time
import zipfile
from dataclasses import dataclass
from datetime import date, timedelta
from pathlib import Path

import requests
import zstandard
from rich.progress import Progress

from aisdati.errors import UserError

BASE_URL = "https://coast.noaa.gov/htdata/CMSP/AISDataHandler"
BASE_URL_ENV = "AISDATI_BASE_URL"
"""Environment variable overriding `BASE_URL` (a mirror, or a local server in the tests)."""
FIRST_CSV_YEAR = 2015
FIRST_DAILY_YEAR = 2018
FIRST_ZST_YEAR = 2025


@dataclass(frozen=True)
class RemoteFile:
    """One MarineCadastre file: its year folder and name."""

    year: int
    name: str

    def url(self, base_url: str) -> str:
        return f"{base_url.rstrip('/')}/{self.year}/{self.name}"


@dataclass(frozen=True)
class DownloadSettings:
    """Retry policy: `retries` further attempts after the first, waiting backoff_s * 2**k."""

    retries: int = 5
    backoff_s: float = 2.0
    timeout_s: float = 60.0
    chunk_bytes: int = 1 << 20


DOWNLOAD_HELP = (
    "YYYY, YYYY-MM or YYYY-MM-DD, or a range A..B of the same form (2018-07-01..2018-07-07)"
)


def parse_period(spec: str) -> tuple[list[date], bool]:
    """`--download`'s period: the days it spans and whether it was given by month (a year or
    months: True; days: False). One-line `UserError` on anything else."""
    first, sep, last = spec.strip().partition("..")
    start, by_month = _period_end(first, spec, start=True)
    end, last_by_month = _period_end(last if sep else first, spec, start=False)
    if sep and by_month != last_by_month:
        raise UserError(f"--download {spec!r}: both ends of a range are days, or both months")
    if end < start:
        raise UserError(f"--download {spec!r}: the range ends before it starts")
    return [start + timedelta(days=k) for k in range((end - start).days + 1)], by_month


def _period_end(text: str, spec: str, start: bool) -> tuple[date, bool]:
    """The first (or last) day of `YYYY`, `YYYY-MM` or `YYYY-MM-DD`, and whether it named a
    month or a year."""
    match = re.fullmatch(r"(\d{4})(?:-(\d{1,2})(?:-(\d{1,2}))?)?", text.strip())
    if not match:
        raise UserError(f"--download {spec!r}: expected {DOWNLOAD_HELP}")
    year, month, day = int(match[1]), match[2], match[3]
    try:
        if day is not None:
            return date(year, int(month), int(day)), False
        if month is not None:
            m = int(month)
            return date(year, m, 1 if start else calendar.monthrange(year, m)[1]), True
        return date(year, 1, 1) if start else date(year, 12, 31), True
    except ValueError:
        raise UserError(f"--download {spec!r}: {text!r} is no date") from None


def utm_zones(lon_min: float, lon_max: float) -> list[int]:
    """The UTM zones (1..60) a longitude span crosses: what the 2015-2017 files are cut by."""
    zone = lambda lon: min(60, max(1, int((lon + 180.0) // 6.0) + 1))  # noqa: E731
    return list(range(zone(lon_min), zone(lon_max) + 1))


def marinecadastre_files(spec: str, zones: list[int] | None = None) -> list[RemoteFile]:
    """The files of a period (`parse_period`) in each year's layout: for 2015-2017 one monthly
    file per month and UTM zone (`zones`, from the region of interest), from 2018 on one
    national file per day. A period that does not fit its years' layout is one line."""
    days, by_month = parse_period(spec)
    if days[0].year < FIRST_CSV_YEAR:
        raise UserError(
            f"--download {spec}: MarineCadastre publishes 2009-2014 as File Geodatabases, which "
            "aisdati does not read; use 2015 or later"
        )
    files: list[RemoteFile] = []
    for d in days:
        if d.year < FIRST_DAILY_YEAR:
            if not by_month:
                raise UserError(
                    f"--download {spec}: files of 2015-2017 are monthly; give months (2016-03)"
                )
            if not zones:
                raise UserError(
                    f"--download {spec}: files of 2015-2017 are per UTM zone, chosen by --roi: "
                    "give a region of interest, not --roi none"
                )
            if d.day == 1:
                files += [
                    RemoteFile(d.year, f"AIS_{d.year}_{d.month:02d}_Zone{z:02d}.zip")
                    for z in zones
                ]
        elif d.year >= FIRST_ZST_YEAR:
            files.append(RemoteFile(d.year, f"ais-{d.year}-{d.month:02d}-{d.day:02d}.csv.zst"))
        else:
            files.append(RemoteFile(d.year, f"AIS_{d.year}_{d.month:02d}_{d.day:02d}.zip"))
    return files

class CorruptArchive(Exception):
    """A downloaded file whose archive does not check out."""


def verify_archive(path: Path, name: str) -> None:
    """Raise `CorruptArchive` unless `path` (to be called `name`) is a complete, intact archive:
    every member's CRC for a zip, every zstd frame decoded to its end for .zst."""
    if name.endswith(".zip"):
        try:
            with zipfile.ZipFile(path) as zf:
                bad = zf.testzip()
        except (zipfile.BadZipFile, EOFError, OSError) as exc:
            raise CorruptArchive(f"not a complete zip archive ({exc})") from None
        if bad is not None:
            raise CorruptArchive(f"bad CRC in member {bad}")
    elif name.endswith(".zst"):
        _verify_zstd(path)


def _verify_zstd(path: Path) -> None:
    dctx = zstandard.ZstdDecompressor()
    dobj, in_frame, frames = dctx.decompressobj(), False, 0
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                while chunk:
                    dobj.decompress(chunk)
                    in_frame = True
                    if dobj.eof:  # a frame ended: the rest belongs to the next one
                        chunk, frames = dobj.unused_data, frames + 1
                        dobj, in_frame = dctx.decompressobj(), False
                    else:
                        chunk = b""
    except zstandard.ZstdError as exc:
        raise CorruptArchive(f"bad zstd data ({exc})") from None
    if in_frame or frames == 0:
        raise CorruptArchive("truncated zstd stream (the last frame does not end)")


class _Retryable(Exception):
    """A transfer that failed in a way worth another attempt."""


def fetch(
    url: str,
    dest: Path,
    settings: DownloadSettings | None = None,
    progress: Progress | None = None,
    session: requests.Session | None = None,
) -> bool:
    """Make `dest` a complete copy of `url`. Returns False when it was already there (skipped).
    Resumes `<dest>.part` left by an earlier attempt or run."""
    settings = settings or DownloadSettings()
    if dest.exists():
        return False
    dest.parent.mkdir(parents=True, exist_ok=True)
    part = dest.with_name(dest.name + ".part")
    session = session or requests.Session()
    task = progress.add_task(f"download {dest.name}", total=None) if progress else None
    last_error = ""
    for attempt in range(settings.retries + 1):
        if attempt:
            time.sleep(settings.backoff_s * 2 ** (attempt - 1))
        try:
            _transfer(url, part, session, settings, progress, task)
            verify_archive(part, dest.name)
        except CorruptArchive as exc:
            part.unlink(missing_ok=True)  # start again from nothing
            last_error = f"corrupt archive: {exc}"
            continue
        except _Retryable as exc:
            last_error = str(exc)
            continue
        os.replace(part, dest)
        return True
    raise UserError(
        f"{url}: download failed after {settings.retries + 1} attempts ({last_error}); "
        f"run again to resume from {part.name}"
    )


def _transfer(
    url: str,
    part: Path,
    session: requests.Session,
    settings: DownloadSettings,
    progress: Progress | None,
    task,
) -> None:
    """One attempt: append the bytes `part` lacks (or restart when the server ignores Range)."""
    have = part.stat().st_size if part.exists() else 0
    headers = {"Range": f"bytes={have}-"} if have else {}
    try:
        with session.get(url, headers=headers, stream=True, timeout=settings.timeout_s) as r:
            if r.status_code == 416:
                return  # nothing left to fetch: the part is whole (verification will tell)
            if r.status_code in (403, 404, 410):
                raise UserError(f"{url}: not on the server (HTTP {r.status_code})")
            if r.status_code >= 400:
                raise _Retryable(f"HTTP {r.status_code}")
            if r.status_code != 206:
                have = 0  # the server sent the whole file
            length = r.headers.get("Content-Length")
            total = have + int(length) if length is not None else None
            if task is not None:
                progress.update(task, total=total, completed=have)
            with open(part, "ab" if have else "wb") as f:
                for chunk in r.iter_content(settings.chunk_bytes):
                    f.write(chunk)
                    if task is not None:
                        progress.advance(task, len(chunk))
    except requests.RequestException as exc:
        raise _Retryable(f"{type(exc).__name__}: {exc}") from None
    if total is not None and part.stat().st_size < total:
        raise _Retryable(f"connection closed after {part.stat().st_size} of {total} bytes")


def download(
    files: list[RemoteFile],
    data_dir: Path,
    base_url: str | None = None,
    settings: DownloadSettings | None = None,
    progress: Progress | None = None,
) -> list[Path]:
    """Fetch `files` into `data_dir/<year>/`, skipping those already complete."""
    base = base_url or os.environ.get(BASE_URL_ENV) or BASE_URL
    session = requests.Session()
    paths = []
    for remote in files:
        dest = data_dir / str(remote.year) / remote.name
        fetch(remote.url(base), dest, settings, progress, session)
        paths.append(dest)
    return paths
