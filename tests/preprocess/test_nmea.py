"""NMEA 0183 input: real receiver sentences (pyais's test data, tests/data/nmea) decoded and
counted per reason, real Kitimat tracks through `aisdati ingest` as !AIVDM sentences (with their
static messages naming the vessels), heading and status per message type, and non-finite times
in a log bad times (issue 27, item 6)."""

from __future__ import annotations

import gzip
import json
import warnings
from functools import reduce
from operator import xor
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from pyais.encode import encode_dict
from pyais.messages import NMEASentenceFactory, TagBlock

from aisdati.errors import UserError
from aisdati.preprocess.clean import check_values
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.inputs import Source, expand_inputs
from aisdati.preprocess.nmea import COLUMNS, NmeaDecoder, SkippedLines, read_lines
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.report import CODE
from tests.helpers.kitimat_sample import kitimat_rows

NMEA = Path(__file__).parents[1] / "data" / "nmea"
AIS_RESOLUTION_DEG = 1 / 600_000
ZERO = {"not_ais": 0, "bad_checksum": 0, "truncated": 0, "not_position": 0, "no_time": 0}
POSITION = "!AIVDM,1,1,,B,15NBj>PP1gG>1PVKTDTUJOv00<0M,0*"  # MMSI 367309370, from the samples


def checksummed(body: str) -> str:
    """An NMEA sentence (`!...` or `$...` without `*hh`) with its checksum appended."""
    return f"{body}*{reduce(xor, body[1:].encode(), 0):02X}"


def decode(lines: list[str]) -> tuple[pd.DataFrame, dict[str, int]]:
    """The frame and the per-reason counts of some log lines."""
    skipped = SkippedLines()
    decoder = NmeaDecoder(skipped.add)
    for line in lines:
        decoder.feed(line.encode())
    decoder.finish()
    counts = {reason: len(texts) for reason, texts in skipped.by_reason.items()}
    return decoder.take().to_pandas(), counts


def read(path: Path) -> tuple[pa.Table | None, np.ndarray, dict[str, int]]:
    """A small log read as ingest reads it: canonical rows (None when there are none), their
    rejection codes, and the skipped lines per reason."""
    reader = open_reader(Source(path))
    batches = list(reader.batches())
    assert len(batches) <= 1
    counts = {reason: len(texts) for reason, texts in reader.skipped.items()}
    if not batches:
        return None, np.zeros(0, np.uint8), counts
    table, codes = to_canonical(batches[0], reader.columns, 0, reader.time_format)
    return table, codes, counts


def test_pyais_sample_accounts_for_every_message():
    """898 real !AIVDM lines: 100 empty payloads and 20 first halves of two-part messages
    (truncated), 16 reports that are no position (types 4, 15, 20, 24), and 762 position
    reports without a time: every line is counted once, under its reason."""
    _, _, counts = read(NMEA / "nmea_data_sample.txt")
    assert counts == {**ZERO, "truncated": 120, "not_position": 16, "no_time": 762}


def test_pyais_sample_positions_with_a_timestamp_column(tmp_path):
    lines = (NMEA / "nmea_data_sample.txt").read_text().splitlines()
    log = tmp_path / "stamped.nmea"
    log.write_text("".join(f"{1606780800 + i},{line}\n" for i, line in enumerate(lines)))
    table, codes, counts = read(log)
    assert table.num_rows == 762 and counts["no_time"] == 0
    assert (codes == 0).sum() > 700  # the rest: sentinels and bad MMSIs, rejected later by name
    expected = [
        (i, NMEASentenceFactory.produce(line.encode()).decode())
        for i, line in enumerate(lines)
        if line.split(",")[1] == "1" and line.split(",")[5][:1] in tuple("123B")  # 1-3, 18
    ]
    assert len(expected) == 762
    assert table.column("mmsi").to_pylist() == [m.mmsi for _, m in expected]
    assert np.allclose(table.column("lat").to_numpy(), [m.lat for _, m in expected])
    assert np.allclose(table.column("sog").to_numpy(), [m.speed for _, m in expected])
    seconds = table.column("time").to_numpy().astype("datetime64[s]").astype(np.int64)
    assert list(seconds) == [1606780800 + i for i, _ in expected]


@pytest.mark.parametrize("name", ["timestamped.ais", "gatehouse.nmea"])
def test_gatehouse_timestamps_stamp_the_sentence_after_them(name):
    """A $PGHP stamps the next sentence only; the 2009 one was edited without its checksum."""
    table, codes, counts = read(NMEA / name)
    assert counts == {**ZERO, "bad_checksum": 1, "no_time": 3}
    assert table.column("mmsi").to_pylist() == [367309370] and list(codes) == [0]
    assert table.column("time")[0].as_py() == pd.Timestamp("2008-05-09 00:00:00.010", tz="UTC")


def test_a_mixed_log_of_comments_gps_noise_and_tag_blocks():
    table, _, counts = read(NMEA / "mixed.txt")
    assert counts == {
        "not_ais": 6,  # $GPGGA, $GPRTE, $GPR00, $IIMWV, foobar, IamNotAnAisMessage1111
        "bad_checksum": 1,  # the 2009 $PGHP
        "truncated": 1,  # a tag-blocked sentence that lost its *hh
        "not_position": 2,  # two-part type 5 messages, one with tag-block groups
        "no_time": 9,
    }
    assert table.num_rows == 1


def test_every_way_of_logging_the_time_gives_the_same_instant():
    t = pd.Timestamp("2020-12-01T00:00:00Z")
    pghp = checksummed("$PGHP,1,2020,12,1,0,0,0,0,338,2,,1,09")
    tag = TagBlock.create_str(receiver_timestamp=1606780800, source_station="r1")
    tag_ms = TagBlock.create_str(receiver_timestamp=1606780800000)
    position = POSITION + "09"
    lines = [
        f"2020-12-01T00:00:00Z,{position}",
        f"2020-12-01 00:00:00;{position}",
        f"1606780800 {position}",
        f"1606780800.0\t{position}",
        f"[2020-12-01T00:00:00.000] {position}",
        f"\\{tag}\\{position}",
        f"\\{tag_ms}\\{position}",
        pghp,
        position,
        f"yesterday,{position}",
    ]
    frame, counts = decode(lines)
    assert counts == ZERO and len(frame) == len(lines) - 1
    canonical, codes = to_canonical(pa.RecordBatch.from_pandas(frame), COLUMNS, 0)
    times = canonical.column("time").slice(0, len(lines) - 2).to_pylist()
    assert times == [t] * (len(lines) - 2) and list(codes[:-1]) == [0] * (len(lines) - 2)
    assert codes[-1] == CODE["bad_time"]


def _fragments(payload: str, cut: int, seq: int = 3) -> list[str]:
    return [
        checksummed(f"!AIVDM,2,1,{seq},A,{payload[:cut]},0"),
        checksummed(f"!AIVDM,2,2,{seq},A,{payload[cut:]},0"),
    ]


def test_a_position_report_over_two_sentences_is_reassembled():
    payload = POSITION.split(",")[5]
    single, _ = decode([f"1606780800,{POSITION}09"])
    first, second = _fragments(payload, 12)
    frame, counts = decode([f"1606780800,{first}", second])
    assert counts == ZERO and frame.equals(single)
    frame, counts = decode([second, first])  # out of order: part 2 alone, part 1 never ended
    assert counts == {**ZERO, "truncated": 2} and frame.empty
    frame, counts = decode([f"1606780800,{first}", f"1606780801,{first}", second])
    assert counts == {**ZERO, "truncated": 1} and len(frame) == 1  # the first start lost


def test_not_available_values_are_the_cleaners_sentinels():
    """Types 1-3 and 18 give 91/181/102.3/360 as they are; type 27 writes 'not available' as SOG
    63 and COG 511, which become the same sentinels; heading 511 becomes missing."""
    long_range = {"type": 27, "mmsi": 257000001, "lat": 91, "lon": 181, "speed": 63, "course": 511}
    class_a = {"type": 1, "mmsi": 257000002, "lat": 91, "lon": 181, "speed": 102.3}
    class_a |= {"course": 360, "heading": 511}
    lines = [f"1606780800,{encode_dict(m, sentence_type='VDM')[0]}" for m in (long_range, class_a)]
    frame, counts = decode(lines)
    assert counts == ZERO
    assert frame[["LAT", "LON", "SOG", "COG"]].values.tolist() == [[91, 181, 102.3, 360]] * 2
    assert frame["Heading"].isna().all()
    table, codes = to_canonical(pa.RecordBatch.from_pandas(frame), COLUMNS, 0)
    check_values(table, codes)
    assert list(codes) == [CODE["sentinel_lat"]] * 2


def test_heading_and_status_of_each_position_type():
    """Types 1-3 give heading and navigational status (15, not defined: none), 18 and 19 a
    heading and no status, 27 a status and no heading; a static message (type 5) is counted as
    no position, its vessel kept for vessels.parquet."""
    at = {"lat": 55.0, "lon": 12.0, "speed": 10, "course": 90}
    messages = [
        {"type": 1, "mmsi": 257000001, "status": 5, "heading": 123, **at},
        {"type": 3, "mmsi": 257000002, "status": 15, "heading": 511, **at},
        {"type": 18, "mmsi": 257000003, "heading": 200, **at},
        {"type": 27, "mmsi": 257000004, "status": 1, **at},
    ]
    lines = [f"1606780800,{encode_dict(m, sentence_type='VDM')[0]}" for m in messages]
    static = {"type": 5, "mmsi": 257000001, "shipname": "ANNA@@@", "ship_type": 70}
    static |= {"to_bow": 100, "to_stern": 20}
    lines += [f"1606780800,{part}" for part in encode_dict(static, sentence_type="VDM", seq_id=1)]
    skipped = SkippedLines()
    decoder = NmeaDecoder(skipped.add)
    for line in lines:
        decoder.feed(line.encode())
    decoder.finish()
    frame = decoder.take().to_pandas()
    assert frame["Heading"].tolist()[:1] + frame["Heading"].tolist()[2:3] == [123, 200]
    assert frame["Heading"].isna().tolist() == [False, True, False, True]
    table, codes = to_canonical(pa.RecordBatch.from_pandas(frame), COLUMNS, 0)
    assert not codes.any() and table.column("status").to_pylist() == [5, None, None, 1]
    assert len(skipped.by_reason["not_position"]) == 1
    (static,) = decoder.take_statics()
    assert static[:4] == (257000001, "ANNA", 70, 120)


def test_cut_corrupt_and_foreign_lines_are_counted_never_raised():
    good = POSITION + "09"
    flipped = good.replace("15NBj", "15NBk")
    lines = [
        good[:30],  # cut inside the payload
        good[:-3],  # cut before the checksum
        flipped,
        "!AIVDM,1,1,,B,,0*25",  # empty payload (real, from the pyais sample)
        "!AIVDM,1,9,,B,15NBj,0*00",  # part 9 of 1
        "\x00\xff" * 40,
        "!" * 5000,  # longer than any sentence
        "# a comment",
        "",
        "$GPGGA,184353.07,1929.045,S,02410.506,E,1,04,2.6,100.00,M,-33.9,M,,0000*6D",
        good,  # no time
    ]
    frame, counts = decode(lines)
    assert frame.empty
    assert counts == {
        "not_ais": 3,
        "bad_checksum": 1,
        "truncated": 4,
        "not_position": 0,
        "no_time": 1,
    }


def test_lines_end_at_lf_crlf_or_cr_and_long_lines_stay_bounded():
    class Chunks:
        def __init__(self, data: bytes, size: int) -> None:
            self.data, self.size = data, size

        def read(self, n: int) -> bytes:
            piece, self.data = self.data[: self.size], self.data[self.size :]
            return piece

    data = b"a\r\nb\rc\n" + b"x" * 10_000 + b"\nd\ne"
    lines = [line for line in read_lines(Chunks(data, 7)) if line]
    assert lines[:3] == [b"a", b"b", b"c"] and lines[4:] == [b"d", b"e"]
    assert 4096 < len(lines[3]) <= 4097


def test_text_files_count_as_nmea_only_when_they_hold_ais_sentences(tmp_path):
    (tmp_path / "README.txt").write_text("what these files are\n")
    (tmp_path / "log.txt").write_text((NMEA / "mixed.txt").read_text())
    (tmp_path / "log.ais.gz").write_bytes(gzip.compress((NMEA / "timestamped.ais").read_bytes()))
    found = expand_inputs([tmp_path])
    assert [p.name for p in found] == ["log.ais.gz", "log.txt"]
    with pytest.raises(UserError, match="unsupported file type"):
        expand_inputs([tmp_path / "README.txt"])
    empty = tmp_path / "empty.nmea"
    empty.write_text("$GPGGA,184353.07,1929.045,S,02410.506,E,1,04,2.6,100.00,M,-33.9,M,,0000*6D\n")
    with pytest.raises(UserError, match="not an NMEA log"):
        open_reader(Source(empty))


def test_a_gzipped_log_reads_as_the_plain_one(tmp_path):
    log = tmp_path / "mixed.nmea.gz"
    log.write_bytes(gzip.compress((NMEA / "mixed.txt").read_bytes()))
    plain, _, plain_counts = read(NMEA / "mixed.txt")
    packed, _, packed_counts = read(log)
    assert packed.to_pandas().equals(plain.to_pandas()) and packed_counts == plain_counts


def read_vessels(out: Path) -> pd.DataFrame:
    return pq.read_table(out / "vessels.parquet").to_pandas()


def kitimat_log(rows: pd.DataFrame) -> tuple[list[str], dict[str, int]]:
    """Kitimat reports as a receiver log: one type 1 or 18 !AIVDM sentence each, the time in
    one of four ways in turn (tag block, ISO column, epoch column, $PGHP before it); plus per
    vessel a two-sentence static report and one line of each kind of fault."""
    lines: list[str] = []
    for i, row in enumerate(rows.itertuples()):
        t = pd.Timestamp(row.BaseDateTime, tz="UTC")
        message = {"type": 1 if row.TransceiverClass == "A" else 18, "mmsi": int(row.MMSI)}
        message |= {"lat": float(row.LAT), "lon": float(row.LON), "speed": float(row.SOG)}
        message |= {"course": float(row.COG), "heading": int(row.Heading)}
        (sentence,) = encode_dict(message, talker_id="AI", sentence_type="VDM")
        if i % 4 == 0:
            tag = TagBlock.create_str(receiver_timestamp=int(t.timestamp()), source_station="k")
            lines.append(f"\\{tag}\\{sentence}")
        elif i % 4 == 1:
            lines.append(f"{t.isoformat().replace('+00:00', 'Z')},{sentence}")
        elif i % 4 == 2:
            lines.append(f"{int(t.timestamp())} {sentence}")
        else:
            stamp = f"{t.year},{t.month},{t.day},{t.hour},{t.minute},{t.second},0"
            lines += [checksummed(f"$PGHP,1,{stamp},316,,,1,{sentence[-2:]}"), sentence]
    faults = {"not_ais": 0, "bad_checksum": 0, "truncated": 0, "not_position": 0, "no_time": 0}
    for mmsi in sorted(set(rows["MMSI"])):
        static = {"type": 5, "mmsi": int(mmsi), "shipname": "KITIMAT SAMPLE", "ship_type": 52}
        parts = encode_dict(static, sentence_type="VDM", seq_id=1)
        position = {"type": 1, "mmsi": int(mmsi), "lat": 53.0, "lon": -129.0, "speed": 10}
        (sentence,) = encode_dict(position, sentence_type="VDM")
        stamp = "2018-07-03T12:00:00Z,"
        wrong = f"{sentence[:-2]}{int(sentence[-2:], 16) ^ 1:02X}"
        lines += [stamp + parts[0], parts[1], stamp + wrong, stamp + sentence[:25]]
        lines += ["$GPGGA,184353.07,1929.045,S,02410.506,E,1,04,2.6,100.00,M,-33.9,M,,0000*6D"]
        lines += [sentence]
        for reason in faults:
            faults[reason] += 1
    return lines, faults


def test_kitimat_tracks_come_back_through_nmea(cli, tmp_path):
    """Six real vessels, a week: ingested from their CSV and from the same reports encoded as
    !AIVDM sentences, the same tracks and points, positions within AIS's resolution, and the
    faults counted per reason in the printed table and the report."""
    rows = kitimat_rows()
    csv = tmp_path / "kitimat.csv"
    rows.to_csv(csv, index=False)
    lines, faults = kitimat_log(rows)
    log = tmp_path / "kitimat.nmea.gz"
    log.write_bytes(gzip.compress("".join(f"{line}\r\n" for line in lines).encode()))
    args = ("--roi", "none", "--min-points", "20")
    result = cli("ingest", "--input", csv, "--out", tmp_path / "csv", *args, "--json")
    assert result.exit_code == 0, result.output
    baseline = json.loads(result.stdout)
    result = cli("ingest", "--input", log, "--out", tmp_path / "nmea", *args, "--keep-rejects")
    assert result.exit_code == 0, result.output
    rejects = pq.read_table(tmp_path / "nmea" / "rejects.parquet").to_pandas()
    for reason in faults:
        raw = rejects.loc[rejects["reason"] == reason, "raw"]
        assert len(raw) == 6 and raw.str.len().min() > 0, reason
    report = json.loads((tmp_path / "nmea" / "ingest_report.json").read_text())
    table = result.stdout
    assert "aisdati ingest" in table and "rows read" in table
    for reason, n in faults.items():
        assert report["rejected"][reason] == n == 6 and reason in table
    assert report["rows_read"] == baseline["rows_read"] + sum(faults.values())
    for reason, n in baseline["rejected"].items():
        assert report["rejected"][reason] == n + faults.get(reason, 0), reason
    assert report["tracks"] == baseline["tracks"] and report["tracks"]["total"] == 32
    want = pq.read_table(tmp_path / "csv" / "points.parquet")
    got = pq.read_table(tmp_path / "nmea" / "points.parquet")
    assert got.num_rows == want.num_rows == baseline["kept_points"]
    for name in ("track_id", "mmsi", "time", "sog", "cog"):
        assert got.column(name).equals(want.column(name)), name
    for name in ("lon", "lat"):
        error = np.abs(got.column(name).to_numpy() - want.column(name).to_numpy())
        assert error.max() <= AIS_RESOLUTION_DEG, name
    assert set(got.column("status").to_pylist()) <= {0, None}  # type 1: 0, type 18: none
    # each vessel named by its type 5 message: in the log, not in the CSV
    named, plain = (read_vessels(tmp_path / run) for run in ("nmea", "csv"))
    assert (named["name"] == "KITIMAT SAMPLE").all() and (named["ship_type"] == "Tug").all()
    assert named["mmsi"].tolist() == plain["mmsi"].tolist() and plain["name"].isna().all()


def test_non_finite_times_in_an_nmea_log_are_bad_times(tmp_path):
    sentence = "!AIVDM,1,1,,B,15NBj>PP1gG>1PVKTDTUJOv00<0M,0*09"  # real, tests/data/nmea
    stamps = ["2020-12-01T00:00:00Z", "nan", "NaN", "inf", "-Infinity", "1e400", "9" * 60]
    log = tmp_path / "log.nmea"
    log.write_text("".join(f"{stamp},{sentence}\n" for stamp in stamps))
    reader = open_reader(Source(log))
    (batch,) = reader.batches()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table, codes = to_canonical(batch, reader.columns, 0, reader.time_format)
    assert codes.tolist() == [0] + [CODE["bad_time"]] * (len(stamps) - 1)
    assert np.isfinite(table.column("lat").to_numpy()).all()
