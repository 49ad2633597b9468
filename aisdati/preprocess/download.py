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
therefore always complete, and is skipped unless `force`.
"""

from __future__ import annotations

import calendar
import os
import re
import time
import zipfile
from dataclasses import dataclass
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


def parse_numbers(text: str, lo: int, hi: int, option: str) -> list[int]:
    """'1-3,7' -> [1, 2, 3, 7], each within [lo, hi]."""
    numbers: set[int] = set()
    for part in text.replace(" ", "").split(","):
        match = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not match:
            raise UserError(f"{option} {text!r}: expected numbers and ranges such as 1-3,7")
        first, last = int(match[1]), int(match[2] or match[1])
        if not lo <= first <= last <= hi:
            raise UserError(f"{option} {text!r}: values must lie in {lo}..{hi}, ranges ascending")
        numbers.update(range(first, last + 1))
    return sorted(numbers)


def marinecadastre_files(
    year: int, months: str = "1-12", days: str | None = None, zone: int | None = None
) -> list[RemoteFile]:
    """The files of a year in that year's layout. Options that do not fit the layout (a zone for
    a daily national year, days for a monthly zone year, a year before 2015) are errors."""
    if year < FIRST_CSV_YEAR:
        raise UserError(
            f"--year {year}: MarineCadastre publishes 2009-2014 as File Geodatabases, which "
            "aisdati does not read; use 2015 or later"
        )
    month_list = parse_numbers(months, 1, 12, "--months")
    if year < FIRST_DAILY_YEAR:
        if zone is None:
            raise UserError(
                f"--year {year}: files of 2015-2017 are monthly per UTM zone; add --zone "
                "(e.g. --zone 17 for Florida)"
            )
        if days is not None:
            raise UserError(f"--year {year}: files of 2015-2017 are monthly; --days does not apply")
        if not 1 <= zone <= 60:
            raise UserError(f"--zone {zone}: UTM zones are numbered 1..60")
        return [RemoteFile(year, f"AIS_{year}_{m:02d}_Zone{zone:02d}.zip") for m in month_list]
    if zone is not None:
        raise UserError(
            f"--year {year}: files from 2018 on are national daily files, not per zone; drop "
            "--zone and choose the area with --roi"
        )
    day_list = parse_numbers(days, 1, 31, "--days") if days else list(range(1, 32))
    files = []
    for m in month_list:
        last_day = calendar.monthrange(year, m)[1]
        for d in day_list:
            if d <= last_day:
                name = (
                    f"ais-{year}-{m:02d}-{d:02d}.csv.zst"
                    if year >= FIRST_ZST_YEAR
                    else f"AIS_{year}_{m:02d}_{d:02d}.zip"
                )
                files.append(RemoteFile(year, name))
    if not files:
        raise UserError(f"--months {months} --days {days}: no such date in {year}")
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
    force: bool = False,
    settings: DownloadSettings | None = None,
    progress: Progress | None = None,
    session: requests.Session | None = None,
) -> bool:
    """Make `dest` a complete copy of `url`. Returns False when it was already there (skipped).
    Resumes `<dest>.part` left by an earlier attempt or run."""
    settings = settings or DownloadSettings()
    if dest.exists() and not force:
        return False
    dest.parent.mkdir(parents=True, exist_ok=True)
    part = dest.with_name(dest.name + ".part")
    if force:
        part.unlink(missing_ok=True)
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
    force: bool = False,
    settings: DownloadSettings | None = None,
    progress: Progress | None = None,
) -> list[Path]:
    """Fetch `files` into `data_dir/<year>/`, skipping those already complete."""
    base = base_url or os.environ.get(BASE_URL_ENV) or BASE_URL
    session = requests.Session()
    paths = []
    for remote in files:
        dest = data_dir / str(remote.year) / remote.name
        fetch(remote.url(base), dest, force, settings, progress, session)
        paths.append(dest)
    return paths
