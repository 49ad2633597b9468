"""Class A position reports decoded many at a time (`position_sentences`, through
`NmeaDecoder.feed_lines`) give exactly the rows, skips and static messages that pyais gives
line by line (`NmeaDecoder.feed`): on every shipped receiver log, on real Kitimat and US
reports written as tag-blocked sentences (the watch's feeds), and on lines that differ from
the common shape in one way each (which must go to pyais and be read as it reads them)."""

from __future__ import annotations

import gzip
from functools import reduce
from operator import xor
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyais.encode import encode_dict

from aisdati.preprocess import position_sentences
from aisdati.preprocess.nmea import NmeaDecoder, RecentMessages, SkippedLines, read_lines

DATA = Path(__file__).parents[1] / "data"
LOGS = [
    p for d in ("nmea", "events") for p in sorted((DATA / d).iterdir()) if "LICENSE" not in p.name
]


def tagged(report: dict, time: str, tag_extra: str = "") -> str:
    tag = f"{tag_extra}c:{time}"
    return f"\\{tag}*{reduce(xor, tag.encode(), 0):02X}\\{encode_dict(report, talker_id='AI')[0]}"


def resum(sentence: str) -> str:
    """The sentence with its checksum made right."""
    body = sentence[1 : sentence.index("*")]
    return f"{sentence[0]}{body}*{reduce(xor, body.encode(), 0):02X}"


def real_reports(n: int) -> list[str]:
    """Kitimat's first `n` reports as the watch's feeds write them, in time order."""
    with gzip.open(DATA / "AIS_2018_07-08_Kitimat.csv.gz", "rt") as f:
        frame = pd.read_csv(f, nrows=n)
    times = pd.to_datetime(frame["BaseDateTime"], utc=True).astype("int64") // 10**9
    lines = []
    for row, t in zip(frame.itertuples(index=False), times, strict=True):
        report = {"type": 1, "mmsi": int(row.MMSI), "lat": row.LAT, "lon": row.LON,
                  "speed": min(row.SOG, 102.2), "course": row.COG % 360, "heading": 511,
                  "status": 0}  # fmt: skip
        lines.append(tagged(report, str(t)))
    return lines


def both(lines: list[bytes]) -> tuple[tuple, tuple]:
    """(rows, skipped lines by reason, statics) of the lines fed one by one, then together."""
    out = []
    for together in (False, True):
        skipped = SkippedLines()
        decoder = NmeaDecoder(skipped.add, RecentMessages())
        if together:
            decoder.feed_lines(lines)
        else:
            for line in lines:
                decoder.feed(line)
        decoder.finish()
        out.append((decoder.take().to_pylist(), skipped.by_reason, decoder.take_statics()))
    return out[0], out[1]


@pytest.mark.parametrize("log", LOGS, ids=lambda p: p.name)
def test_every_shipped_log_reads_the_same(log: Path):
    with open(log, "rb") as stream:
        lines = list(read_lines(stream))
    one_by_one, together = both(lines)
    assert together == one_by_one


def test_real_reports_as_a_feed_read_the_same_and_take_the_fast_path():
    lines = [line.encode() for line in real_reports(3000)]
    one_by_one, together = both(lines)
    assert together == one_by_one
    assert len(one_by_one[0]) > 2900  # rows, not skips
    assert len(position_sentences.decode(lines).line) == len(lines)


def test_every_field_value_reads_as_pyais_reads_it():
    """Random reports over each field's whole range: sign, sentinels (lat 91, lon 181, speed
    102.3, course 360, heading 511), every status and message type 1-3."""
    rng = np.random.default_rng(7)
    lines = []
    for k in range(2000):
        report = {
            "type": int(rng.integers(1, 4)),
            "mmsi": int(rng.integers(0, 1 << 30)),
            "status": int(rng.integers(0, 16)),
            "speed": float(rng.choice([rng.integers(0, 1024) / 10, 102.3])),
            "lon": float(rng.choice([rng.uniform(-180, 180), 181.0])),
            "lat": float(rng.choice([rng.uniform(-90, 90), 91.0])),
            "course": float(rng.choice([rng.integers(0, 3600) / 10, 360.0])),
            "heading": int(rng.choice([rng.integers(0, 360), 511])),
        }
        time = str(1_600_000_000 + k) if k % 2 else str(1_600_000_000_000 + 1000 * k)
        lines.append(tagged(report, time, "s:r003669945,").encode())
    one_by_one, together = both(lines)
    assert together == one_by_one
    assert len(position_sentences.decode(lines).line) == len(lines)


def test_lines_of_another_shape_go_to_pyais():
    """Each differs from the common shape in one way: none is taken by the fast path, and
    all read as pyais reads them (rows, skips by reason)."""
    good = tagged({"type": 1, "mmsi": 367309370, "lat": 40.7, "lon": -74.0, "speed": 5.0}, "1")
    tag, sentence = good[1:].split("\\", 1)
    body, check = sentence[1:].split("*")
    others = [
        good[:-2] + ("00" if good[-2:] != "00" else "01"),  # a wrong checksum
        good[:-2] + good[-2:].lower(),  # the checksum in lower case (pyais reads it)
        f"\\s:x*00\\{sentence}",  # no time in the tag block: no_time
        f"\\c:1,c:2*00\\{sentence}",  # two times
        f"\\c:abc*00\\{sentence}",  # a time that is no number
        f"2020-01-01T00:00:00Z,{sentence}",  # a time before the sentence
        f"{good},1600000000",  # a time after it
        good.replace(",0*", ",2*"),  # fill bits
        f"\\{tag}\\!{body[:-3]}0*{check}",  # a short payload
        f"\\{tag}\\{resum(sentence.replace('VDO', 'VDM'))}",  # VDM as pyais wrote VDO
        "  " + good + "  ",  # spaces around it (stripped: the fast path)
    ]
    lines = [line.encode() for line in others]
    one_by_one, together = both(lines)
    assert together == one_by_one
    taken = position_sentences.decode([line.strip() for line in lines]).line.tolist()
    assert taken == [1, 9, 10]


def test_another_receivers_copy_is_counted_once_on_either_path():
    report = {"type": 1, "mmsi": 367309370, "lat": 40.7, "lon": -74.0}
    lines = [tagged(report, time).encode() for time in ("1600000000", "1600000005")]
    one_by_one, together = both(lines)
    assert together == one_by_one
    assert len(together[0]) == 1
    assert len(together[1]["duplicate_reception"]) == 1
