"""Reading AIS files of any MarineCadastre layout as a stream of pyarrow record batches.

Inputs are local paths, globs or directories holding `.zip` (CSV members), `.csv`, `.csv.gz`,
`.csv.zst` or `.parquet` files. Columns are matched by name, ignoring case, underscores and
spaces, with the spellings seen in the wild (`BaseDateTime`, `base_date_time`, `latitude`...);
their order does not matter and extra columns are ignored. Only the six columns the pipeline
needs are converted, as strings first, so one bad value costs one counted row, not the file.
"""

from __future__ import annotations

import codecs
import csv
import glob
import math
import re
import zipfile
import zlib
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numba
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import zstandard

from aisdati.errors import UserError
from aisdati.preprocess.report import CODE

SUFFIXES = (".zip", ".csv", ".csv.gz", ".csv.zst", ".parquet")
BLOCK_SIZE = 16 << 20
"""Bytes of CSV per record batch: large enough for pyarrow's threads, small enough for memory."""

ALIASES: dict[str, tuple[str, ...]] = {
    "mmsi": ("mmsi",),
    "time": ("basedatetime", "basedatatime", "datetime", "timestamp", "time", "datetimeutc"),
    "lat": ("lat", "latitude", "lattitude"),
    "lon": ("lon", "long", "lng", "longitude", "longtitude"),
    "sog": ("sog", "speedoverground"),
    "cog": ("cog", "courseoverground"),
}
"""Canonical column -> normalised spellings (lower case, letters and digits only)."""
REQUIRED = ("mmsi", "time", "lat", "lon")
MAX_MMSI = 2**53
"""MMSIs are nine digits by the standard, but real files hold longer ones (e.g. 1072211352);
any positive integer that float64 holds exactly identifies a vessel."""
DERIVABLE = ("sog", "cog")


@dataclass(frozen=True)
class Source:
    """One table to read: a plain or compressed file, or one CSV member of a zip archive."""

    path: Path
    member: str | None = None

    @property
    def label(self) -> str:
        return f"{self.path.name}:{self.member}" if self.member else self.path.name

    @property
    def is_parquet(self) -> bool:
        return self.path.name.lower().endswith(".parquet")

    @property
    def compression(self) -> str | None:
        name = self.path.name.lower()
        return "gzip" if name.endswith(".gz") else "zstd" if name.endswith(".zst") else None

    def size(self) -> int:
        """Bytes the progress bar counts: uncompressed for zip members, on disk otherwise."""
        if self.member is None:
            return self.path.stat().st_size
        with zipfile.ZipFile(self.path) as zf:
            return zf.getinfo(self.member).file_size

    def estimated_rows(self) -> int:
        """A rough row count (about 100 bytes of CSV per row) used to size vessel partitions."""
        expand = {"gzip": 5, "zstd": 8}.get(self.compression or "", 1)
        return self.size() * (4 if self.is_parquet else expand) // 100


def _is_supported(path: Path) -> bool:
    return path.name.lower().endswith(SUFFIXES)


def expand_inputs(specs: list[str | Path]) -> list[Path]:
    """Files named by `--input`: paths, globs and directories (searched recursively)."""
    files: list[Path] = []
    for spec in specs:
        path = Path(spec)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*") if p.is_file() and _is_supported(p))
        elif path.is_file():
            found = [path]
        else:
            found = sorted(Path(p) for p in glob.glob(str(spec), recursive=True))
            found = [p for p in found if p.is_file() and _is_supported(p)]
        if not found:
            raise UserError(f"--input {spec}: no {', '.join(SUFFIXES)} file found there")
        for p in found:
            if not _is_supported(p):
                raise UserError(f"{p}: unsupported file type (expected {', '.join(SUFFIXES)})")
        files.extend(found)
    return list(dict.fromkeys(files))


def sources_of(path: Path) -> list[Source]:
    """The tables inside one input file (a zip archive may hold several CSV members)."""
    if path.stat().st_size == 0:
        raise UserError(f"{path}: the file is empty")
    if not path.name.lower().endswith(".zip"):
        return [Source(path)]
    try:
        with zipfile.ZipFile(path) as zf:
            members = [i.filename for i in zf.infolist() if i.filename.lower().endswith(".csv")]
    except (zipfile.BadZipFile, OSError) as exc:
        raise UserError(f"{path}: not a readable zip archive ({exc})") from None
    if not members:
        raise UserError(f"{path}: the zip archive holds no .csv file")
    return [Source(path, m) for m in members]


def _normalise(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def resolve_columns(names: list[str], label: str) -> dict[str, str]:
    """Canonical column -> the source's own column name. Raises a `UserError` naming a missing
    required column; SOG and COG may be absent (they are then derived from the positions)."""
    found: dict[str, str] = {}
    for name in names:
        key = _normalise(name)
        for canonical, spellings in ALIASES.items():
            if key in spellings:
                if canonical in found:
                    raise UserError(
                        f"{label}: columns {found[canonical][:40]!r} and {name[:40]!r} both look "
                        f"like {canonical.upper()}"
                    )
                found[canonical] = name
    missing = [c for c in REQUIRED if c not in found]
    if missing:
        wanted = ", ".join(f"{c.upper()} (e.g. {ALIASES[c][0]})" for c in missing)
        shown = repr([n if len(n) <= 40 else n[:37] + "..." for n in names[:30]])
        more = f" and {len(names) - 30} more" if len(names) > 30 else ""
        raise UserError(f"{label}: missing required column {wanted}; header is {shown}{more}")
    return found


class _ForwardOnly:
    """What pyarrow asks of a file-like object that can only be read forwards."""

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False


class _CountingReader(_ForwardOnly):
    """A read-only file wrapper that counts the bytes read, for the progress bars."""

    def __init__(self, raw: BinaryIO) -> None:
        self.raw = raw
        self.bytes_read = 0
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        data = self.raw.read(n)
        self.bytes_read += len(data)
        return data

    def close(self) -> None:
        self.closed = True
        self.raw.close()


class SourceReader:
    """Streams one source as record batches of its needed columns (as the source typed them:
    strings for CSV), counting malformed CSV rows instead of failing on them."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.malformed: list[str] = []
        self._counter: _CountingReader | None = None
        self._rows = 0
        self.names = self._header() if not source.is_parquet else self._parquet_names()
        self.columns = resolve_columns(self.names, source.label)

    @property
    def total(self) -> int:
        """Progress units of the whole source: bytes of CSV, rows of parquet."""
        if self.source.is_parquet:
            return pq.ParquetFile(self.source.path).metadata.num_rows
        return self.source.size()

    @property
    def done(self) -> int:
        """Progress units read so far."""
        return self._counter.bytes_read if self._counter else self._rows

    def _open_binary(self) -> _CountingReader | _Decompressed:
        """A fresh (decompressed) byte stream of the source."""
        if self.source.member is not None:
            zf = zipfile.ZipFile(self.source.path)
            raw: BinaryIO = zf.open(self.source.member)
        else:
            raw = open(self.source.path, "rb")  # noqa: SIM115 - closed by the reader
        counter = _CountingReader(raw)
        if self.source.compression:
            native = pa.PythonFile(counter, mode="r")
            stream = pa.CompressedInputStream(native, self.source.compression)
            return _Decompressed(stream, counter)
        return counter

    def _header(self) -> list[str]:
        """The column names on the first line (ended by LF, CRLF or a lone CR)."""
        try:
            stream = self._open_binary()
            try:
                chunk = stream.read(MAX_HEADER_BYTES)
            finally:
                stream.close()
        except READ_ERRORS as exc:
            raise describe_read_error(self.source, exc) from None
        ends = [i for i in (chunk.find(b"\n"), chunk.find(b"\r")) if i >= 0]
        if not ends and len(chunk) >= MAX_HEADER_BYTES:
            raise UserError(
                f"{self.source.label}: no line break in the first {MAX_HEADER_BYTES >> 20} MiB: "
                "not a CSV file with a header line"
            )
        first = chunk[: min(ends)] if ends else chunk
        if not first.strip():
            raise UserError(f"{self.source.label}: the file is empty (no header line)")
        text = first.decode("utf-8-sig", errors="replace")
        odd = sum(1 for c in text if c == "\ufffd" or (not c.isprintable() and c != "\t"))
        if odd > len(text) // 10:
            raise UserError(f"{self.source.label}: the first line is not CSV text (a binary file?)")
        limit = csv.field_size_limit(MAX_HEADER_BYTES)  # a name may be as long as the line
        try:
            names = next(csv.reader([text]))
        except csv.Error as exc:
            raise UserError(f"{self.source.label}: unreadable header line ({exc})") from None
        finally:
            csv.field_size_limit(limit)
        return [n.strip() for n in names]

    def _parquet_names(self) -> list[str]:
        try:
            schema = pq.ParquetFile(self.source.path).schema_arrow
        except (pa.ArrowException, OSError) as exc:
            raise UserError(f"{self.source.label}: not a readable parquet file ({exc})") from None
        for name, kind in zip(schema.names, schema.types, strict=True):
            if _normalise(name) in ALIASES["time"] and not _time_like(kind):
                raise UserError(
                    f"{self.source.label}: column {name!r} holds {kind} values; expected times "
                    "(a timestamp, text, or numbers of seconds since 1970)"
                )
        return schema.names

    def batches(self) -> Iterator[pa.RecordBatch]:
        """Record batches holding the resolved columns, under the source's own names."""
        wanted = list(self.columns.values())
        if self.source.is_parquet:
            for batch in pq.ParquetFile(self.source.path).iter_batches(
                batch_size=1 << 18, columns=wanted
            ):
                self._rows += batch.num_rows
                yield batch
            return
        raw = self._open_binary()
        self._counter = raw if isinstance(raw, _CountingReader) else raw.counter
        stream = LineGuard(raw, self.malformed.append)
        try:
            reader = pcsv.open_csv(
                pa.PythonFile(stream, mode="r"),
                read_options=pcsv.ReadOptions(
                    block_size=BLOCK_SIZE, skip_rows=0, column_names=self.names
                ),
                parse_options=pcsv.ParseOptions(invalid_row_handler=self._on_malformed),
                convert_options=pcsv.ConvertOptions(
                    include_columns=wanted,
                    column_types={name: pa.string() for name in wanted},
                    strings_can_be_null=True,
                    quoted_strings_can_be_null=True,
                ),
            )
        except pa.ArrowInvalid as exc:
            stream.close()
            if "Empty CSV file" in str(exc):
                return  # a header and no rows: nothing to read
            raise
        try:
            yield from reader
        finally:
            stream.close()

    def _on_malformed(self, row: pcsv.InvalidRow) -> str:
        self.malformed.append(shorten(row.text))
        return "skip"


class _Decompressed(_ForwardOnly):
    """A decompressing stream that still reports the compressed bytes read to its counter."""

    def __init__(self, stream: pa.NativeFile, counter: _CountingReader) -> None:
        self.stream = stream
        self.counter = counter
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        return self.stream.read(None if n is None or n < 0 else n)

    def close(self) -> None:
        self.closed = True
        self.stream.close()
        self.counter.close()


MAX_HEADER_BYTES = 1 << 20
"""The header line must end within this many bytes."""
MAX_LINE_BYTES = 1 << 20
"""A line longer than this is no AIS report (they take 100-300 bytes): it is cut out of the stream
and counted as one malformed row, so one giant line neither fails the file on pyarrow's block size
nor holds more than this much memory."""
RAW_TEXT_CHARS = 1000
"""How much of a malformed row's text is kept (for rejects.parquet)."""


def shorten(text: str) -> str:
    """A malformed row's text as kept: at most `RAW_TEXT_CHARS` characters."""
    if len(text) <= RAW_TEXT_CHARS:
        return text
    return f"{text[:RAW_TEXT_CHARS]}... ({len(text):,} characters)"


class LineGuard(_ForwardOnly):
    """The CSV bytes as pyarrow can parse them line by line, between the (decompressed) source and
    pyarrow's reader. It drops the header line (read already by `SourceReader`), ends lines at LF
    whatever the file used (CRLF or old-Mac CR), replaces bytes that are not UTF-8 (so a row with
    random bytes fails its own checks, or is kept when they sit in a column we do not read,
    instead of failing the file), and cuts out, as one malformed row each, lines longer than
    `MAX_LINE_BYTES` and lines that end inside a quoted field (pyarrow would carry the quote on
    over the following lines and swallow up to a block of good rows into one bad one).

    Clean blocks (the usual case) pass as views of what was read, without a copy: the checks
    are searches over the block, and only a block that needs a change is copied and cut."""

    def __init__(self, raw: Any, on_malformed: Callable[[str], None]) -> None:
        self.raw = raw
        self.on_malformed = on_malformed
        self.closed = False
        self._ready: deque[bytes | memoryview] = deque()  # whole lines, in order
        self._carry = b""  # the start of a line whose end has not arrived yet
        self._dropping: str | None = "header"  # or "long": skipping to the end of a line
        self._dropped = 0
        self._dropped_head = b""
        self._eof = False

    def read(self, n: int = -1) -> bytes | memoryview:
        """Whole lines, at most `n` bytes (pyarrow reads blocks of `BLOCK_SIZE`; a shorter block
        is fine as long as it ends at a line end); empty only at the end."""
        want = BLOCK_SIZE if n is None or n < 0 else max(n, 1)
        while not self._ready and not self._eof:
            chunk = self.raw.read(want)
            if chunk:
                self._feed(chunk)
            else:
                self._eof = True
                self._finish()
        if not self._ready:
            return b""
        piece = self._ready.popleft()
        if len(piece) > want:  # grown by UTF-8 replacement characters: the rest comes next
            self._ready.appendleft(piece[want:])
            piece = piece[:want]
        return piece

    def close(self) -> None:
        self.closed = True
        self.raw.close()

    def _feed(self, chunk: bytes) -> None:
        if b"\r" in chunk:
            chunk = chunk.replace(b"\r", b"\n")  # CRLF leaves an empty line: pyarrow skips it
        start = 0
        if self._dropping is not None or self._carry:
            first = chunk.find(b"\n")
            if first < 0:
                self._hold(chunk)
                return
            if self._dropping is not None:
                self._drop_more(chunk[:first])
                self._end_drop()
            else:
                line, self._carry = self._carry + chunk[: first + 1], b""
                self._emit(line, 0, len(line))
            start = first + 1
        cut = chunk.rfind(b"\n") + 1
        if cut > start:
            self._emit(chunk, start, cut)
        else:
            cut = start
        if cut < len(chunk):
            self._hold(chunk[cut:])

    def _hold(self, part: bytes) -> None:
        """Keep the start of an unfinished line; past `MAX_LINE_BYTES` it is dropped instead."""
        if self._dropping is not None:
            self._drop_more(part)
            return
        self._carry += part
        if len(self._carry) > MAX_LINE_BYTES:
            self._dropping = "long"
            self._drop_more(self._carry)
            self._carry = b""

    def _finish(self) -> None:
        if self._dropping is not None:
            self._end_drop()
        tail, self._carry = self._carry, b""
        if tail:
            self._emit(tail, 0, len(tail))

    def _drop_more(self, data: bytes) -> None:
        if len(self._dropped_head) < RAW_TEXT_CHARS:
            self._dropped_head += data[: RAW_TEXT_CHARS - len(self._dropped_head)]
        self._dropped += len(data)

    def _end_drop(self) -> None:
        if self._dropping == "long":
            self._report(self._dropped_head, self._dropped)
        self._dropping, self._dropped, self._dropped_head = None, 0, b""

    def _report(self, line: bytes, size: int | None = None) -> None:
        text = line[:RAW_TEXT_CHARS].decode("utf-8", errors="replace")
        size = len(line) if size is None else size
        if size > RAW_TEXT_CHARS:
            text += f"... ({size:,} bytes)"
        self.on_malformed(text)

    def _emit(self, buf: bytes, a: int, b: int) -> None:
        """Queue the whole lines buf[a:b]: as a view when they need nothing, else cleaned."""
        clean = not (b - a > MAX_LINE_BYTES and _may_hold_long_line(buf, a, b))
        if clean and not buf.isascii():
            try:
                codecs.utf_8_decode(memoryview(buf)[a:b], "strict", True)
            except UnicodeDecodeError:
                clean = False
        if clean and buf.find(b'"', a, b) >= 0 and _unterminated_spans(buf, a, b):
            clean = False
        if clean:
            self._ready.append(memoryview(buf)[a:b])
        else:
            cleaned = self._clean(buf[a:b])
            if cleaned:  # (an empty block would read as the end of the file)
                self._ready.append(cleaned)

    def _clean(self, body: bytes) -> bytes:
        """Whole lines (or the file's last, unended one) made safe for pyarrow."""
        if _may_hold_long_line(body, 0, len(body)):
            starts = _line_starts(body)
            ends = np.r_[starts[1:], len(body)]
            long = np.flatnonzero(ends - starts > MAX_LINE_BYTES + 1)
            body = self._cut(body, [(int(starts[i]), int(ends[i])) for i in long])
        if not body.isascii():
            try:
                body.decode("utf-8")
            except UnicodeDecodeError:
                body = body.decode("utf-8", errors="replace").encode("utf-8")
        if b'"' in body:
            body = self._cut(body, _unterminated_spans(body, 0, len(body)))
        return body

    def _cut(self, body: bytes, spans: list[tuple[int, int]]) -> bytes:
        """`body` without the lines [start, end) of `spans` (each reported as a malformed row)."""
        if not spans:
            return body
        pieces, pos = [], 0
        for a, b in sorted(spans):
            pieces.append(body[pos:a])
            self._report(body[a:b].rstrip(b"\n"))
            pos = b
        pieces.append(body[pos:])
        return b"".join(pieces)


def _unterminated_spans(buf: bytes, a: int, b: int) -> list[tuple[int, int]]:
    """The lines [start, end) of buf[a:b] (whole lines) that end inside a quoted field. Only lines
    holding a quote can; with few of them each is checked on its own, with many (a file that
    quotes every field) the rest of the block is scanned at once."""
    spans: list[tuple[int, int]] = []
    pos, checked = buf.find(b'"', a, b), 0
    while pos >= 0:
        line = max(buf.rfind(b"\n", a, pos) + 1, a)
        if checked == 1000:  # quotes everywhere: one compiled pass over what is left
            return spans + _scan_unterminated(buf, line, b)
        end = buf.find(b"\n", pos, b)
        end = b if end < 0 else end + 1
        if end - line > 10_000:
            spans += _scan_unterminated(buf, line, end)
        elif _ends_in_quotes(buf[line:end]):
            spans.append((line, end))
        checked += 1
        pos = buf.find(b'"', end, b) if end < b else -1
    return spans


def _ends_in_quotes(line: bytes) -> bool:
    """Whether one line ends inside a quoted field (`_unterminated_lines`'s rules, in Python: a
    few lines per block hold quotes, and compiling is not worth it for them)."""
    state, i, n = 0, 0, len(line)  # 0: field start, 1: unquoted or after closing quote, 2: quoted
    while i < n:
        c = line[i]
        if state == 2:
            if c == 34:
                if i + 1 < n and line[i + 1] == 34:
                    i += 1
                else:
                    state = 1
            elif c == 10:
                return True
        elif c == 10:
            return False
        elif c == 44:
            state = 0
        elif state == 0:
            state = 2 if c == 34 else 1
        i += 1
    return state == 2


def _scan_unterminated(buf: bytes, a: int, b: int) -> list[tuple[int, int]]:
    view = np.frombuffer(buf, np.uint8, count=b - a, offset=a)
    starts = np.empty(64, np.int64)
    found = _unterminated_lines(view, starts)
    if found > len(starts):
        starts = np.empty(found, np.int64)
        _unterminated_lines(view, starts)
    spans = []
    for s in starts[:found]:
        end = buf.find(b"\n", a + int(s), b)
        spans.append((a + int(s), b if end < 0 else end + 1))
    return spans


@numba.njit(cache=True)
def _unterminated_lines(buf: np.ndarray, out: np.ndarray) -> int:  # pragma: no cover - compiled
    """Start offsets (into `out`, as many as fit) of the lines of `buf` that end inside a quoted
    field, and how many there are. pyarrow's dialect: a quote opens a field only at its start,
    `""` inside it is an escaped quote, the first other quote closes it, and after that (as in an
    unquoted field) a quote is a literal character. Only lines holding a quote are parsed; the
    rest are skipped at memory speed."""
    found = 0
    n = buf.shape[0]
    done = 0  # everything before this offset is settled
    i = 0
    while True:
        while i < n and buf[i] != 34:  # the next quote
            i += 1
        if i >= n:
            return found
        line = i
        while line > done and buf[line - 1] != 10:  # back to the start of its line
            line -= 1
        state = 0  # 0: field start, 1: unquoted field or after a closing quote, 2: quoted
        i = line
        while i < n:
            c = buf[i]
            if state == 2:
                if c == 34:
                    if i + 1 < n and buf[i + 1] == 34:
                        i += 1
                    else:
                        state = 1
                elif c == 10:
                    break
            elif c == 10:
                break
            elif c == 44:  # ,
                state = 0
            elif state == 0:
                state = 2 if c == 34 else 1
            i += 1
        if state == 2:  # the line ended (or the buffer did) inside the quotes
            if found < out.shape[0]:
                out[found] = line
            found += 1
        i += 1
        done = i


def _may_hold_long_line(buf: bytes, a: int, b: int) -> bool:
    """Cheap test: some window of half `MAX_LINE_BYTES` in buf[a:b] without a line end (else no
    line is too long); only then are the lines measured."""
    half = MAX_LINE_BYTES // 2
    return b - a > MAX_LINE_BYTES and any(
        buf.find(b"\n", k, k + half) < 0 for k in range(a, b - half + 1, half)
    )


def _line_starts(body: bytes) -> np.ndarray:
    ends = np.flatnonzero(np.frombuffer(body, np.uint8) == ord("\n"))
    starts = np.r_[0, ends + 1]
    return starts[starts < len(body)] if len(body) else starts[:0]


READ_ERRORS = (
    zipfile.BadZipFile,
    EOFError,
    OSError,
    zlib.error,
    zstandard.ZstdError,
    pa.ArrowException,
)
"""What a corrupt or truncated file raises while it is being read (bad CRC, truncated stream)."""


def describe_read_error(source: Source, exc: BaseException) -> UserError:
    """One line for a file that broke while being read (bad CRC, truncated stream, ...)."""
    message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return UserError(f"{source.label}: corrupt or truncated input ({message})")


PARTITION_SCHEMA = pa.schema(
    [
        ("mmsi", pa.int64()),
        ("time", pa.timestamp("us", tz="UTC")),
        ("lon", pa.float64()),
        ("lat", pa.float64()),
        ("sog", pa.float64()),
        ("cog", pa.float64()),
        ("src", pa.int32()),
    ]
)
"""Rows between the stages: canonical names and types; NaN SOG/COG means 'derive it'."""


def _to_float(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Values as float64 (NaN for blanks) and a mask of the values that are not numbers."""
    if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        try:
            values = pc.cast(arr, pa.float64())
        except pa.ArrowInvalid:  # a bad value somewhere in this batch: per value, slower
            parsed = pd.to_numeric(arr.to_pandas(), errors="coerce").to_numpy(dtype=np.float64)
            return parsed, np.isnan(parsed) & ~_null_mask(arr)
    else:
        values = pc.cast(arr, pa.float64())
    return values.to_numpy(zero_copy_only=False), np.zeros(len(arr), dtype=bool)


TIME_RANGE_US = (
    int(pd.Timestamp("1990-01-01", tz="UTC").value // 1000),
    int(pd.Timestamp("2100-01-01", tz="UTC").value // 1000),
)
"""Times outside [1990, 2100) are no AIS reports (AIS began in the 2000s): a time column read in
the wrong unit lands in 1970 or far in the future, and is rejected row by row as bad_time."""
EPOCH_UNITS = ((1e11, 1_000_000, 1), (1e14, 1_000, 1), (1e17, 1, 1), (math.inf, 1, 1_000))
"""Numeric times are seconds, milliseconds, microseconds or nanoseconds since 1970, told apart by
their size (|t| below 1e11, 1e14, 1e17 or more: any time from 1973 to 5138 in each unit):
(bound, multiplier, divisor) to microseconds."""


def _to_time(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Microseconds since the epoch (UTC; times without a zone are UTC, as MarineCadastre's are)
    and a mask of the values that are not times: unparsable, or outside `TIME_RANGE_US`.
    Timestamps keep their unit; numbers (a parquet column of epoch seconds, or such strings in a
    CSV) are read in the unit their size gives (`EPOCH_UNITS`)."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    nulls = _null_mask(arr)
    if pa.types.is_timestamp(arr.type):
        values = arr.cast(pa.timestamp("us", tz=arr.type.tz))
        out = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        bad = np.zeros(len(arr), dtype=bool)
    elif pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type):
        out, bad = _epoch_us(arr.to_numpy(zero_copy_only=False))
    elif pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        out, bad = _text_time_us(arr)
    else:
        try:
            values = pc.cast(arr, pa.timestamp("us"))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            raise UserError(
                f"the time column holds {arr.type} values: expected times, text or numbers"
            ) from None
        out = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        bad = np.zeros(len(arr), dtype=bool)
    out = np.asarray(out, dtype=np.int64)
    bad = (bad | (out < TIME_RANGE_US[0]) | (out >= TIME_RANGE_US[1])) & ~nulls
    return out, bad


def _epoch_us(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Epoch numbers (any unit, see `EPOCH_UNITS`) as microseconds, and a mask of non-numbers."""
    out = np.zeros(len(values), dtype=np.int64)
    if values.dtype.kind in "iu":
        ints = values.astype(np.int64)
        size = np.abs(ints.astype(np.float64))
        low = 0.0
        for bound, mul, div in EPOCH_UNITS:
            sel = (size >= low) & (size < bound)
            with np.errstate(over="ignore"):
                out[sel] = ints[sel] * mul // div
            low = bound
        return out, np.zeros(len(values), dtype=bool)
    floats = values.astype(np.float64)
    bad = ~np.isfinite(floats)
    size = np.abs(np.where(bad, 0.0, floats))
    scale = np.ones(len(floats))
    low = 0.0
    for bound, mul, div in EPOCH_UNITS:
        scale[(size >= low) & (size < bound)] = mul / div
        low = bound
    ok = ~bad
    out[ok] = np.round(floats[ok] * scale[ok]).astype(np.int64)
    return out, bad


def _text_time_us(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Times written as text: ISO 8601 (fast path in Arrow, else pandas), or epoch numbers."""
    for kind in (pa.timestamp("us"), pa.timestamp("us", tz="UTC")):
        try:
            values = pc.cast(arr, kind)
        except pa.ArrowInvalid:
            continue
        ints = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        return ints, np.zeros(len(arr), dtype=bool)
    text = arr.to_pandas()
    parsed = pd.to_datetime(text, errors="coerce", utc=True, format="ISO8601").dt.as_unit("us")
    out = parsed.to_numpy(dtype="datetime64[us]").view(np.int64).copy()
    bad = parsed.isna().to_numpy() & ~_null_mask(arr)
    if bad.any():  # numbers: epoch seconds (or ms, us, ns) written as text
        numbers = pd.to_numeric(text[bad], errors="coerce").to_numpy(dtype=np.float64)
        epoch, not_number = _epoch_us(numbers)
        idx = np.flatnonzero(bad)
        out[idx[~not_number]] = epoch[~not_number]
        bad[idx[~not_number]] = False
    return out, bad


def _time_like(kind: pa.DataType) -> bool:
    return (
        pa.types.is_timestamp(kind)
        or pa.types.is_date(kind)
        or pa.types.is_integer(kind)
        or pa.types.is_floating(kind)
        or pa.types.is_string(kind)
        or pa.types.is_large_string(kind)
        or pa.types.is_dictionary(kind)
    )


def _null_mask(arr: pa.Array) -> np.ndarray:
    return arr.is_null().to_numpy(zero_copy_only=False)


def to_canonical(
    batch: pa.RecordBatch, columns: dict[str, str], src: int
) -> tuple[pa.Table, np.ndarray]:
    """Convert one batch to `PARTITION_SCHEMA`, with a rejection code per row for blanks,
    non-numbers, bad MMSIs and unparsable times (0 where the row is fine)."""
    n = batch.num_rows
    codes = np.zeros(n, dtype=np.uint8)
    raw = {key: batch.column(name) for key, name in columns.items()}
    missing = np.zeros(n, dtype=bool)
    for arr in raw.values():
        missing |= _null_mask(arr)
    numbers, bad_number = {}, np.zeros(n, dtype=bool)
    for key in ("lat", "lon", "sog", "cog"):
        if key in raw:
            numbers[key], bad = _to_float(raw[key])
            bad_number |= bad
        else:
            numbers[key] = np.full(n, np.nan)
    mmsi_f, bad_mmsi = _to_float(raw["mmsi"])
    with np.errstate(invalid="ignore"):
        out_of_range = (mmsi_f < 1) | (mmsi_f > MAX_MMSI)
        bad_mmsi |= ~missing & ((mmsi_f != np.floor(mmsi_f)) | out_of_range)
    time_us, bad_time = _to_time(raw["time"])
    for mask, reason in (
        (missing, "missing_value"),
        (bad_number, "bad_number"),
        (bad_mmsi, "bad_mmsi"),
        (bad_time, "bad_time"),
    ):
        codes[(codes == 0) & mask] = CODE[reason]
    with np.errstate(invalid="ignore"):
        mmsi = np.where((mmsi_f >= 0) & (mmsi_f <= MAX_MMSI), mmsi_f, 0).astype(np.int64)
    table = pa.table(
        [
            mmsi,
            pa.array(time_us, pa.int64()).view(pa.timestamp("us", tz="UTC")),
            numbers["lon"],
            numbers["lat"],
            numbers["sog"],
            numbers["cog"],
            np.full(n, src, dtype=np.int32),
        ],
        schema=PARTITION_SCHEMA,
    )
    return table, codes
