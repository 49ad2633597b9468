"""Finding the inputs: which files `--input` names, what kind each is, and the tables inside them.

Three kinds of file: CSV (`.csv`, `.csv.gz`, `.csv.zst`, or the CSV members of a `.zip`), parquet
(`.parquet`) and NMEA 0183 logs (`.nmea`, `.ais`, `.txt`, each also `.gz` or `.zst`). A `.txt`
file counts as NMEA only when an AIS sentence is near its start, so a folder's README.txt is no
input.

A zip archive is opened once and its members read through that one handle (reopening it per
member costs a read of its whole directory: quadratic in the number of members), and runs of
small members with the same header line are read together as one table of about a CSV block
(per table, reading and conversion cost about a millisecond whatever its size: thousands of
small members would cost more than their rows). Members stored with a method Python cannot read
(Deflate64, PPMd, ...) or encrypted fail the run in one line before any work.
"""

from __future__ import annotations

import codecs
import glob
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Literal

from aisdati.errors import UserError
from aisdati.preprocess.streams import (
    READ_ERRORS,
    ByteStream,
    CountingReader,
    ForwardOnly,
    bom_encoding,
    counted_stream,
)
from aisdati.preprocess.zipmember import InflatedMember, open_member

Kind = Literal["csv", "parquet", "nmea"]
COMPRESSED = {".gz": "gzip", ".zst": "zstd"}
"""File name endings of compressed streams -> pyarrow's codec names."""
NMEA_SUFFIXES = tuple(f"{s}{c}" for s in (".nmea", ".ais", ".txt") for c in ("", *COMPRESSED))
SUFFIXES = (".zip", ".csv", ".csv.gz", ".csv.zst", ".parquet", *NMEA_SUFFIXES)
SNIFF_BYTES = 64 << 10
"""How far into a `.txt` file an AIS sentence must appear for it to count as NMEA."""
AIS_SENTENCE = re.compile(rb"![A-Z]{2}VD[MO],")
ZIP_METHODS = {
    zipfile.ZIP_STORED: None,
    zipfile.ZIP_DEFLATED: None,
    zipfile.ZIP_BZIP2: None,
    zipfile.ZIP_LZMA: None,
    1: "Shrink",
    2: "Reduce",
    3: "Reduce",
    4: "Reduce",
    5: "Reduce",
    6: "Implode",
    9: "Deflate64",
    10: "PKWARE DCL Implode",
    18: "IBM TERSE",
    19: "IBM LZ77",
    93: "Zstandard",
    95: "XZ",
    96: "JPEG",
    97: "WavPack",
    98: "PPMd",
}
"""Zip compression methods -> None for those `zipfile` reads, else the method's name (PKWARE's
APPNOTE 4.4.5); method 99 is WinZip's AES encryption."""
AES_METHOD = 99
SMALL_MEMBER_BYTES = 1 << 20
"""Zip members up to this size (uncompressed) are read in groups (`Source.also`)."""
GROUP_BYTES = 16 << 20
"""Uncompressed bytes of one group of small members (a few CSV blocks): enough that per-table
costs vanish, little enough that a group's label still says where its rows came from."""


class Archive:
    """One zip archive, opened on first use and shared by its members' sources."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._zip: zipfile.ZipFile | None = None

    @property
    def zip(self) -> zipfile.ZipFile:
        if self._zip is None:
            self._zip = zipfile.ZipFile(self.path)
        return self._zip

    def __getstate__(self) -> dict[str, object]:
        """Pickled (for a task in another process, perhaps in another working folder) without
        its open file, which is opened there anew, by its absolute path."""
        return {"path": self.path.absolute(), "_zip": None}


@dataclass(frozen=True)
class Source:
    """One table to read: a plain or compressed file, or one CSV member of a zip archive."""

    path: Path
    member: str | None = None
    archive: Archive | None = field(default=None, compare=False, repr=False)
    """The open archive of a zip member (without it, each use opens the file anew)."""
    also: tuple[str, ...] = ()
    """Small zip members read after `member`, their header lines (the same as its) dropped."""

    @property
    def label(self) -> str:
        if self.also:
            count = len(self.also) + 1
            return f"{self.path.name}:{self.member}..{self.also[-1]} ({count:,} members)"
        return f"{self.path.name}:{self.member}" if self.member else self.path.name

    @property
    def kind(self) -> Kind:
        return "csv" if self.member is not None else file_kind(self.path)

    @property
    def compression(self) -> str | None:
        return COMPRESSED.get(self.path.suffix.lower()) if self.member is None else None

    def size(self) -> int:
        """Bytes the progress bar counts: uncompressed for zip members, on disk otherwise."""
        if self.member is None:
            return self.path.stat().st_size
        zf = self._zip()
        return sum(zf.getinfo(name).file_size for name in (self.member, *self.also))

    def estimated_rows(self) -> int:
        """A rough row count (about 100 bytes of CSV per row) used to size vessel partitions."""
        expand = {"gzip": 5, "zstd": 8}.get(self.compression or "", 1)
        return self.size() * (4 if self.kind == "parquet" else expand) // 100

    def open(self) -> tuple[ByteStream, CountingReader]:
        """A fresh (decompressed) byte stream of the source, and the counter of its bytes read
        from disk (or from the zip member)."""
        if self.also:
            raw: BinaryIO | MemberChain | InflatedMember = MemberChain(
                self._zip(), (self.member, *self.also)
            )
        elif self.member is not None:
            raw = open_member(self._zip(), self.member)
        else:
            raw = open(self.path, "rb")  # noqa: SIM115 - closed with the stream
        return counted_stream(raw, self.compression)

    def _zip(self) -> zipfile.ZipFile:
        return self.archive.zip if self.archive else zipfile.ZipFile(self.path)


def file_kind(path: Path) -> Kind:
    """The kind of a supported (non-zip) file, from its name."""
    name = path.name.lower()
    if name.endswith(".parquet"):
        return "parquet"
    return "nmea" if name.endswith(NMEA_SUFFIXES) else "csv"


def looks_like_nmea(source: Source) -> bool:
    """Whether an AIS sentence (`!AIVDM,`, `!AIVDO,`, any talker) lies in the first
    `SNIFF_BYTES` of the (decompressed) source."""
    stream, _ = source.open()
    try:
        return AIS_SENTENCE.search(stream.read(SNIFF_BYTES)) is not None
    finally:
        stream.close()


def is_supported(path: Path) -> bool:
    """Whether `path` is an input file: a supported name, and for `.txt` NMEA content (a file
    that cannot be read is kept, so that its error is reported when it is read)."""
    name = path.name.lower()
    if not name.endswith(SUFFIXES):
        return False
    if not name.endswith(tuple(f".txt{c}" for c in ("", *COMPRESSED))):
        return True
    try:
        return looks_like_nmea(Source(path))
    except READ_ERRORS:
        return True


def expand_inputs(specs: list[str | Path]) -> list[Path]:
    """Files named by `--input`: paths, globs and directories (searched recursively)."""
    files: list[Path] = []
    for spec in specs:
        path = Path(spec)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and is_supported(p))
        elif path.is_file():
            found = [path]
        else:
            found = sorted(Path(p) for p in glob.glob(str(spec), recursive=True))
            found = [p for p in found if p.is_file() and is_supported(p)]
        if not found:
            raise UserError(f"--input {spec}: no {', '.join(SUFFIXES)} file found there")
        for p in found:
            if not is_supported(p):
                raise UserError(
                    f"{p}: unsupported file type (expected {', '.join(SUFFIXES)}; a .txt file "
                    "is read as NMEA and must hold AIS sentences)"
                )
        files.extend(found)
    return list(dict.fromkeys(files))


def sources_of(path: Path) -> list[Source]:
    """The tables inside one input file (a zip archive may hold several CSV members)."""
    if path.stat().st_size == 0:
        raise UserError(f"{path}: the file is empty")
    if not path.name.lower().endswith(".zip"):
        return [Source(path)]
    archive = Archive(path)
    return group_small_members(archive, archive_members(path, archive, (".csv",)))


def archive_members(
    path: Path, archive: Archive, suffixes: tuple[str, ...]
) -> list[zipfile.ZipInfo]:
    """The members of a zip archive whose names end with `suffixes`, in the archive's order,
    each checked (`check_member`); an unreadable archive, or one with none, is one line."""
    try:
        members = [i for i in archive.zip.infolist() if i.filename.lower().endswith(suffixes)]
    except (zipfile.BadZipFile, OSError) as exc:
        raise UserError(f"{path}: not a readable zip archive ({exc})") from None
    if not members:
        raise UserError(f"{path}: the zip archive holds no {', '.join(suffixes)} file")
    for info in members:
        check_member(path, info)
    return members


def group_small_members(archive: Archive, members: list[zipfile.ZipInfo]) -> list[Source]:
    """One source per member, except that consecutive small members with the same header line
    make one source (up to `GROUP_BYTES`)."""
    sources: list[Source] = []
    group: list[str] = []
    group_header, group_bytes = b"", 0
    for info in members:
        header = member_header(archive.zip, info) if info.file_size <= SMALL_MEMBER_BYTES else None
        if group and (
            header != group_header or group_bytes + info.file_size > GROUP_BYTES or header is None
        ):
            sources.append(Source(archive.path, group[0], archive, tuple(group[1:])))
            group, group_bytes = [], 0
        if header is None:
            sources.append(Source(archive.path, info.filename, archive))
            continue
        group.append(info.filename)
        group_header, group_bytes = header, group_bytes + info.file_size
    if group:
        sources.append(Source(archive.path, group[0], archive, tuple(group[1:])))
    return sources


def member_header(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> bytes | None:
    """The first line of a small member that is not blank (without a UTF-8 byte-order mark), or
    None when it has none or is no plain UTF-8 text (then it is read on its own, and its own
    checks say what is wrong)."""
    try:
        with zf.open(info) as f:
            head = f.read(SNIFF_BYTES)
    except READ_ERRORS:
        return None
    if bom_encoding(head):
        return None
    header, rest = split_header(head.removeprefix(codecs.BOM_UTF8))
    return header if header and (rest or len(head) == info.file_size) else None


def split_header(data: bytes) -> tuple[bytes, bytes]:
    """(the first line that is not blank, what follows its line end) of CSV bytes."""
    pos = 0
    while pos < len(data):
        ends = [i for i in (data.find(b"\n", pos), data.find(b"\r", pos)) if i >= 0]
        end = min(ends) if ends else len(data)
        line, pos = data[pos:end], end + 1
        if data[end : end + 2] == b"\r\n":
            pos += 1
        if line.strip():
            return line, data[pos:]
    return b"", b""


class MemberChain(ForwardOnly):
    """Zip members read one after another as one CSV: the first whole, the others without their
    header line (and blank lines before it), each ended by a line end."""

    def __init__(self, zf: zipfile.ZipFile, names: tuple[str, ...]) -> None:
        self.zf = zf
        self.names = iter(names)
        self.first = True
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        """Whole members, at least `n` bytes of them unless the last comes first; empty at the
        end."""
        pieces, size = [], 0
        for name in self.names:
            data = self.zf.read(name)
            if not self.first:
                data = split_header(data)[1]
            self.first = False
            if data and data[-1:] not in (b"\n", b"\r"):
                data += b"\n"
            pieces.append(data)
            size += len(data)
            if n is not None and 0 <= n <= size:
                break
        return b"".join(pieces)

    def close(self) -> None:
        self.closed = True


def check_member(path: Path, info: zipfile.ZipInfo) -> None:
    """A one-line error for a zip member that `zipfile` cannot read: encrypted, or compressed
    with a method it does not know."""
    label = f"{path.name}:{info.filename}"
    if info.flag_bits & 0x1 or info.compress_type == AES_METHOD:
        raise UserError(f"{label}: the member is encrypted: unzip it (with its password) first")
    method = ZIP_METHODS.get(info.compress_type, f"number {info.compress_type}")
    if method is not None:
        raise UserError(f"{label}: compression method {method} not supported: unzip it first")


def describe_read_error(source: Source, exc: BaseException) -> UserError:
    """One line for a file that broke while being read (bad CRC, truncated stream, ...)."""
    message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return UserError(f"{source.label}: corrupt or truncated input ({message})")
