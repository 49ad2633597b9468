"""NMEA logs of several receivers (issue 61, items 7 and 15): a message heard by two or three
receivers is one report, its copies counted as `duplicate_reception` (real Kitimat tracks
encoded as two receivers' logs, and real Danish Maritime Authority lines); a Unix time after
the checksum (`!AIVDM,...*hh,1530428400`) is the report's time; and a planted pickle is refused
as a model or checkpoint without torch's advice to load it unsafely."""

from __future__ import annotations

import gzip
import json
import pickle
from functools import reduce
from operator import xor
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch
from pyais.encode import encode_dict
from pyais.messages import TagBlock

from aisdati.errors import UserError
from aisdati.model.persistence import read_checkpoint, read_weights
from aisdati.preprocess.convert import to_canonical
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.nmea import RECEPTION_WINDOW_S
from aisdati.preprocess.read import open_reader
from tests.helpers.kitimat_sample import kitimat_rows

NMEA = Path(__file__).parents[1] / "data" / "nmea"
AIS_RESOLUTION_DEG = 1 / 600_000
INGEST = ("--roi", "none", "--min-points", "20")
POSITION = "!AIVDM,1,1,,B,15NBj>PP1gG>1PVKTDTUJOv00<0M,0*09"  # MMSI 367309370, pyais's sample
OTHER_POSITION = "!AIVDM,1,1,,A,16:=?;0P00`SstvFnFbeGH6L088h,0*44"  # the same sample
DMA_LINES = r"""\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,4,684,219,21,992190921,1,14*22
!AIVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*14
\si:IALA*25\
$PGHP,1,2014,9,28,16,0,4,752,219,,2190074,1,0D*53
!BSVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*0D
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,4,752,219,,2190073,1,0D*54
!BSVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*0D
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,4,752,219,,2190074,1,0D*53
!BSVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*0D
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,5,77,219,53,992190937,1,14*1B
!AIVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*14
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,5,376,251,3,,1,0D*56
!BSVDM,1,1,,A,1815:?Pu@SPl2`LQ4kaeRr0400SS,0*0D
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,14,794,219,21,992190921,1,45*17
!AIVDM,1,1,,B,1815:?Pu@SPl2W0Q4l2MQJ0H0H8b,0*45
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,14,798,219,,2190073,1,5C*61
!BSVDM,1,1,,B,1815:?Pu@SPl2W0Q4l2MQJ0H0H8b,0*5C
\si:IALA*25\
$PGHP,1,2014,9,28,16,0,14,814,219,,2190074,1,5C*6D
!BSVDM,1,1,,B,1815:?Pu@SPl2W0Q4l2MQJ0H0H8b,0*5C
\si:AISD*3F\
$PGHP,1,2014,9,28,16,0,14,814,219,,2190074,1,5C*6D
!BSVDM,1,1,,B,1815:?Pu@SPl2W0Q4l2MQJ0H0H8b,0*5C
"""
"""The first 30 lines of the DMA's recording of FRIO (../shared/data/events/538004030_drift_1.ais,
from github dma-ais/AisAbnormal, LGPL-3.0): two position reports, heard six and four times by
the receivers AISD and IALA, as `!AIVDM` and `!BSVDM`, each after its receiver's tag block and a
`$PGHP` time."""


def checksummed(body: str) -> str:
    """An NMEA sentence (`!...` without `*hh`) with its checksum appended."""
    return f"{body}*{reduce(xor, body[1:].encode(), 0):02X}"


def read(path: Path) -> tuple[pa.Table | None, dict[str, int]]:
    """A small log read as ingest reads it: canonical rows (None: none) and the skipped lines
    per reason (the reasons met)."""
    reader = open_reader(Source(path))
    batches = list(reader.batches())
    counts = {reason: len(texts) for reason, texts in reader.skipped.items() if texts}
    if not batches:
        return None, counts
    return to_canonical(pa.concat_batches(batches), reader.columns, 0)[0], counts


def encoded(rows: pd.DataFrame, talker: str = "AI") -> list[tuple[pd.Timestamp, str]]:
    """Kitimat reports as type 1 or 18 sentences, with their times."""
    out = []
    for row in rows.itertuples():
        message = {"type": 1 if row.TransceiverClass == "A" else 18, "mmsi": int(row.MMSI)}
        message |= {"lat": float(row.LAT), "lon": float(row.LON), "speed": float(row.SOG)}
        message |= {"course": float(row.COG), "heading": int(row.Heading)}
        (sentence,) = encode_dict(message, talker_id=talker, sentence_type="VDM")
        out.append((pd.Timestamp(row.BaseDateTime, tz="UTC"), sentence))
    return out


def tagged(t: pd.Timestamp, sentence: str, station: str, delay_ms: int = 0) -> str:
    """A sentence after an NMEA 4.0 tag block of its receiver and time (milliseconds)."""
    ms = int(t.timestamp()) * 1000 + delay_ms
    return f"\\{TagBlock.create_str(receiver_timestamp=ms, source_station=station)}\\{sentence}"


def receivers_log(rows: pd.DataFrame) -> tuple[list[str], int]:
    """The Kitimat reports as a log merged from three receivers: r1 hears every message, r2 too,
    300 ms later; every fourth one r3 (a base station, `!BSVDM`) 1.2 s later. Returns the lines
    and the number of copies past the first."""
    lines, copies = [], 0
    base = encoded(rows, "BS")
    for i, (t, sentence) in enumerate(encoded(rows)):
        lines += [tagged(t, sentence, "r1"), tagged(t, sentence, "r2", 300)]
        copies += 1
        if i % 4 == 0:
            lines.append(tagged(t, base[i][1], "r3", 1200))
            copies += 1
    return lines, copies


def write_log(path: Path, lines: list[str]) -> Path:
    path.write_bytes(gzip.compress("".join(f"{line}\r\n" for line in lines).encode()))
    return path


def ingest(cli, log: Path, out: Path) -> dict:
    """`aisdati ingest` of one log (rejects kept): its ingest_report.json."""
    result = cli("ingest", "--input", log, "--out", out, *INGEST, "--keep-rejects")
    assert result.exit_code == 0, result.output
    return json.loads((out / "ingest_report.json").read_text())


def assert_same_points(got_dir: Path, want_dir: Path) -> None:
    """The same tracks and points, positions within AIS's resolution."""
    want = pq.read_table(want_dir / "points.parquet")
    got = pq.read_table(got_dir / "points.parquet")
    assert got.num_rows == want.num_rows
    for name in ("track_id", "mmsi", "time", "sog", "cog"):
        assert got.column(name).equals(want.column(name)), name
    for name in ("lon", "lat"):
        error = np.abs(got.column(name).to_numpy() - want.column(name).to_numpy())
        assert error.max() <= AIS_RESOLUTION_DEG, name


def test_a_message_heard_by_several_receivers_is_one_report(cli, tmp_path):
    """Item 7: six real Kitimat vessels, a week, heard by one receiver and by three: the same
    32 tracks and points, each copy counted as `duplicate_reception` (and kept in rejects)
    instead of doubling the points and letting short pieces pass --min-points."""
    rows = kitimat_rows()
    one = [tagged(t, sentence, "r1") for t, sentence in encoded(rows)]
    single = ingest(cli, write_log(tmp_path / "one.nmea.gz", one), tmp_path / "one")
    lines, copies = receivers_log(rows)
    merged = ingest(cli, write_log(tmp_path / "three.nmea.gz", lines), tmp_path / "three")
    assert copies == len(rows) + (len(rows) + 3) // 4
    assert merged["tracks"] == single["tracks"] and single["tracks"]["total"] == 32
    assert merged["kept_points"] == single["kept_points"]
    assert merged["rejected"]["duplicate_reception"] == copies
    assert single["rejected"]["duplicate_reception"] == 0
    assert merged["rows_read"] == single["rows_read"] + copies
    for reason, n in single["rejected"].items():
        if reason != "duplicate_reception":
            assert merged["rejected"][reason] == n, reason
    assert_same_points(tmp_path / "three", tmp_path / "one")
    rejects = pq.read_table(tmp_path / "three" / "rejects.parquet").to_pandas()
    raw = rejects.loc[rejects["reason"] == "duplicate_reception", "raw"]
    assert len(raw) == copies and raw.str.contains(r"s:r[23]").all()


def test_the_dma_receivers_copies_are_one_report_each(tmp_path):
    """Real lines of the DMA's receivers: ten sentences, two messages (copies up to 0.7 s apart,
    some with the same time): two rows at the first copy's time, eight copies counted; the
    receivers' tag blocks on lines of their own stay `not_ais`."""
    log = tmp_path / "frio.ais"
    log.write_text(DMA_LINES)
    table, counts = read(log)
    assert counts == {"not_ais": 10, "duplicate_reception": 8}
    assert table.column("mmsi").to_pylist() == [538004030] * 2
    times = [t.isoformat() for t in table.column("time").to_pylist()]
    assert times == ["2014-09-28T16:00:04.684000+00:00", "2014-09-28T16:00:14.794000+00:00"]


def test_only_the_same_message_within_the_window_is_a_copy(tmp_path):
    """Another message of the same vessel a second later is a report; the same message heard
    again after `RECEPTION_WINDOW_S` is one too (a new transmission, or a late replay)."""
    t = 1606780800
    late = t + int(RECEPTION_WINDOW_S) + 1
    log = tmp_path / "log.nmea"
    lines = [f"{t},{POSITION}", f"{t}.3,{POSITION}", f"{t + 1},{OTHER_POSITION}"]
    lines += [f"{t + 2},{POSITION}", f"{late},{POSITION}", f"{late}.5,{POSITION}"]
    lines += [f"yesterday,{POSITION}", f"yesterday,{POSITION}"]  # no time to compare: rows
    log.write_text("\n".join(lines) + "\n")
    table, counts = read(log)
    assert counts == {"duplicate_reception": 3}
    assert table.column("mmsi").to_pylist() == [367309370, 413355820] + [367309370] * 3
    seconds = table.column("time").to_numpy()[:3].astype("datetime64[s]").astype(np.int64)
    assert list(seconds) == [t, t + 1, late]


def test_a_unix_time_after_the_checksum_is_the_report_time(tmp_path):
    """Item 15: `!AIVDM,...*hh,1530428400`, the log of several receivers: the 898 real lines of
    pyais's sample read as with the time in a column before them (762 position reports), not
    as 898 truncated lines; milliseconds and a space before the time read too."""
    lines = (NMEA / "nmea_data_sample.txt").read_text().splitlines()
    before, after = tmp_path / "before.nmea", tmp_path / "after.nmea"
    before.write_text("".join(f"{1530428400 + i},{line}\n" for i, line in enumerate(lines)))
    stamps = [f",{1530428400 + i}" if i % 3 else f" {(1530428400 + i) * 1000}" for i in range(898)]
    after.write_text("".join(f"{line}{s}\n" for line, s in zip(lines, stamps, strict=True)))
    want, want_counts = read(before)
    got, got_counts = read(after)
    assert got_counts == want_counts == {"truncated": 120, "not_position": 16}
    assert got.num_rows == want.num_rows == 762 and got.to_pandas().equals(want.to_pandas())


def test_kitimat_with_the_time_after_the_checksum_ingests_like_tag_blocks(cli, tmp_path):
    """The six Kitimat vessels logged as `!AIVDM,...*hh,<unix time>` give the tracks and points
    of the same reports with tag blocks."""
    reports = encoded(kitimat_rows())
    tags = [tagged(t, sentence, "r1") for t, sentence in reports]
    after = [f"{sentence},{int(t.timestamp())}" for t, sentence in reports]
    want = ingest(cli, write_log(tmp_path / "tags.nmea.gz", tags), tmp_path / "tags")
    got = ingest(cli, write_log(tmp_path / "after.nmea.gz", after), tmp_path / "after")
    assert got["rejected"] == want["rejected"] and got["rejected"]["truncated"] == 0
    assert got["tracks"] == want["tracks"] and want["tracks"]["total"] == 32
    assert_same_points(tmp_path / "after", tmp_path / "tags")


class Planted:
    """What a hostile model file holds: unpickling it would call `open` (here: only a file is
    created; a real one would run a shell)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


@pytest.mark.parametrize("kind", ["weights", "checkpoint"])
def test_a_planted_pickle_is_refused_without_inviting_an_unsafe_load(tmp_path, kind):
    """Item 15: a model or checkpoint holding pickled code is refused in one line that says it
    is not a safe aisdati file and to retrain or use a trusted copy, and never repeats torch's
    advice to load it with `weights_only=False`; nothing in it runs."""
    marker = tmp_path / "ran"
    path = tmp_path / ("down.pt" if kind == "weights" else "down.ckpt")
    torch.save({"trainer": {"w": torch.zeros(2)}, "payload": Planted(marker)}, path)
    with pytest.raises(UserError) as caught:
        (read_weights if kind == "weights" else read_checkpoint)(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message
    assert "not a safe aisdati" in message and "trusted copy" in message
    assert "weights_only" not in message and "trust the source" not in message
    assert "it asks to run io.open" in message  # what it planted
    assert not marker.exists()
    with pytest.raises(pickle.UnpicklingError, match="weights_only"):  # torch's own text
        torch.load(path, weights_only=True)
