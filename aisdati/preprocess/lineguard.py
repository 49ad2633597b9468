"""The line guard: the CSV bytes between a (decompressed) source and pyarrow's CSV reader, cleaned
so that one bad line costs one counted row instead of the file (see `LineGuard`)."""

from __future__ import annotations

import codecs
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from aisdati.preprocess.bytewords import each, equal
from aisdati.preprocess.streams import ForwardOnly

BLOCK_SIZE = 4 << 20
"""Bytes of CSV per record batch: large enough for pyarrow's threads, small enough for memory
(pyarrow parses several blocks ahead, each also held as Python bytes: 16 MiB blocks held 350 MB
more while reading a 590 MB file than these, and were no faster)."""
MAX_LINE_BYTES = 1 << 20
"""A line longer than this is no AIS report (they take 100-300 bytes): it is cut out of the stream
and counted as one malformed row, so one giant line neither fails the file on pyarrow's block size
nor holds more than this much memory."""
RAW_TEXT_CHARS = 1000
"""How much of a malformed row's text is kept (for rejects.parquet)."""
RECORD_LINES = 10
"""Lines one record may span: a quoted field may hold line ends (valid CSV: `"NAME\nMORE"`), but
a quote that stays open longer is a stray one, whose line alone is cut."""
HEADER_MARK = b"mmsi"
"""Every header line names the MMSI column, so only lines holding this (in any case) can be a
header repeated mid-file (two exports joined with `cat`): one compiled pass over the block
(`_marks`; three `bytes.find`, one per spelling, took 1.6 s of 10 M rows), then a real check of
the few lines found."""


@dataclass(frozen=True)
class HeaderLine:
    """A header line met mid-file: its column names and its text (for rejects.parquet)."""

    names: list[str]
    text: str


class Multiline(bytes):
    """Whole records of CSV some of which hold a line end in a quoted field: they must be read
    by a parser that knows (pyarrow's with `newlines_in_values`), not line by line."""


def shorten(text: str) -> str:
    """A malformed row's text as kept: at most `RAW_TEXT_CHARS` characters."""
    if len(text) <= RAW_TEXT_CHARS:
        return text
    return f"{text[:RAW_TEXT_CHARS]}... ({len(text):,} characters)"


class LineGuard(ForwardOnly):
    """The CSV bytes as pyarrow can parse them line by line, between the (decompressed) source and
    pyarrow's reader. It drops the header line (read already by `SourceReader`), ends lines at LF
    whatever the file used (CRLF or old-Mac CR), replaces bytes that are not UTF-8 (so a row with
    random bytes fails its own checks, or is kept when they sit in a column we do not read,
    instead of failing the file), and cuts out, as one malformed row each, lines longer than
    `MAX_LINE_BYTES` and lines that end inside a quoted field (pyarrow would carry the quote on
    over the following lines and swallow up to a block of good rows into one bad one) but for
    a record whose quoted field holds line ends and which is valid CSV all the same: its quote
    closes within `RECORD_LINES` lines, before a comma or the line end, and it has the header's
    `fields` fields. Such records stay whole, and the piece holding them is a `Multiline`.

    Clean blocks (the usual case) pass as views of what was read, without a copy: the checks
    are searches over the block, and only a block that needs a change is copied and cut.

    The first `header_lines` lines (blank lines, then the header) are dropped. A later line that
    `header_of` takes for a header (its column names, or None) ends the stream there, as if the
    file ended: the reader takes it with `next_header` and reads on under it."""

    def __init__(
        self,
        raw: Any,
        on_malformed: Callable[[str], None],
        header_lines: int = 1,
        header_of: Callable[[bytes], list[str] | None] | None = None,
        fields: int | None = None,
    ) -> None:
        self.raw = raw
        self.on_malformed = on_malformed
        self.header_of = header_of
        self.fields = fields
        """The header's number of fields (None: no record may span lines)."""
        self.closed = False
        self._ready: deque[bytes | memoryview | HeaderLine] = deque()  # whole lines, in order
        self._header: HeaderLine | None = None  # met, and not taken yet: the stream ends there
        self._carry = b""  # the start of a line whose end has not arrived yet
        self._header_left = header_lines
        self._dropping: str | None = "header"  # or "long": skipping to the end of a line
        self._dropped = 0
        self._dropped_head = b""
        self._eof = False

    def read(self, n: int = -1) -> bytes | memoryview:
        """Whole lines, at most `n` bytes (pyarrow reads blocks of `BLOCK_SIZE`; a shorter block
        is fine as long as it ends at a line end); empty only at the end."""
        want = BLOCK_SIZE if n is None or n < 0 else max(n, 1)
        while not self._ready and not self._eof and self._header is None:
            chunk = self._next_chunk(want)
            if chunk is None:
                self._eof = True
                self._finish()
            else:
                self._feed(chunk)
        if not self._ready or self._header is not None:
            return b""
        piece = self._ready.popleft()
        if isinstance(piece, HeaderLine):
            self._header = piece
            return b""
        if len(piece) > want:  # grown by UTF-8 replacement characters: the rest comes next
            kind = type(piece)  # (a `Multiline` stays one)
            self._ready.appendleft(kind(piece[want:]))
            piece = kind(piece[:want])
        return piece

    def next_header(self) -> HeaderLine | None:
        """The header line the stream stopped at (then reading goes on after it), or None at the
        end of the file."""
        header, self._header = self._header, None
        return header

    def close(self) -> None:
        self.closed = True
        self.raw.close()

    def _next_chunk(self, want: int) -> bytes | bytearray | None:
        """The start of a line carried over from the last chunk, then the stream's next bytes,
        `want` in all (or a byte more than the carry), as one buffer; None at the stream's end
        (the carry stays for `_finish`). The stream reads into the buffer behind the carry
        where it can (`readinto`), so that no chunk is copied: the carried line made a piece
        of its own before, half of the reader's blocks, each costing a parse, a typing and
        partition writes however small (the read stage 2.58 -> 2.14 s of 10 M rows)."""
        head = self._carry
        size = max(want - len(head), 1)
        readinto = getattr(self.raw, "readinto", None) if head else None
        if readinto is None:
            data = self.raw.read(size)
            if not data:
                return None
            self._carry = b""
            return head + data if head else data
        chunk = bytearray(len(head) + size)
        chunk[: len(head)] = head
        got = readinto(memoryview(chunk)[len(head) :])
        if not got:
            return None
        self._carry = b""
        del chunk[len(head) + got :]
        return chunk

    def _feed(self, chunk: bytes | bytearray) -> None:
        if b"\r" in chunk:
            chunk = chunk.replace(b"\r", b"\n")  # CRLF leaves an empty line: pyarrow skips it
        start = 0
        while self._dropping is not None:
            first = chunk.find(b"\n", start)
            if first < 0:
                self._hold(chunk[start:])
                return
            self._drop_more(chunk[start:first])
            self._end_drop()
            start = first + 1
        cut = chunk.rfind(b"\n") + 1
        if cut > start:
            self._emit(chunk, start, cut, more=True)
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
        if self._dropping == "header":
            self._header_left -= 1
        if self._dropping == "long" or self._header_left <= 0:
            self._dropping = None
        self._dropped, self._dropped_head = 0, b""

    def _report(self, line: bytes, size: int | None = None) -> None:
        text = line[:RAW_TEXT_CHARS].decode("utf-8", errors="replace")
        size = len(line) if size is None else size
        if size > RAW_TEXT_CHARS:
            text += f"... ({size:,} bytes)"
        self.on_malformed(text)

    def _emit(self, buf: bytes, a: int, b: int, more: bool = False) -> None:
        """Queue the whole lines buf[a:b], and a `HeaderLine` in place of each header among them;
        `more`: the stream goes on after them (a record may continue there)."""
        for start, end, header in self._headers_in(buf, a, b):
            self._queue(buf, a, start)
            self._ready.append(header)
            self.fields = len(header.names)
            a = end
        self._queue(buf, a, b, more)

    def _headers_in(self, buf: bytes, a: int, b: int) -> list[tuple[int, int, HeaderLine]]:
        """The header lines [start, end) of the whole lines buf[a:b] (see `HEADER_MARK`)."""
        if self.header_of is None:
            return []
        lines = set()
        for pos in _mark_offsets(buf, a, b):
            start = max(buf.rfind(b"\n", a, pos) + 1, a)
            end = buf.find(b"\n", pos, b)
            lines.add((start, b if end < 0 else end + 1))
        found = []
        for start, end in sorted(lines):
            line = bytes(buf[start:end]).rstrip(b"\n")
            names = self.header_of(line)
            if names is not None:
                text = line[:RAW_TEXT_CHARS].decode("utf-8", errors="replace")
                found.append((start, end, HeaderLine(names, text)))
        return found

    def _queue(self, buf: bytes, a: int, b: int, more: bool = False) -> None:
        """Queue the whole lines buf[a:b]: as a view when they need nothing, else cleaned (a
        record whose quoted field runs on past b, when `more` may come, held for it)."""
        if a >= b:
            return
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
            cleaned = self._clean(buf[a:b], more)
            if cleaned:  # (an empty block would read as the end of the file)
                self._ready.append(cleaned)

    def _clean(self, body: bytes, more: bool = False) -> bytes:
        """Whole lines (or the file's last, unended one) made safe for pyarrow; a `Multiline`
        where records span lines."""
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
            return self._records(body, _unterminated_spans(body, 0, len(body)), more)
        return body

    def _records(self, body: bytes, open_lines: list[tuple[int, int]], more: bool) -> bytes:
        """`body` with each line that ends inside a quoted field (`open_lines`) either kept as
        the start of a record spanning lines (`record_end`) or cut; a record that may go on
        past the body when `more` comes is held for it, with the lines after it."""
        cut, spanned, done = [], False, 0
        for start, end in open_lines:
            if start < done:  # a line of a record already kept
                continue
            record = record_end(body, start, self.fields)
            if record == RUNS_ON and more:
                self._carry = bytes(body[start:])
                body = body[:start]
                break
            if record > 0:
                spanned, done = True, record
            else:
                cut.append((start, end))
        body = self._cut(body, cut)
        return Multiline(body) if spanned else body

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


RUNS_ON = -1
"""`record_end`: the record's quoted field is still open where the buffer ends."""


def record_end(buf: bytes, start: int, fields: int | None) -> int:
    """The end (past its line end) of the record starting at `start` whose quoted field holds
    line ends, when it is valid CSV: each quote it opens closes before a comma or the line end,
    within `RECORD_LINES` lines, and it has `fields` fields; 0 when it is not (a stray quote),
    `RUNS_ON` when the buffer ends first."""
    if fields is None:
        return 0
    state, count, lines, i, n = 0, 1, 1, start, len(buf)
    while i < n:  # 0: field start, 1: unquoted field, 2: quoted, 3: just after a closing quote
        c = buf[i]
        if state == 2:
            if c == 34:
                if i + 1 == n:
                    return RUNS_ON
                if buf[i + 1] == 34:
                    i += 1
                else:
                    state = 3
            elif c == 10:
                lines += 1
                if lines > RECORD_LINES:
                    return 0
        elif c == 10:
            return i + 1 if count == fields else 0
        elif c == 44:
            state, count = 0, count + 1
        elif state == 3:
            return 0
        elif state == 0:
            state = 2 if c == 34 else 1
        i += 1
    return RUNS_ON if state == 2 else 0


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


def _found(
    kernel: Callable[[np.ndarray, np.ndarray], int], buf: bytes | memoryview, a: int, b: int
) -> np.ndarray:
    """Every offset into buf[a:b] that a compiled `kernel(bytes, out) -> how many` finds, however
    many there are (it fills `out` as far as it reaches)."""
    view = np.frombuffer(buf, np.uint8, count=b - a, offset=a)
    view.flags.writeable = False  # (a chunk read into a bytearray: one compiled kernel, not two)
    out = np.empty(64, np.int64)
    found = kernel(view, out)
    if found > len(out):
        out = np.empty(found, np.int64)
        kernel(view, out)
    return out[:found]


def _scan_unterminated(buf: bytes, a: int, b: int) -> list[tuple[int, int]]:
    spans = []
    for s in _found(_unterminated_lines, buf, a, b):
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


def _mark_offsets(buf: bytes | memoryview, a: int, b: int) -> list[int]:
    """Where `HEADER_MARK` starts in buf[a:b], in any case."""
    return [a + int(k) for k in _found(_marks, buf, a, b)]


@numba.njit(nogil=True, cache=True)
def _marks(buf: np.ndarray, out: np.ndarray) -> int:  # pragma: no cover - compiled
    """Offsets (into `out`, as many as fit, in order) of `mmsi` in `buf` in any case, and how
    many. Eight bytes at a time (`_mark_ends`); a first pass only counts the words where a mark
    ends, which the compiler vectorises (0.1 s per GB, where a byte at a time took 0.65 s, a
    third of the reading thread's time), and only a block that has some is passed again to
    find them."""
    n = buf.shape[0]
    whole = n - n % 8
    words = buf[:whole].view(np.uint64)  # the words, without a copy (4 MiB of zeros cost more)
    tail = np.uint64(0)  # the last bytes, as a word ending in zero bytes (no letter)
    for q in range(whole, n):
        tail |= np.uint64(buf[q]) << np.uint64(8 * (q - whole))
    hits = 0
    prev_m = prev_s = np.uint64(0)
    for j in range(words.shape[0]):
        ends, prev_m, prev_s = _mark_ends(words[j], prev_m, prev_s)
        hits += ends != 0
    ends, prev_m, prev_s = _mark_ends(tail, prev_m, prev_s)
    if hits == 0 and ends == 0:
        return 0
    found = 0
    prev_m = prev_s = np.uint64(0)
    for j in range(words.shape[0] + 1):
        word = words[j] if j < words.shape[0] else tail
        ends, prev_m, prev_s = _mark_ends(word, prev_m, prev_s)
        for k in range(8):
            if (ends >> np.uint64(8 * k + 7)) & np.uint64(1):
                if found < out.shape[0]:
                    out[found] = 8 * j + k - 3
                found += 1
    return found


_LOWER = each(0x20)
_M, _S, _I = each(ord("m")), each(ord("s")), each(ord("i"))


@numba.njit(nogil=True, cache=True, inline="always")
def _mark_ends(word, prev_m, prev_s):  # pragma: no cover - compiled
    """The mask of the bytes of `word` where `mmsi` (any case) ends, and the word's masks of `m`
    and `s` for the next word (`prev_m`, `prev_s`: the previous word's)."""
    word |= _LOWER
    m, s = equal(word, _M), equal(word, _S)
    ends = (
        equal(word, _I)
        & ((s << np.uint64(8)) | (prev_s >> np.uint64(56)))
        & ((m << np.uint64(16)) | (prev_m >> np.uint64(48)))
        & ((m << np.uint64(24)) | (prev_m >> np.uint64(40)))
    )
    return ends, m, s


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
