"""Reading AIS files of any MarineCadastre layout as a stream of pyarrow record batches.

Inputs are local paths, globs or directories holding `.zip` (CSV members), `.csv`, `.csv.gz`,
`.csv.zst` or `.parquet` files. Columns are matched by name, ignoring case, underscores and
spaces, with the spellings seen in the wild (`BaseDateTime`, `base_date_time`, `latitude`...);
their order does not matter and extra columns are ignored. Only the six columns the pipeline
needs are converted, as strings first, so one bad value costs one counted row, not the file.
"""

from __future__ import annotations

import csv
import glob
import re
import zipfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

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
                        f"{label}: columns '{found[canonical]}' and '{name}' both look like "
                        f"{canonical.upper()}"
                    )
                found[canonical] = name
    missing = [c for c in REQUIRED if c not in found]
    if missing:
        wanted = ", ".join(f"{c.upper()} (e.g. {ALIASES[c][0]})" for c in missing)
        raise UserError(f"{label}: missing required column {wanted}; header is {names}")
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
        try:
            stream = self._open_binary()
            try:
                chunk = stream.read(1 << 20)
            finally:
                stream.close()
        except READ_ERRORS as exc:
            raise describe_read_error(self.source, exc) from None
        first = chunk.split(b"\n", 1)[0].rstrip(b"\r")
        if not first.strip():
            raise UserError(f"{self.source.label}: the file is empty (no header line)")
        text = first.decode("utf-8-sig", errors="replace")
        names = next(csv.reader([text]))
        return [n.strip() for n in names]

    def _parquet_names(self) -> list[str]:
        try:
            return pq.ParquetFile(self.source.path).schema_arrow.names
        except (pa.ArrowException, OSError) as exc:
            raise UserError(f"{self.source.label}: not a readable parquet file ({exc})") from None

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
        stream = self._open_binary()
        self._counter = stream if isinstance(stream, _CountingReader) else stream.counter
        try:
            reader = pcsv.open_csv(
                pa.PythonFile(stream, mode="r"),
                read_options=pcsv.ReadOptions(
                    block_size=BLOCK_SIZE, skip_rows=1, column_names=self.names
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
        self.malformed.append(row.text)
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


def _to_time(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Microseconds since the epoch (UTC; times without a zone are UTC, as MarineCadastre's are)
    and a mask of the values that are not times."""
    if pa.types.is_timestamp(arr.type):
        values = arr.cast(pa.timestamp("us", tz=arr.type.tz))
    else:
        try:
            values = pc.cast(arr, pa.timestamp("us"))
        except pa.ArrowInvalid:
            try:
                values = pc.cast(arr, pa.timestamp("us", tz="UTC"))
            except pa.ArrowInvalid:
                parsed = pd.to_datetime(
                    arr.to_pandas(), errors="coerce", utc=True, format="ISO8601"
                ).dt.as_unit("us")
                out = parsed.to_numpy(dtype="datetime64[us]").view(np.int64)
                return out, parsed.isna().to_numpy() & ~_null_mask(arr)
    ints = pc.fill_null(values.view(pa.int64()), 0)
    return ints.to_numpy(zero_copy_only=False), np.zeros(len(arr), dtype=bool)


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
