"""Reading AIS files as a stream of pyarrow record batches of their needed columns.

`open_reader` picks the reader of a source's kind (`inputs.Source.kind`): `SourceReader` for CSV
(any MarineCadastre layout, or the DMA's) and parquet, `nmea.NmeaReader` for NMEA logs. Every
reader offers the same few things to the pipeline (`TableReader`): the resolved columns, the
layout's time format, record batches, progress, the lines it had to skip, by reason, and the
tally of who the vessels are (`vessels.VesselTally`). Only the columns the pipeline needs are
read (the six of a position, the optional heading, status and the vessel's own columns), as
strings for CSV, so one bad value costs one counted row, not the file (`convert.to_canonical`
does the typing). `TableReader.tables` gives the rows typed: a CSV's plain rows parsed by the
fast path (`fastcsv`), the rest the usual way, and a block whose records hold line ends in
quoted fields (`lineguard.Multiline`: valid CSV, rare) the usual way whole.
"""

from __future__ import annotations

import csv
import os
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple, Protocol

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

from aisdati.errors import UserError
from aisdati.preprocess.convert import is_time_type, to_canonical
from aisdati.preprocess.fastcsv import ColumnSlots, ParsedBlock, parse_block, typed_batch
from aisdati.preprocess.inputs import Source, describe_read_error
from aisdati.preprocess.layouts import OPTIONAL, STATIC, layout_of, resolve_columns
from aisdati.preprocess.lineguard import BLOCK_SIZE, HeaderLine, LineGuard, Multiline, shorten
from aisdati.preprocess.nmea import NmeaReader
from aisdati.preprocess.streams import (
    READ_ERRORS,
    ByteStream,
    CountingReader,
    Transcoded,
    bom_encoding,
    looks_like_utf16,
)
from aisdati.preprocess.vessels import VesselTally

MAX_HEADER_BYTES = 1 << 20
"""The header line must end within this many bytes."""
PARSE_THREADS = min(2, os.cpu_count() or 1)
"""Threads parsing CSV blocks on the fast path (`fastcsv` releases the GIL), while one more
reads, inflates and guards the next blocks and the caller's thread takes the parsed ones."""
READ_AHEAD = 2
"""Blocks asked of the guarded stream ahead of the one being parsed."""
MOSTLY_SLOW = 8
"""A block with more than one row in this many that the fast path cannot parse (a file that
quotes fields with commas in them, say) is read the usual way whole."""
ROW_KEY = "\x00row"
"""The column that numbers the rows read the usual way on the fast path (no header names it)."""


class PlainRows(NamedTuple):
    """A block as the fast path parsed it, its rows made canonical, and its plain rows' static
    hashes counted (`ParsedBlock.static_tally`)."""

    parsed: ParsedBlock
    table: pa.Table
    codes: np.ndarray
    tally: tuple[np.ndarray, ...]


class TableReader(Protocol):
    """What the pipeline reads from a source, whatever its kind."""

    source: Source
    columns: dict[str, str]
    """Canonical column -> the batches' column name (`layouts.resolve_columns`)."""
    time_format: str | None
    """`strptime` format of the time column (`layouts.Layout.time_format`)."""
    vessels: VesselTally
    """Who the vessels are, from the rows read so far (complete once `tables` is exhausted)."""

    @property
    def total(self) -> int: ...

    @property
    def done(self) -> int: ...

    @property
    def skipped(self) -> dict[str, list[str | None]]:
        """Rejection reason -> the text of each line skipped for it (None past a memory bound);
        complete once `batches` is exhausted."""
        ...

    def batches(self) -> Iterator[pa.RecordBatch]: ...

    def tables(self, src: int) -> Iterator[tuple[pa.Table, np.ndarray]]:
        """The rows as canonical tables with a rejection code per row (`convert.to_canonical`),
        `src` their source number."""
        ...


def open_reader(source: Source) -> TableReader:
    """The reader of `source`'s kind, its header (or first lines) checked already."""
    return NmeaReader(source) if source.kind == "nmea" else SourceReader(source)


class SourceReader:
    """Streams one CSV or parquet source as record batches of its needed columns (as the source
    typed them: strings for CSV), counting malformed CSV rows instead of failing on them.

    A CSV may begin with blank lines, and be UTF-16 or UTF-32 with a byte-order mark (read as
    UTF-8). A header line met again mid-file (exports joined with `cat`) is counted as a
    `header_line` and the rows after it are read under it, whatever its column order; a header
    naming other columns (or another layout) fails the run in one line."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.malformed: list[str] = []
        self.headers: list[str] = []
        """The text of each header line met mid-file."""
        self._counter: CountingReader | None = None
        self._rows = 0
        self.encoding: str | None = None
        """The text encoding its byte-order mark gives (None: UTF-8)."""
        self._header_lines = 1
        """Lines before the first row: blank lines, then the header."""
        self.vessels = VesselTally()
        self._position = 0
        """Rows of the source read so far (where each is, for `vessels`)."""
        schema = self._parquet_schema() if source.kind == "parquet" else None
        self.names = schema.names if schema else self._header()
        self.columns = resolve_columns(self.names, source.label)
        self.time_format = layout_of(self.names).time_format
        if schema:
            self.columns = usable_columns(schema, self.columns)
            check_parquet_types(schema, self.columns, source.label)

    @property
    def total(self) -> int:
        """Progress units of the whole source: bytes of CSV, rows of parquet."""
        if self.source.kind == "parquet":
            return pq.ParquetFile(self.source.path).metadata.num_rows
        return self.source.size()

    @property
    def done(self) -> int:
        """Progress units read so far."""
        return self._counter.bytes_read if self._counter else self._rows

    @property
    def skipped(self) -> dict[str, list[str | None]]:
        return {"malformed_row": list(self.malformed), "header_line": list(self.headers)}

    def _open(self) -> tuple[ByteStream | Transcoded, CountingReader]:
        stream, counter = self.source.open()
        return (Transcoded(stream, self.encoding) if self.encoding else stream), counter

    def _header(self) -> list[str]:
        """The column names on the first line that is not blank (lines end with LF, CRLF or a
        lone CR)."""
        try:
            stream, _ = self.source.open()
            try:
                chunk = stream.read(MAX_HEADER_BYTES)
            finally:
                stream.close()
        except READ_ERRORS as exc:
            raise describe_read_error(self.source, exc) from None
        self.encoding = bom_encoding(chunk)
        text = chunk.decode(self.encoding or "utf-8-sig", errors="replace")
        if self.encoding is None and looks_like_utf16(chunk):
            raise UserError(
                f"{self.source.label}: UTF-16 text without a byte-order mark: save it as UTF-8"
            )
        lines = text.replace("\r", "\n").split("\n")
        first = next((i for i, line in enumerate(lines) if line.strip()), None)
        if first is None:
            raise UserError(f"{self.source.label}: the file is empty (no header line)")
        if first == len(lines) - 1 and len(chunk) >= MAX_HEADER_BYTES:
            raise UserError(
                f"{self.source.label}: no line break in the first {MAX_HEADER_BYTES >> 20} MiB: "
                "not a CSV file with a header line"
            )
        self._header_lines = first + 1
        header = lines[first]
        odd = sum(1 for c in header if c == "\ufffd" or (not c.isprintable() and c != "\t"))
        if odd > len(header) // 10:
            raise UserError(f"{self.source.label}: the first line is not CSV text (a binary file?)")
        try:
            return parse_header(header)
        except csv.Error as exc:
            raise UserError(f"{self.source.label}: unreadable header line ({exc})") from None

    def _parquet_schema(self) -> pa.Schema:
        try:
            schema = pq.ParquetFile(self.source.path).schema_arrow
        except (pa.ArrowException, OSError) as exc:
            raise UserError(f"{self.source.label}: not a readable parquet file ({exc})") from None
        return schema

    def _header_of(self, line: bytes) -> list[str] | None:
        """The column names of a line mid-file when it is a header (it names every required
        column), else None."""
        try:
            names = parse_header(line.decode("utf-8-sig", errors="replace"))
            resolve_columns(names, self.source.label)
        except (csv.Error, UserError):
            return None
        return names

    def batches(self) -> Iterator[pa.RecordBatch]:
        """Record batches holding the resolved columns, under the source's own (first) names."""
        if self.source.kind == "parquet":
            for batch in pq.ParquetFile(self.source.path).iter_batches(
                batch_size=1 << 18, columns=list(self.columns.values())
            ):
                self._rows += batch.num_rows
                yield batch
            return
        for guard, names, columns in self._segments():
            yield from self._csv_batches(guard, names, columns)

    def tables(self, src: int) -> Iterator[tuple[pa.Table, np.ndarray]]:
        if self.source.kind == "parquet" or self.time_format is not None:
            yield from self.usual_tables(src)
            return
        for guard, names, columns in self._segments():
            slots = ColumnSlots.of(names, columns)
            if slots is None:
                yield from self._tallied(self._csv_batches(guard, names, columns), src)
            else:
                yield from self._fast_tables(guard, names, columns, slots, src)

    def usual_tables(self, src: int) -> Iterator[tuple[pa.Table, np.ndarray]]:
        """Every row the usual way (`batches`, then `convert.to_canonical`), the vessels
        tallied: what `tables` gives where the fast path does not apply."""
        yield from self._tallied(self.batches(), src)

    def _tallied(
        self, batches: Iterator[pa.RecordBatch], src: int
    ) -> Iterator[tuple[pa.Table, np.ndarray]]:
        for batch in batches:
            table, codes = to_canonical(batch, self.columns, src, self.time_format)
            self._tally(batch, table, np.arange(batch.num_rows))
            self._position += batch.num_rows
            yield table, codes

    def _tally(self, batch: pa.RecordBatch, table: pa.Table, rows: np.ndarray) -> None:
        """The vessels of a batch's rows read the usual way (`table`: them made canonical), at
        `rows` from `_position` on."""
        statics = {key: batch.column(self.columns[key]) for key in STATIC if key in self.columns}
        mmsi, time_us = table.column("mmsi").to_numpy(), time_of(table)
        self.vessels.add(mmsi, statics, self._position + rows, time_us)

    def _segments(self) -> Iterator[tuple[LineGuard, list[str], dict[str, str]]]:
        """The CSV's stretches under each header line: the guarded stream, positioned at the
        stretch's first row, with the stretch's column names and resolved columns."""
        raw, self._counter = self._open()
        guard = LineGuard(
            raw, self.malformed.append, self._header_lines, self._header_of, len(self.names)
        )
        try:
            names, columns = self.names, self.columns
            while True:
                yield guard, names, columns
                header = guard.next_header()
                if header is None:
                    return
                self.headers.append(header.text)
                names, columns = header.names, self._columns_of(header)
        finally:
            guard.close()

    def _columns_of(self, header: HeaderLine) -> dict[str, str]:
        """The columns of a header met mid-file, once it is known to name the same ones as the
        first header (but the optional ones: those it lacks read as none), in the same layout."""
        columns = resolve_columns(header.names, self.source.label)
        needed = [c for c in columns if c not in OPTIONAL]
        first = [c for c in self.columns if c not in OPTIONAL]
        if set(needed) != set(first):
            raise UserError(
                f"{self.source.label}: a second header line mid-file names other columns "
                f"({', '.join(c.upper() for c in needed)}) than the first "
                f"({', '.join(c.upper() for c in first)}): give the files as separate --input"
            )
        layouts = layout_of(header.names).name, layout_of(self.names).name
        if layouts[0] != layouts[1]:
            raise UserError(
                f"{self.source.label}: a second header line mid-file is of the {layouts[0]} "
                f"layout, the first of the {layouts[1]} layout: give the files as separate --input"
            )
        return columns

    def _csv_batches(
        self, guard: LineGuard, names: list[str], columns: dict[str, str]
    ) -> Iterator[pa.RecordBatch]:
        """The rows up to the next header line (or the end), read under `names` (`columns`: the
        needed ones), as batches whose columns carry the first header's names."""
        wanted = [columns[c] for c in self.columns if c in columns]
        try:
            reader = pcsv.open_csv(
                pa.PythonFile(guard, mode="r"),
                read_options=pcsv.ReadOptions(
                    block_size=BLOCK_SIZE, skip_rows=0, column_names=names
                ),
                parse_options=pcsv.ParseOptions(
                    newlines_in_values=True, invalid_row_handler=self._on_malformed
                ),
                convert_options=text_columns(wanted),
            )
        except pa.ArrowInvalid as exc:
            if "Empty CSV file" in str(exc):
                return  # a header and no rows: nothing to read
            raise
        for batch in reader:
            yield self._first_names(batch, columns)

    def _first_names(
        self, table: pa.RecordBatch | pa.Table, columns: dict[str, str], key: tuple[str, ...] = ()
    ) -> pa.RecordBatch:
        """The `key` columns, then the needed ones (`columns`: their names in `table`) under the
        first header's names; an optional one that this stretch of the file lacks, null."""
        arrays = [table.column(name) for name in key]
        for canonical in self.columns:
            at = columns.get(canonical)
            arrays.append(table.column(at) if at else pa.nulls(table.num_rows, pa.string()))
        arrays = [a.combine_chunks() if isinstance(a, pa.ChunkedArray) else a for a in arrays]
        return pa.record_batch(arrays, names=[*key, *self.columns.values()])

    def _on_malformed(self, row: pcsv.InvalidRow) -> str:
        self.malformed.append(shorten(row.text))
        return "skip"

    def _fast_tables(
        self,
        guard: LineGuard,
        names: list[str],
        columns: dict[str, str],
        slots: ColumnSlots,
        src: int,
    ) -> Iterator[tuple[pa.Table, np.ndarray]]:
        """The stretch's blocks read (inflated, guarded) on one thread and parsed on others
        (`fastcsv` releases the GIL) while this one passes them on, in order; each block's
        other rows read the usual way and put back in their places."""
        with (
            ThreadPoolExecutor(1) as reader,
            ThreadPoolExecutor(PARSE_THREADS) as parser,
        ):
            reads = deque(reader.submit(guard.read, BLOCK_SIZE) for _ in range(READ_AHEAD))
            parsed: deque[tuple[bytes | memoryview, Future[PlainRows]]] = deque()
            while True:
                block = reads.popleft().result()
                if not len(block):  # the end, or a header line: later reads give nothing too
                    break
                reads.append(reader.submit(guard.read, BLOCK_SIZE))
                parsed.append((block, parser.submit(self._plain_rows, block, slots, src)))
                if len(parsed) > PARSE_THREADS:
                    yield self._block_table(*parsed.popleft(), names, columns, src)
            for rest in reads:
                rest.result()
            while parsed:
                yield self._block_table(*parsed.popleft(), names, columns, src)

    def _plain_rows(
        self, block: bytes | memoryview, slots: ColumnSlots, src: int
    ) -> PlainRows | None:
        """A block parsed by the fast path, its rows canonical (those it could not parse are
        placeholders, `ParsedBlock.slow`); None for a `Multiline` block (not read by lines)."""
        if isinstance(block, Multiline):
            return None
        parsed = parse_block(block, slots)
        batch = typed_batch(parsed, slots, self.columns)
        table, codes = to_canonical(batch, self.columns, src)
        return PlainRows(parsed, table, codes, parsed.static_tally(time_of(table)))

    def _block_table(
        self,
        block: bytes | memoryview,
        plain: Future[PlainRows | None],
        names: list[str],
        columns: dict[str, str],
        src: int,
    ) -> tuple[pa.Table, np.ndarray]:
        """One block's canonical rows in the block's order: its plain rows from the fast path,
        the others (`ParsedBlock.slow`) read the usual way, each numbered by its row; a block
        of mostly other rows, or of records spanning lines, read the usual way whole. The
        vessels of every row tallied."""
        if (rows := plain.result()) is None:
            malformed = len(self.malformed)
            usual = self._read_usual(pa.py_buffer(block), names, columns, numbered=False)
            table, codes = to_canonical(usual, self.columns, src)
            self._tally(usual, table, np.arange(usual.num_rows))
            self._position += usual.num_rows + len(self.malformed) - malformed
            return table, codes
        parsed, table, codes, tally = rows
        slow = np.flatnonzero(parsed.slow)
        if len(slow) * MOSTLY_SLOW > parsed.rows:
            usual = self._read_usual(pa.py_buffer(block), names, columns, numbered=False)
            table, codes = to_canonical(usual, self.columns, src)
            self._tally(usual, table, np.arange(usual.num_rows))
            self._position += parsed.rows
            return table, codes
        self._tally_plain(block, parsed, tally, names, columns)
        if not len(slow):
            self._position += parsed.rows
            return table, codes
        view = memoryview(block)
        text = b"".join(
            b"%d,%b\n" % (k, view[parsed.line_start[k] : parsed.line_end[k]]) for k in slow
        )
        usual = self._read_usual(pa.py_buffer(text), names, columns, numbered=True)
        slow_table, slow_codes = to_canonical(usual, self.columns, src)
        self._tally(usual, slow_table, usual.column(ROW_KEY).to_numpy())
        self._position += parsed.rows
        kept = np.flatnonzero(~parsed.slow)
        order = np.argsort(np.concatenate([kept, usual.column(ROW_KEY).to_numpy()]), kind="stable")
        merged = pa.concat_tables([table.take(kept), slow_table]).take(order)
        return merged, np.concatenate([codes[kept], slow_codes])[order]

    def _tally_plain(
        self,
        block: bytes | memoryview,
        parsed: ParsedBlock,
        tally: tuple[np.ndarray, ...],
        names: list[str],
        columns: dict[str, str],
    ) -> None:
        """The vessels of a block's plain rows, from their static hashes (`tally`,
        `ParsedBlock.static_tally`): the text of one row of each hash not met before read the
        usual way, then the counts and times."""
        keys, counts, last, first_us, last_us = tally
        if not len(keys):
            return
        numbers = self.vessels.numbers(keys)
        new = numbers < 0
        if new.any():
            rows = last[new]
            text = parsed.lines(block, rows)
            usual = self._read_usual(pa.py_buffer(text), names, columns, numbered=False)
            statics = {k: usual.column(self.columns[k]) for k in STATIC if k in self.columns}
            numbers[new] = self.vessels.know(keys[new], parsed.mmsi[rows], statics)
        self.vessels.add_counts(numbers, counts, self._position + last, (first_us, last_us))

    def _read_usual(
        self, text: pa.Buffer, names: list[str], columns: dict[str, str], numbered: bool
    ) -> pa.RecordBatch:
        """Whole records read by pyarrow's parser as `_csv_batches` reads them, the needed
        columns under the first header's names; `numbered`: each line starts with its row in the
        block (`ROW_KEY`, kept as a column), which a malformed line's reported text leaves out."""
        wanted = [columns[c] for c in self.columns if c in columns]
        key = (ROW_KEY,) if numbered else ()
        table = pcsv.read_csv(
            text,
            read_options=pcsv.ReadOptions(column_names=[*key, *names], use_threads=False),
            parse_options=pcsv.ParseOptions(
                newlines_in_values=True,
                invalid_row_handler=self._on_numbered_malformed if numbered else self._on_malformed,
            ),
            convert_options=text_columns(wanted, list(key)),
        )
        return self._first_names(table, columns, key)

    def _on_numbered_malformed(self, row: pcsv.InvalidRow) -> str:
        """A malformed row read the usual way on the fast path: its text without its number."""
        self.malformed.append(shorten(row.text.split(",", 1)[1]))
        return "skip"


def text_columns(wanted: list[str], numbers: list[str] | None = None) -> pcsv.ConvertOptions:
    """pyarrow's conversion of the `wanted` columns as text (blank or quoted-blank: null), so
    that `convert.to_canonical` types them and counts a bad value as one row; `numbers` come
    first, as integers (the fast path's row numbers)."""
    numbers = numbers or []
    return pcsv.ConvertOptions(
        include_columns=[*numbers, *wanted],
        column_types={n: pa.int64() for n in numbers} | {n: pa.string() for n in wanted},
        strings_can_be_null=True,
        quoted_strings_can_be_null=True,
    )


def parse_header(line: str) -> list[str]:
    """The column names of a header line (a name may be as long as the line)."""
    limit = csv.field_size_limit(MAX_HEADER_BYTES)
    try:
        return [n.strip() for n in next(csv.reader([line]))]
    finally:
        csv.field_size_limit(limit)


NUMERIC_TYPES = (
    pa.types.is_integer,
    pa.types.is_floating,
    pa.types.is_decimal,
    pa.types.is_string,
    pa.types.is_large_string,
    pa.types.is_null,
)
"""Parquet column types that can hold MMSIs, positions, SOG and COG (text is parsed per row)."""


def usable_columns(schema: pa.Schema, columns: dict[str, str]) -> dict[str, str]:
    """The columns of a parquet file to read: an optional one (`layouts.OPTIONAL`) of a type
    that holds no such values (a struct, a list, booleans, ...) is left out, not refused."""
    return {
        canonical: name
        for canonical, name in columns.items()
        if canonical not in OPTIONAL or _holds_numbers(schema.field(name).type)
    }


def _holds_numbers(kind: pa.DataType) -> bool:
    value_kind = kind.value_type if pa.types.is_dictionary(kind) else kind
    return any(test(value_kind) for test in NUMERIC_TYPES)


def check_parquet_types(schema: pa.Schema, columns: dict[str, str], label: str) -> None:
    """A one-line error for a needed parquet column of a type that holds no such values (a
    struct, a list, booleans, ...), before any row is read."""
    for canonical, name in columns.items():
        kind = schema.field(name).type
        if canonical == "time":
            if not is_time_type(kind):
                raise UserError(
                    f"{label}: column {name!r} holds {kind} values; expected times "
                    "(a timestamp, text, or numbers of seconds since 1970)"
                )
        elif not _holds_numbers(kind):
            raise UserError(f"{label}: column {name} has type {kind}, expected numbers")


def time_of(table: pa.Table) -> np.ndarray:
    """A canonical table's times, microseconds since the epoch (NaT: the int64 minimum)."""
    return table.column("time").to_numpy().view(np.int64)
