"""The fast path of CSV reading: the needed columns of plain rows parsed straight into numbers.

pyarrow's CSV reader tokenises every column of a MarineCadastre row (17 of them) and hands the six
we need on as text, which `convert.to_canonical` then parses again: about 5 s of one core for 10
million rows. Nearly every real row is plain: the header's number of fields, no quote but around a
whole field (`"..."`, as pyarrow's and pandas' writers quote text; a quote doubled within it, as
in MarineCadastre's `"RAY ""CHIEF"" TONEY"`, is one quote of its text), the MMSI digits, the time
`YYYY-MM-DDTHH:MM:SS` (or with a space), the numbers `-?digits[.digits]`. Those
are parsed here in one compiled pass over the block (`scan_block`, which releases the GIL, so
blocks are parsed on threads); every other row (a blank or odd value, a quote, a wrong number
of fields) is marked and read the usual way (`read.SourceReader`), so it is counted and rejected,
or read, exactly as before.

The values are those the usual way gives, bit for bit: a number whose digits make an integer below
2**53 (15 digits always, 16 mostly: a float's full repr often has them) is that integer (exact in
a float64) divided by a power of ten (exact up to 10^22), and IEEE division rounds that exact
quotient correctly, as Arrow's parser rounds the text.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import pyarrow as pa

from aisdati.preprocess.bytewords import HIGH, below_first, count, each, equal, word_at
from aisdati.preprocess.layouts import STATIC

MMSI, TIME, FIRST_NUMBER = 0, 1, 2
"""Output slots of the MMSI and time columns (and their rows of `ints`); slots from
`FIRST_NUMBER` on are the number columns."""
KEY = 2
"""The row of `ints` that holds each row's static hash (`ParsedBlock.keys`)."""
NOT_READ, STATIC_SLOT = -1, -2
"""Slots of a field that is not read, and of one that is hashed (`STATIC`)."""
NUMBERS = ("lat", "lon", "sog", "cog", "heading", "status")
OPTIONAL_NUMBERS = frozenset({"heading", "status"})
"""Number columns whose blank is a value (none), not an odd row."""
HASH_SEED = np.int64(0x1F2E3D4C5B6A7988)
HASH_PRIME = np.int64(1099511628211)
"""FNV-1a's prime, in wrapping int64 arithmetic (the hash of `KEY`)."""
MAX_DIGITS = 18
"""Digits of a number read here (an int64 holds them); its digits as an integer must also be at
most `EXACT` (below 2**53: exact as a float64), or it goes the usual way."""
EXACT = 2**53
MAX_MMSI_DIGITS = 18
"""As `convert.MAX_MMSI_DIGITS`: longer MMSIs are rejected the usual way."""
POW10 = np.array([10.0**k for k in range(MAX_DIGITS + 1)])
DELIMITER = np.zeros(256, np.uint8)
"""What ends a field's scan: 1 a comma, 2 a line end, 3 a quote."""
DELIMITER[44], DELIMITER[10], DELIMITER[34] = 1, 2, 3
TYPICAL_ROW_BYTES = 24
"""The outputs are first sized for rows of this many bytes or more (a MarineCadastre row takes
about 100, six bare columns about 50): sizing them for the worst case, two bytes a row, mapped
130 MB per 4 MiB block, and the kernel's page faults doubled the read's system time."""
MONTH_DAYS = np.array([0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31], np.int64)


@dataclass(frozen=True)
class ColumnSlots:
    """Which field of a row goes where: `slots[i]` is the output slot of field i (-1: not read),
    for a header of `len(slots)` fields."""

    slots: np.ndarray
    numbers: tuple[str, ...]
    """The number columns present (canonical names), in slot order from 2."""
    optional: np.ndarray
    """Per number column, whether a blank is none (`OPTIONAL_NUMBERS`)."""

    @classmethod
    def of(cls, names: list[str], columns: dict[str, str]) -> ColumnSlots | None:
        """The slots of a header, or None where the header names a needed column twice (the
        usual way decides which)."""
        numbers = tuple(c for c in NUMBERS if c in columns)
        wanted = {"mmsi": MMSI, "time": TIME} | {c: FIRST_NUMBER + i for i, c in enumerate(numbers)}
        wanted |= {c: STATIC_SLOT for c in STATIC if c in columns}
        slots = np.full(len(names), NOT_READ, np.int64)
        for canonical, slot in wanted.items():
            at = [i for i, name in enumerate(names) if name == columns[canonical]]
            if len(at) != 1:
                return None
            slots[at[0]] = slot
        return cls(slots, numbers, np.array([c in OPTIONAL_NUMBERS for c in numbers]))


@dataclass(frozen=True)
class ParsedBlock:
    """The rows of one block: values of the plain ones; the others marked `slow`, with their
    lines' spans in the block (`line_start`, `line_end`, the newline excluded)."""

    mmsi: np.ndarray
    time_us: np.ndarray
    numbers: np.ndarray
    """[len(ColumnSlots.numbers), rows] float64."""
    keys: np.ndarray
    """A hash of each row's MMSI and static fields, 0 where those are all blank."""
    slow: np.ndarray
    line_start: np.ndarray
    line_end: np.ndarray

    @property
    def rows(self) -> int:
        return len(self.slow)

    def static_tally(self, time_us: np.ndarray) -> tuple[np.ndarray, ...]:
        """The distinct static hashes of the plain rows (0 aside), sorted (the tally looks them
        up among those it knows in one sweep), how many rows have each, the last of them, and
        the earliest and latest of their times `time_us` (microseconds; the int64 minimum:
        none; `NO_FIRST`/`NO_LAST` where no row has one)."""
        keys, counts, last, first_us, last_us = tally_keys(self.keys, self.slow, time_us)
        order = np.argsort(keys)
        return keys[order], counts[order], last[order], first_us[order], last_us[order]

    def lines(self, block: bytes | memoryview, rows: np.ndarray) -> bytes:
        """The text of these rows of `block` (parsed into this), each ended by a line end."""
        starts, ends = self.line_start[rows], self.line_end[rows]
        sizes = ends - starts + 1
        at = np.r_[0, np.cumsum(sizes)]
        index = np.arange(at[-1]) - np.repeat(at[:-1] - starts, sizes)
        index[at[1:] - 1] = 0  # where each line end goes
        text = np.frombuffer(block, np.uint8)[index]
        text[at[1:] - 1] = 10
        return text.tobytes()


def parse_block(block: bytes | memoryview, slots: ColumnSlots) -> ParsedBlock:
    """Parse whole lines (the last one may lack its line end); blank lines are no rows."""
    if len(block) and block[-1] != 10:  # the file's last line, unended: the scan needs an end
        block = bytes(block) + b"\n"
    buf = np.frombuffer(block, np.uint8)
    buf.flags.writeable = False  # (a chunk read into a bytearray: one compiled kernel, not two)
    for cap in (len(buf) // TYPICAL_ROW_BYTES + 1, len(buf) // 2 + 1):  # every row takes 2 or more
        ints = np.empty((3, cap), np.int64)
        numbers = np.empty((len(slots.numbers), cap), np.float64)
        slow = np.empty(cap, np.bool_)
        spans = np.empty((2, cap), np.int64)
        rows = scan_block(buf, slots.slots, slots.optional, ints, numbers, slow, spans)
        if rows >= 0:
            break
    return ParsedBlock(
        ints[MMSI, :rows],
        ints[TIME, :rows],
        numbers[:, :rows],
        ints[KEY, :rows],
        slow[:rows],
        spans[0, :rows],
        spans[1, :rows],
    )


def typed_batch(parsed: ParsedBlock, slots: ColumnSlots, names: dict[str, str]) -> pa.RecordBatch:
    """The block's rows (parsed with `slots`) as a record batch of typed columns under the
    source's names (`names`: canonical -> name), which `convert.to_canonical` reads like a typed
    parquet's."""
    columns = {
        names["mmsi"]: pa.array(parsed.mmsi),
        names["time"]: pa.array(parsed.time_us).view(pa.timestamp("us")),
    }
    for i, canonical in enumerate(slots.numbers):
        columns[names[canonical]] = pa.array(parsed.numbers[i])
    return pa.record_batch(list(columns.values()), names=list(columns))


@numba.njit(nogil=True, cache=True)
def scan_block(buf, slots, optional, ints, numbers, slow, spans):  # pragma: no cover - compiled
    """Rows of `buf` into the outputs (see `parse_block`); returns how many rows there were, or
    -1 where there were more than the outputs hold."""
    n = buf.shape[0]
    n_fields = slots.shape[0]
    words = buf[: n - n % 8].view(np.uint64)
    needed_until = _needed_until(slots)  # fields from here on are not read: `_skip_fields`
    row, i = 0, 0
    date_at, date_days = -1, np.int64(0)  # the last date parsed: most rows share it
    cap = slow.shape[0]
    while i < n:
        if buf[i] == 10:  # a blank line: no row (as pyarrow skips it)
            i += 1
            continue
        if row == cap:
            return -1  # more rows than the outputs hold: the caller sizes them for more
        line, field, bad = i, 0, False
        static, any_static = HASH_SEED, False
        while True:
            # the values are read and stored here, not in a helper: one handed the outputs made
            # the scan 2.1 times as slow, one returning the values 1.3 times (issue 58)
            slot = slots[field] if field < n_fields else NOT_READ
            end = -1  # the field's end, once a value read in passing found it
            if slot == TIME:  # `YYYY-MM-DDTHH:MM:SS` then a delimiter: no scan for the end
                if i + 19 < n and 0 < DELIMITER[buf[i + 19]] < 3:
                    value, date_at, date_days = _time_us(buf, i, i + 19, date_at, date_days)
                    if value != _NO_TIME:  # (its 19 bytes checked: no delimiter among them)
                        ints[TIME, row] = value
                        start, end, i, kind = i, i + 19, i + 19, DELIMITER[buf[i + 19]]
            elif slot == MMSI or slot >= FIRST_NUMBER:  # read while the end is sought
                j, mantissa, digits, decimals = _leading_number(buf, i, slot == MMSI)
                if 0 < DELIMITER[buf[j]] < 3:  # the field ended with the number
                    start, end, kind = i, j, DELIMITER[buf[j]]
                    i = j
                    if slot == MMSI:
                        value = mantissa if 0 < digits <= MAX_MMSI_DIGITS else np.int64(0)
                        bad |= value <= 0
                        ints[MMSI, row] = value
                    else:
                        number = _number_of(buf[start] == 45, mantissa, digits, decimals)
                        k = slot - FIRST_NUMBER
                        bad |= np.isnan(number) and not (optional[k] and end == start)
                        numbers[k, row] = number
            if end < 0:  # any other field, or a value in an odd form: scanned, then read
                # (a static field is hashed as written: its doubled quotes need no unquoting)
                start, end, i, kind, odd = _field_at(buf, i, slot >= 0)
                bad |= odd
                if slot == MMSI:
                    value = _digits(buf, start, end)
                    bad |= value <= 0
                    ints[MMSI, row] = value
                elif slot == TIME:
                    value, date_at, date_days = _time_us(buf, start, end, date_at, date_days)
                    bad |= value == _NO_TIME
                    ints[TIME, row] = value
                elif slot >= FIRST_NUMBER:
                    number = _number(buf, start, end)
                    k = slot - FIRST_NUMBER
                    bad |= np.isnan(number) and not (optional[k] and end == start)
                    numbers[k, row] = number
                elif slot == STATIC_SLOT:
                    static = _hashed(buf, start, end, static)
                    any_static |= end > start
            field += 1
            if kind == 2:
                break
            i += 1
            if field >= needed_until:
                i, commas, ended = _skip_fields(buf, words, i)
                field += commas
                if ended:
                    field += 1
                    break
        slow[row] = bad or field != n_fields
        ints[KEY, row] = _row_key(static, ints[MMSI, row]) if any_static else 0
        spans[0, row], spans[1, row] = line, i
        row += 1
        i += 1
    return row


_NO_TIME = np.int64(-(2**62))


@numba.njit(nogil=True, cache=True, inline="always")
def _needed_until(slots):  # pragma: no cover - compiled
    """The number of a row's fields up to its last one that is read: `scan_block` passes over
    the fields from there on (`_skip_fields`)."""
    needed_until = 0
    for k in range(slots.shape[0]):
        if slots[k] != NOT_READ:
            needed_until = k + 1
    return needed_until


@numba.njit(nogil=True, cache=True, inline="always")
def _hashed(buf, start, end, h):  # pragma: no cover - compiled
    """The hash `h` of the fields so far, with the field [start, end) and its end mixed in."""
    for k in range(start, end):
        h = (h ^ np.int64(buf[k])) * HASH_PRIME
    return (h ^ np.int64(256)) * HASH_PRIME  # (a field's end is no byte)


@numba.njit(nogil=True, cache=True, inline="always")
def _row_key(static, mmsi):  # pragma: no cover - compiled
    """A row's `KEY`: its static fields' hash with its MMSI mixed in, never 0."""
    h = (static ^ mmsi) * HASH_PRIME
    h ^= h >> 29
    return h if h != 0 else np.int64(1)


@numba.njit(nogil=True, cache=True)
def tally_keys(keys, slow, time_us):  # pragma: no cover - compiled
    """The distinct nonzero `keys` of the rows that are not `slow`, in the order first met,
    with the rows that have each, the last such row, and their earliest and latest time: one
    pass over an open-addressing
    table (a sort of the block's keys took 5 times as long)."""
    n = keys.shape[0]
    size = 16
    while size < 2 * n:
        size *= 2
    where = np.full(size, -1, np.int64)
    found = np.empty(n, np.int64)
    counts = np.zeros(n, np.int64)
    last = np.empty(n, np.int64)
    none = np.iinfo(np.int64).min
    first_us = np.full(n, np.iinfo(np.int64).max)
    last_us = np.full(n, none)
    m = 0
    for i in range(n):
        key = keys[i]
        if slow[i] or key == 0:
            continue
        h = (key ^ (key >> 31)) & (size - 1)
        while where[h] >= 0 and found[where[h]] != key:
            h = (h + 1) & (size - 1)
        if where[h] < 0:
            where[h] = m
            found[m] = key
            m += 1
        counts[where[h]] += 1
        last[where[h]] = i
        if time_us[i] != none:
            first_us[where[h]] = min(first_us[where[h]], time_us[i])
            last_us[where[h]] = max(last_us[where[h]], time_us[i])
    return found[:m], counts[:m], last[:m], first_us[:m], last_us[:m]


@numba.njit(nogil=True, cache=True, inline="always")
def _field_at(buf, i, needed):  # pragma: no cover - compiled
    """The field starting at `i` (`needed`: its value is read): (the start and end of its
    text, where its delimiter is, that delimiter's kind (1 a comma, 2 a line end), whether the
    usual way must read the row: a quote inside the field, or a doubled one inside a needed
    value's quotes)."""
    start = i
    end = -1
    bad = False
    kind = DELIMITER[buf[i]]
    if kind == 3:  # a quoted field: its text, where a doubled quote is one quote
        j, after, doubled = _quoted_field(buf, i)
        if after == 1 or after == 2:
            start, end, i, kind = i + 1, j, j + 1, after
            # a needed value's text would have to be unquoted: the usual way does it
            bad = doubled and needed
    while True:
        while kind == 0:  # (the block ends with a line end)
            i += 1
            kind = DELIMITER[buf[i]]
        if kind != 3:
            break
        bad = True  # a quote inside a field: the usual parser's dialect decides
        i += 1
        kind = DELIMITER[buf[i]]
    if end < 0:
        end = i
    return start, end, i, kind, bad


@numba.njit(nogil=True, cache=True, inline="always")
def _time_us(buf, start, end, date_at, date_days):  # pragma: no cover - compiled
    """The time [start, end) in microseconds since 1970, else `_NO_TIME` (the usual way
    decides), its date parsed only where it differs from the last one parsed (at `date_at`,
    -1: none; `date_days` days): (the time, where the last date parsed is, its days)."""
    if date_at < 0 or end - start != 19 or not _same(buf, date_at, start, 11):
        date_days = _days(buf, start, end)
        date_at = start if date_days != _NO_TIME else -1
    value = _clock_us(buf, start, date_days) if date_at >= 0 else _NO_TIME
    return value, date_at, date_days


@numba.njit(nogil=True, cache=True, inline="always")
def _quoted_field(buf, i):  # pragma: no cover - compiled
    """The field whose opening quote is at `i`: (where its closing quote or the line end is, the
    kind of delimiter right after that quote (0: something else follows), whether a doubled
    quote is inside)."""
    j = i + 1
    doubled = False
    while True:
        while buf[j] != 34 and buf[j] != 10:  # (commas are text here)
            j += 1
        if buf[j] != 34 or buf[j + 1] != 34:
            break
        doubled = True
        j += 2
    return j, DELIMITER[buf[j + 1]] if buf[j] == 34 else 0, doubled


_COMMAS, _LINE_ENDS, _QUOTES = each(44), each(10), each(34)


@numba.njit(nogil=True, cache=True, inline="always")
def _skip_fields(buf, words, i):  # pragma: no cover - compiled
    """From the start of a field that is not read, past the fields up to the line end or a quote:
    (where it stopped, the commas passed, whether it stopped at the line end, not at the start of
    the field that holds a quote). The eleven columns a MarineCadastre row has after COG took
    half the parse a byte at a time; here eight bytes at a time, without a branch per byte:
    the masks of the commas and of the stops (a line end, a quote) in the eight bytes at `i`,
    the commas below the first stop counted, and `i` moved to it (by 8 where there is none)."""
    begin = i
    commas = 0
    while i + 16 <= buf.shape[0]:
        word = word_at(words, i)
        stops = equal(word, _LINE_ENDS) | equal(word, _QUOTES)
        comma = equal(word, _COMMAS)
        if stops:  # (the next `i` waits on no load: the processor runs ahead to it)
            below = below_first(stops)
            commas += count(comma & below)
            i += count(below & HIGH)
            break
        commas += count(comma)
        i += 8
    while buf[i] != 10 and buf[i] != 34:  # the block's last bytes (it ends with a line end)
        commas += buf[i] == 44
        i += 1
    if buf[i] == 10:
        return i, commas, True
    while i > begin and buf[i - 1] != 44:  # back to the start of the quote's field
        i -= 1
    return i, commas, False


@numba.njit(nogil=True, cache=True, inline="always")
def _digits(buf, a, b):  # pragma: no cover - compiled
    """The MMSI written as 1-18 digits, else 0 (the usual way decides)."""
    if b <= a or b - a > MAX_MMSI_DIGITS:
        return np.int64(0)
    value = np.int64(0)
    for k in range(a, b):
        d = np.int64(buf[k]) - 48
        if d < 0 or d > 9:
            return np.int64(0)
        value = value * 10 + d
    return value


@numba.njit(nogil=True, cache=True, inline="always")
def _number(buf, a, b):  # pragma: no cover - compiled
    """`-?digits(.digits)?` whose digits make an integer of at most `EXACT`, else NaN (the usual
    way decides)."""
    negative = a < b and buf[a] == 45
    if negative:
        a += 1
    mantissa = np.int64(0)
    digits = 0
    decimals = -1  # digits after the point; -1: no point yet
    for k in range(a, b):
        c = buf[k]
        if c == 46 and decimals < 0 and digits > 0:
            decimals = 0
            continue
        d = np.int64(c) - 48
        if d < 0 or d > 9:
            return np.nan
        mantissa = mantissa * 10 + d
        digits += 1
        if decimals >= 0:
            decimals += 1
    if digits == 0 or decimals == 0 or digits > MAX_DIGITS or mantissa > EXACT:
        return np.nan
    value = np.float64(mantissa) / POW10[max(decimals, 0)]
    return -value if negative else value


@numba.njit(nogil=True, cache=True, inline="always")
def _leading_number(buf, i, unsigned):  # pragma: no cover - compiled
    """The number `-?digits(.digits)?` (`unsigned`: digits only) that starts at `i`, read up to
    the first byte that cannot continue it: (where that byte is, the digits as an integer, how
    many there are, how many follow the point, -1: no point). Where that byte ends the field,
    this is the field's value (`_number_of`), as `_number` reads it."""
    j = i
    if not unsigned and buf[j] == 45:
        j += 1
    mantissa = np.int64(0)
    digits = 0
    decimals = -1
    while True:
        d = np.int64(buf[j]) - 48
        if 0 <= d <= 9:
            if digits < MAX_DIGITS:  # (more: no value either way; no overflow)
                mantissa = mantissa * 10 + d
            digits += 1
            if decimals >= 0:
                decimals += 1
        elif d == -2 and decimals < 0 and digits > 0 and not unsigned:  # the point
            decimals = 0
        else:
            return j, mantissa, digits, decimals
        j += 1


@numba.njit(nogil=True, cache=True, inline="always")
def _number_of(negative, mantissa, digits, decimals):  # pragma: no cover - compiled
    """The value `_number` gives the text `_leading_number` read (NaN: the usual way decides)."""
    if digits == 0 or decimals == 0 or digits > MAX_DIGITS or mantissa > EXACT:
        return np.nan
    value = np.float64(mantissa) / POW10[max(decimals, 0)]
    return -value if negative else value


@numba.njit(nogil=True, cache=True, inline="always")
def _two(buf, k):  # pragma: no cover - compiled
    hi, lo = np.int64(buf[k]) - 48, np.int64(buf[k + 1]) - 48
    return -1 if hi < 0 or hi > 9 or lo < 0 or lo > 9 else hi * 10 + lo


@numba.njit(nogil=True, cache=True, inline="always")
def _same(buf, a, b, length):  # pragma: no cover - compiled
    for k in range(length):  # noqa: SIM110 - numba compiles loops, not generators
        if buf[a + k] != buf[b + k]:
            return False
    return True


@numba.njit(nogil=True, cache=True)
def _days(buf, a, b):  # pragma: no cover - compiled
    """The days since 1970 of a time `YYYY-MM-DDTHH:MM:SS` (or a space for the T), else
    `_NO_TIME` (the usual way decides)."""
    if b - a != 19 or buf[a + 4] != 45 or buf[a + 7] != 45 or buf[a + 13] != 58:
        return _NO_TIME
    if buf[a + 16] != 58 or (buf[a + 10] != 84 and buf[a + 10] != 32):
        return _NO_TIME
    century, yy = _two(buf, a), _two(buf, a + 2)
    month, day = _two(buf, a + 5), _two(buf, a + 8)
    if century < 0 or yy < 0 or month < 1 or month > 12 or day < 1:
        return _NO_TIME
    year = century * 100 + yy
    leap = year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)
    if day > MONTH_DAYS[month] + (1 if month == 2 and leap else 0):
        return _NO_TIME
    # Howard Hinnant's days_from_civil
    y = year - (1 if month <= 2 else 0)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * (month + (-3 if month > 2 else 9)) + 2) // 5 + day - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return np.int64(era * 146097 + doe - 719468)


@numba.njit(nogil=True, cache=True, inline="always")
def _clock_us(buf, a, days):  # pragma: no cover - compiled
    """Microseconds since 1970 of the time at `a` whose date (and form) `_days` checked, else
    `_NO_TIME`."""
    if buf[a + 13] != 58 or buf[a + 16] != 58:
        return _NO_TIME
    hour, minute, second = _two(buf, a + 11), _two(buf, a + 14), _two(buf, a + 17)
    if hour < 0 or hour > 23 or minute < 0 or minute > 59 or second < 0 or second > 59:
        return _NO_TIME
    return np.int64(((days * 24 + hour) * 60 + minute) * 60 + second) * 1_000_000
