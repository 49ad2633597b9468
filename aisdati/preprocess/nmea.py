"""NMEA 0183 logs of AIS receivers (`!AIVDM` / `!AIVDO` sentences), read as the frame a
MarineCadastre CSV gives: `MMSI, BaseDateTime, LAT, LON, SOG, COG, Heading, Status`.

Sentences are parsed and decoded with pyais; messages of several sentences are reassembled. Only
position reports become rows (types 1-3 class A, 18-19 class B, 27 long range; the navigational
status of types 1-3 and 27, the heading of all but 27). Static messages (types 5 and 24, and the
class B extended report 19) tell who a vessel is: their name, ship type and length go into the
reader's vessel tally (`vessels.VesselTally`), joined to the rows by MMSI. Each message needs
a time, which receivers log in one of four ways:

* an NMEA 4.0 tag block before the sentence, `\\c:1606780800,s:r1*hh\\!AIVDM,...` (seconds, or
  milliseconds, since 1970; the tag block's own checksum is not checked, as pyais does not);
* a timestamp column before the sentence, `2020-12-01T00:00:00Z,!AIVDM,...` or
  `1606780800.25 !AIVDM,...` (ISO 8601, UTC when no zone is given, or seconds since 1970);
* the same after the sentence's checksum, `!AIVDM,...*hh,1530428400` (several receivers' logs);
* a Gatehouse `$PGHP,1,<year>,<month>,<day>,<h>,<m>,<s>,<ms>,...` sentence on the line before.

The times are handed on as the text they were written in, for `convert.time_us` to parse like
any CSV's. AIS's 'not available' values stay the values the cleaner rejects by name (LAT 91,
LON 181, SOG 102.3, COG 360; type 27's SOG 63 and COG 511 become 102.3 and 360), and heading 511
becomes a missing value. Every line that gives no row is counted under one reason: `not_ais`,
`bad_checksum`, `truncated` (cut short, empty, or a multi-sentence message with parts missing),
`not_position`, `no_time` or `duplicate_reception`; blank lines and `#` comments are not rows.

A log merged from several receivers holds each message they all heard once per receiver: the
first copy read is the report, the others (the same payload within `RECEPTION_WINDOW_S`) are
counted as `duplicate_reception`, so that copies neither double a track's points nor let short
pieces pass `--min-points`.
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from itertools import islice
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa
from pyais.exceptions import AISBaseException, UnknownMessageException
from pyais.messages import AISSentence, GatehouseSentence, NMEASentence, NMEASentenceFactory

from aisdati.errors import UserError
from aisdati.preprocess import position_sentences
from aisdati.preprocess.clean import SENTINEL_COG, SENTINEL_SOG
from aisdati.preprocess.convert import EPOCH_UNITS, canonical_tables, time_us
from aisdati.preprocess.inputs import (
    AIS_SENTENCE,
    SNIFF_BYTES,
    Source,
    describe_read_error,
    looks_like_nmea,
)
from aisdati.preprocess.lineguard import shorten
from aisdati.preprocess.streams import READ_ERRORS, ByteStream, CountingReader
from aisdati.preprocess.vessels import VesselTally

COLUMNS = {
    "mmsi": "MMSI",
    "time": "BaseDateTime",
    "lat": "LAT",
    "lon": "LON",
    "sog": "SOG",
    "cog": "COG",
    "heading": "Heading",
    "status": "Status",
}
"""Canonical column -> the frame's (MarineCadastre's) name."""
FRAME_SCHEMA = pa.schema(
    [
        ("MMSI", pa.int64()),
        ("BaseDateTime", pa.string()),
        ("LAT", pa.float64()),
        ("LON", pa.float64()),
        ("SOG", pa.float64()),
        ("COG", pa.float64()),
        ("Heading", pa.int16()),
        ("Status", pa.int16()),
    ]
)
POSITION_TYPES = frozenset({1, 2, 3, 18, 19, 27})
STATIC_TYPES = frozenset({5, 19, 24})
"""Messages that give a vessel's name, ship type or dimensions."""
REASONS = ("not_ais", "bad_checksum", "truncated", "not_position", "no_time")
"""Why a line gives no row (`report.REASONS` describes them)."""
DUPLICATE_RECEPTION = "duplicate_reception"
"""The reason of a copy of a message already read (another receiver's): listed among the skipped
lines once a log has one, as a log of one receiver has none."""
RECEPTION_WINDOW_S = 30.0
"""Seconds within which the same payload is one message heard again, by another receiver or
through another feed. In the DMA's recordings (three receivers, 2014) 99% of the copies come
within 2 s of the first and the slowest 16.5 s after it. A vessel's next report cannot repeat the
payload that soon: the payload holds the MMSI, the fix's UTC second (the same one only a minute
later) and the radio's slot state, so only a vessel standing still without a second could, and
then the copy dropped repeats its position."""
EPOCH = datetime(1970, 1, 1, tzinfo=timezone.utc)
MAX_RECENT_MESSAGES = 1 << 18
"""The most payloads remembered to spot copies (about 50 MB): a feed of the whole world brings
some 5,000 messages a second, 150,000 within `RECEPTION_WINDOW_S`."""
HEADING_NOT_AVAILABLE = 511
LONG_RANGE_SOG_NOT_AVAILABLE = 63
LONG_RANGE_COG_NOT_AVAILABLE = 511
BATCH_MESSAGES = 1 << 16
"""Position reports per record batch (give or take `LINES_AT_ONCE`)."""
LINES_AT_ONCE = 4096
"""Lines decoded together (`NmeaDecoder.feed_lines`)."""
MAX_LINE_BYTES = 4096
"""An NMEA sentence has at most 82 characters, a tag block a few dozen: a longer line is none."""
MAX_KEPT_TEXT = 1 << 26
"""Characters of skipped lines kept for rejects.parquet; past this only their count is kept (a
log without times would otherwise hold all its lines in memory)."""
SENTENCE_START = re.compile(rb"[!$\\]")
STAMP_SEPARATORS = b" \t,;[]"
TRAILING_STAMP = re.compile(rb"\*[0-9A-Fa-f]{2}[ \t,;]+([^*!$\\]+)$")
"""A time after a sentence's checksum, `*hh,1530428400`: the group is the time."""


class SkippedLines:
    """The lines that gave no row: their text by reason, within `MAX_KEPT_TEXT` characters."""

    def __init__(self) -> None:
        self.by_reason: dict[str, list[str | None]] = {reason: [] for reason in REASONS}
        self._kept = 0

    def add(self, reason: str, line: bytes) -> None:
        text = None
        if self._kept < MAX_KEPT_TEXT:
            text = shorten(line.decode("ascii", errors="replace"))
            self._kept += len(text)
        self.by_reason.setdefault(reason, []).append(text)  # DUPLICATE_RECEPTION, once met


class RecentMessages:
    """The messages read lately, by payload (which holds the MMSI), with the time of the copy
    kept: tells another receiver's copy of a message from a new report. Entries leave twice
    `RECEPTION_WINDOW_S` after the times of the messages read since (a merged log is only
    roughly in time order), or when more than `MAX_RECENT_MESSAGES` are held."""

    def __init__(self, window_s: float = RECEPTION_WINDOW_S) -> None:
        self.window_us = round(window_s * 1e6)
        self._kept: dict[bytes, int] = {}  # payload -> microseconds of the copy kept
        self._order: deque[tuple[int, bytes]] = deque()

    def heard(self, payload: bytes, time: str) -> bool:
        """Whether `payload` at `time` is a copy of a message kept within the window, at another
        time (else it is kept now). A copy at the very time of the kept one stays a row: the
        vessel stage counts it as an exact `duplicate`, as it does a CSV's repeated row. A time
        Python cannot read makes no copy: the row goes on to the time check."""
        return self.heard_at(payload, _time_us(time))

    def heard_at(self, payload: bytes, us: int | None) -> bool:
        """`heard` with the time already read (microseconds; None: unreadable)."""
        if us is None:
            return False
        self._forget(us - 2 * self.window_us)
        kept = self._kept.get(payload)
        if kept is not None and abs(us - kept) <= self.window_us:
            return us != kept
        self._kept[payload] = us
        self._order.append((us, payload))
        return False

    def _forget(self, before: int) -> None:
        """Drop the messages kept before `before` (microseconds), and the oldest past the
        bound."""
        order, kept = self._order, self._kept
        while order and (order[0][0] < before or len(order) > MAX_RECENT_MESSAGES):
            us, payload = order.popleft()
            if kept.get(payload) == us:  # not kept again since
                del kept[payload]


def _time_us(text: str) -> int | None:
    """Microseconds since 1970 of a time as `convert.time_us` reads it: a number in the unit
    its size gives (`EPOCH_UNITS`), or ISO 8601 (UTC when no zone is given); None when
    unreadable."""
    try:
        number = float(text)
    except ValueError:
        return _iso_us(text)
    if not math.isfinite(number):
        return None
    _, mul, div = next(unit for unit in EPOCH_UNITS if abs(number) < unit[0])
    return round(number * (mul / div))


def _iso_us(text: str) -> int | None:
    """Microseconds since 1970 of an ISO 8601 time (UTC when no zone is given), or None."""
    try:
        when = datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith("Z") else text)
    except ValueError:
        return None
    when = when if when.tzinfo else when.replace(tzinfo=timezone.utc)
    return (when - EPOCH) // timedelta(microseconds=1)


@dataclass
class Part:
    """One sentence of a message, with the time its line gave (if any) and the line itself."""

    sentence: AISSentence
    time: str | None
    line: bytes


class Static(NamedTuple):
    """A static message: the vessel it names, its name, ship-type code and length (None where
    it gives none), and the time of its line (None: none)."""

    mmsi: int
    name: str | None
    ship_type: int | None
    length: int | None
    time: str | None


def static_times_us(times: Sequence[str | None]) -> np.ndarray:
    """Static messages' times (as their lines give them, like the rows' `BaseDateTime`) in
    microseconds since the epoch; the int64 minimum where none."""
    us, bad = time_us(pa.array(times, pa.string()))
    return np.where(bad, np.iinfo(np.int64).min, us)


class NmeaDecoder:
    """Lines in; position rows (taken as record batches of `FRAME_SCHEMA`) and skipped lines
    (handed to `skip` with their reason) out. With `recent`, a copy of a message already read
    (another receiver's) is skipped as `DUPLICATE_RECEPTION`; without, every copy is a row."""

    def __init__(
        self, skip: Callable[[str, bytes], None], recent: RecentMessages | None = None
    ) -> None:
        self.skip = skip
        self.recent = recent
        self.statics: list[Static] = []
        """Each static message decoded since the last `take_statics`."""
        self._rows: list[tuple] = []
        self._gatehouse: str | None = None  # the time of the last $PGHP, for the next sentence
        self._parts: dict[tuple, list[Part]] = {}  # unfinished messages by their stream

    @property
    def pending_rows(self) -> int:
        return len(self._rows)

    def feed_lines(self, lines: list[bytes]) -> None:
        """Lines of the log (without their line ends), in order: those of the common shape
        decoded together (`position_sentences`: the same rows as pyais, many times faster),
        the others one by one (`feed`)."""
        lines = [line.strip() for line in lines]
        fast = position_sentences.decode(lines)
        heading = [None if h < 0 else h for h in fast.heading.tolist()]
        rows = zip(
            fast.mmsi.tolist(), fast.time, fast.lat.tolist(), fast.lon.tolist(),
            fast.sog.tolist(), fast.cog.tolist(), heading, fast.status.tolist(),
            strict=True,
        )  # fmt: skip
        taken, times, j = fast.line.tolist(), fast.time_us.tolist(), 0
        for k, line in enumerate(lines):
            if j < len(taken) and taken[j] == k:
                self._gatehouse = None  # a $PGHP stamps the line after it only
                row = next(rows)
                if self.recent is not None and self.recent.heard_at(fast.payload[j], times[j]):
                    self.skip(DUPLICATE_RECEPTION, line)
                else:
                    self._rows.append(row)
                j += 1
            else:
                self.feed(line)

    def feed(self, line: bytes) -> None:
        """One line of the log (without its line end)."""
        line = line.strip()
        if not line or line.startswith(b"#"):
            return
        start = SENTENCE_START.search(line) if len(line) <= MAX_LINE_BYTES else None
        if start is None:
            self.skip("not_ais", line)
            return
        gatehouse = self._gatehouse
        raw, after = _split_trailing_stamp(line[start.start() :])
        sentence = self._parse(raw, line)
        if isinstance(sentence, GatehouseSentence):
            self._gatehouse = sentence.timestamp.isoformat()
            return
        self._gatehouse = None  # a $PGHP stamps the line after it only
        if isinstance(sentence, AISSentence):
            stamp = line[: start.start()].strip(STAMP_SEPARATORS).decode("ascii", "replace")
            time = _tag_time(sentence) or stamp or after or gatehouse
            self._add_part(Part(sentence, time, line))

    def finish(self) -> None:
        """The end of the log: messages still missing parts are truncated."""
        for slot in list(self._parts):
            self._give_up(slot)

    def take(self) -> pa.RecordBatch:
        """The rows decoded since the last call, as one record batch."""
        columns = list(zip(*self._rows, strict=True)) if self._rows else [[]] * len(FRAME_SCHEMA)
        self._rows = []
        return pa.record_batch(
            [pa.array(c, f.type) for c, f in zip(columns, FRAME_SCHEMA, strict=True)],
            schema=FRAME_SCHEMA,
        )

    def _parse(self, raw: bytes, line: bytes) -> NMEASentence | None:
        """The sentence of a line, or None (the line skipped under its reason)."""
        try:
            sentence = NMEASentenceFactory.produce(raw)
        except UnknownMessageException:
            self.skip("not_ais", line)
            return None
        except AISBaseException:
            self.skip("truncated" if AIS_SENTENCE.search(line) else "not_ais", line)
            return None
        if not sentence.is_valid:  # pyais gives a missing `*hh` checksum as -1
            self.skip("bad_checksum" if sentence.checksum >= 0 else "truncated", line)
            return None
        return sentence

    def _add_part(self, part: Part) -> None:
        """Decode a one-sentence message at once; collect the parts of a longer one, in order."""
        sentence = part.sentence
        if sentence.is_single:
            self._decode(sentence, part.time, part.line)
            return
        slot = (sentence.seq_id, sentence.channel, sentence.talker_id, sentence.type)
        slot += (sentence.frag_cnt,)
        parts = self._parts.get(slot)
        if sentence.frag_num == 1 or (parts and sentence.frag_num == len(parts) + 1):
            if sentence.frag_num == 1 and parts:
                self._give_up(slot)  # a new message began before the last one ended
            self._parts.setdefault(slot, []).append(part)
        else:  # a part without its beginning, or out of order
            if parts:
                self._give_up(slot)
            self.skip("truncated", part.line)
            return
        if len(self._parts[slot]) == sentence.frag_cnt:
            parts = self._parts.pop(slot)
            message = AISSentence.assemble_from_iterable([p.sentence for p in parts])
            time = next((p.time for p in parts if p.time), None)
            self._decode(message, time, b"\n".join(p.line for p in parts))

    def _give_up(self, slot: tuple) -> None:
        self.skip("truncated", b"\n".join(p.line for p in self._parts.pop(slot)))

    def _decode(self, message: AISSentence, time: str | None, text: bytes) -> None:
        """One row from a whole message, or the reason it gives none."""
        if not message.payload:
            self.skip("truncated", text)
            return
        if message.ais_id not in POSITION_TYPES:
            if message.ais_id in STATIC_TYPES:
                self._static(message, time)
            self.skip("not_position", text)
            return
        try:
            report = message.decode()
        except AISBaseException:
            self.skip("truncated", text)
            return
        sog, cog = report.speed, report.course
        if None in (report.mmsi, report.lat, report.lon, sog, cog):
            self.skip("truncated", text)  # the payload ended before these fields
            return
        if not time:
            self.skip("no_time", text)
            return
        if self.recent is not None and self.recent.heard(message.payload, time):
            self.skip(DUPLICATE_RECEPTION, text)
            return
        if report.msg_type == 27:
            sog = SENTINEL_SOG if sog == LONG_RANGE_SOG_NOT_AVAILABLE else sog
            cog = SENTINEL_COG if cog == LONG_RANGE_COG_NOT_AVAILABLE else cog
        heading = getattr(report, "heading", None)
        heading = None if heading == HEADING_NOT_AVAILABLE else heading
        status = getattr(report, "status", None)
        status = None if status is None else int(status)
        self._rows.append((report.mmsi, time, report.lat, report.lon, sog, cog, heading, status))
        if report.msg_type in STATIC_TYPES:
            self._add_static(report, time)

    def _static(self, message: AISSentence, time: str | None) -> None:
        """The vessel a static message names (none where it does not decode)."""
        try:
            report = message.decode()
        except AISBaseException:
            return
        self._add_static(report, time)

    def _add_static(self, report: Any, time: str | None) -> None:
        """Name, ship type and length (bow to stern, 0: not available) of a decoded message of
        `STATIC_TYPES` (type 24's part A gives the name only, part B the rest), at its time
        (None: the line gave none)."""
        kind = getattr(report, "ship_type", None)
        bow, stern = getattr(report, "to_bow", None), getattr(report, "to_stern", None)
        length = None if bow is None or stern is None else bow + stern
        name = getattr(report, "shipname", None)
        kind = None if kind is None else int(kind)
        self.statics.append(Static(report.mmsi, name, kind, length, time))

    def take_statics(self) -> list[Static]:
        """The static messages decoded since the last call."""
        statics, self.statics = self.statics, []
        return statics


def _split_trailing_stamp(raw: bytes) -> tuple[bytes, str]:
    """A sentence without the time some receivers write after its checksum
    (`!AIVDM,...*hh,1530428400`), and that time ("" when there is none)."""
    found = TRAILING_STAMP.search(raw)
    if found is None:
        return raw, ""
    stamp = found.group(1).strip(STAMP_SEPARATORS).decode("ascii", "replace")
    return raw[: found.start(1)].rstrip(STAMP_SEPARATORS), stamp


def _tag_time(sentence: AISSentence) -> str | None:
    """The receiver time (`c:`) of the sentence's NMEA 4.0 tag block, if it has one."""
    if sentence.tag_block is None:
        return None
    sentence.tag_block.init()
    return sentence.tag_block.receiver_timestamp


def read_lines(stream: ByteStream, chunk_bytes: int = 1 << 20) -> Iterator[bytes]:
    """The lines of a byte stream, ended by LF, CRLF or CR. A line longer than `MAX_LINE_BYTES`
    comes as its first `MAX_LINE_BYTES + 1` bytes (no sentence: it will be skipped), so memory
    stays bounded whatever the file holds."""
    carry, dropping = b"", False
    while chunk := stream.read(chunk_bytes):
        lines = (carry + chunk).replace(b"\r", b"\n").split(b"\n")
        carry = lines.pop()
        if dropping and lines:
            lines.pop(0)  # the end of the over-long line, already given
            dropping = False
        yield from lines
        if not dropping and len(carry) > MAX_LINE_BYTES:
            yield carry[: MAX_LINE_BYTES + 1]
            dropping = True
        if dropping:
            carry = b""
    if carry and not dropping:
        yield carry


class NmeaReader:
    """Streams one NMEA log as record batches of `FRAME_SCHEMA` (see the module docstring); the
    `TableReader` of NMEA sources."""

    def __init__(self, source: Source) -> None:
        self.source = source
        self.columns = dict(COLUMNS)
        self.time_format: str | None = None
        self.vessels = VesselTally()
        self._statics_seen = 0
        self._skipped = SkippedLines()
        self._counter: CountingReader | None = None
        try:
            found = looks_like_nmea(source)
        except READ_ERRORS as exc:
            raise describe_read_error(source, exc) from None
        if not found:
            raise UserError(
                f"{source.label}: no AIS sentence (!AIVDM or !AIVDO) in the first "
                f"{SNIFF_BYTES >> 10} KiB: not an NMEA log"
            )

    @property
    def total(self) -> int:
        """Progress units of the whole source: bytes on disk."""
        return self.source.size()

    @property
    def done(self) -> int:
        return self._counter.bytes_read if self._counter else 0

    @property
    def skipped(self) -> dict[str, list[str | None]]:
        return self._skipped.by_reason

    def tables(self, src: int) -> Iterator[tuple[pa.Table, np.ndarray]]:
        return canonical_tables(self.batches(), self.columns, src, self.time_format)

    def batches(self) -> Iterator[pa.RecordBatch]:
        stream, self._counter = self.source.open()
        decoder = NmeaDecoder(self._skipped.add, RecentMessages())
        try:
            lines = read_lines(stream)
            while batch := list(islice(lines, LINES_AT_ONCE)):
                decoder.feed_lines(batch)
                if decoder.pending_rows >= BATCH_MESSAGES or len(decoder.statics) >= BATCH_MESSAGES:
                    self._tally(decoder.take_statics())
                    yield decoder.take()
            decoder.finish()
            self._tally(decoder.take_statics())
            if decoder.pending_rows:
                yield decoder.take()
        finally:
            stream.close()

    def _tally(self, statics: list[Static]) -> None:
        """Static messages into `vessels`, in the order read, at their times."""
        if not statics:
            return
        mmsi, names, kinds, lengths, times = zip(*statics, strict=True)
        order = np.arange(self._statics_seen, self._statics_seen + len(statics))
        self._statics_seen += len(statics)
        columns = {
            "name": pa.array(names, pa.string()),
            "ship_type": pa.array(kinds, pa.int64()),
            "length": pa.array(lengths, pa.int64()),
        }
        self.vessels.add(np.array(mmsi, np.int64), columns, order, static_times_us(times))
