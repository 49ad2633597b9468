"""Who each vessel is (`aisdati.preprocess.vessels`): ITU ship-type groups, lengths and AIS
padding; per column the most frequent value, the last seen among equals, over every source;
vessels.parquet and the tracks' vessel columns from real CSV and NMEA files (static messages
5 and 24)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aisdati.preprocess.inputs import Source
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.vessels import VesselTally, length_of, ship_type_of, winners
from aisdati.tracks.schema import VESSEL_SCHEMA

NMEA = Path(__file__).parents[1] / "data" / "nmea"
FRIO = Path(__file__).parents[1] / "data" / "events" / "538004030_drift_1.ais"
"""A real recording of the DMA's receivers: FRIO (MMSI 538004030) drifting, with its type 5
messages (tests/data/events/README.md)."""


@pytest.mark.parametrize(
    ("text", "group"),
    [
        ("30", "Fishing"),
        ("31", "Towing"),
        ("32.0", "Towing"),
        ("35", "Military"),
        ("36", "Sailing"),
        ("37", "Pleasure craft"),
        ("40", "High speed craft"),
        ("49", "High speed craft"),
        ("50", "Pilot"),
        ("51", "Search and rescue"),
        ("52", "Tug"),
        ("55", "Law enforcement"),
        ("60", "Passenger"),
        ("69.0", "Passenger"),
        ("70", "Cargo"),
        ("79", "Cargo"),
        ("80", "Tanker"),
        ("89", "Tanker"),
        ("20", "Other"),
        ("33", "Other"),
        ("90", "Other"),
        ("99", "Other"),
        ("0", None),
        ("100", None),
        ("1004", None),
        ("37.5", None),
        ("Tug", "Tug"),
        ("Pleasure Craft", "Pleasure Craft"),
        ("Undefined", None),
    ],
)
def test_numeric_ship_types_are_their_itu_group_and_text_stays(text, group):
    assert ship_type_of(text) == group


def test_a_length_is_positive_metres():
    assert [length_of(t) for t in ("274", "22.5", "0", "-3", "", "x", "inf")] == [
        274.0, 22.5, None, None, None, None, None,
    ]  # fmt: skip


def tallied(*sources: list[tuple]) -> dict[int, tuple]:
    """Each vessel's values from sources of rows (MMSI, name, type, length), in order."""
    tables = []
    for src, rows in enumerate(sources):
        tally = VesselTally()
        mmsi, name, kind, length = zip(*rows, strict=True)
        columns = {"name": pa.array(name), "ship_type": pa.array(kind), "length": pa.array(length)}
        tally.add(np.array(mmsi), columns, np.arange(len(rows)))
        tables.append(tally.table(src))
    found = winners(tables)
    return {row["mmsi"]: tuple(row.values())[1:] for row in found.to_pylist()}


def test_the_most_frequent_value_wins_per_column_and_the_last_seen_among_equals():
    """Per column, blanks and padding aside: A twice beats B once; a tie goes to the value seen
    last, in the input's order (a later source is later); each column on its own."""
    got = tallied(
        [
            (1, "A@@@@", "37", "10"),
            (1, "B", None, "12"),
            (1, " A ", "Tug", ""),
            (2, "C", "60", "0"),
            (2, "@@@@", "70", None),
            (3, "E", None, None),
            (0, "NO MMSI", "52", "5"),
        ],
        [(2, "D", None, None), (3, "", None, "7")],
    )
    assert got == {
        1: ("A", "Tug", 12.0),
        2: ("D", "Cargo", None),
        3: ("E", None, 7.0),
    }


def test_static_messages_24_a_and_b_and_5_name_a_vessel_by_mmsi():
    """pyais's real samples: a class B vessel's type 24 part A (its name) and part B (its type
    and size), and two type 5 messages."""
    found = {}
    for name in ("nmea_data_sample.txt", "mixed.txt"):
        reader = open_reader(Source(NMEA / name))
        for _ in reader.tables(0):
            pass
        found |= {r["mmsi"]: r for r in winners([reader.vessels.table(0)]).to_pylist()}
    assert found[244270489] == {
        "mmsi": 244270489, "name": "SY-LUNDE", "ship_type": "Sailing", "length_m": 12.0,
    }  # fmt: skip
    assert found[351759000]["name"] == "EVER DIADEM" and found[351759000]["ship_type"] == "Cargo"
    assert found[366989380]["length_m"] == 42.0


def ingested(cli, source: Path, out: Path, *args: str) -> dict:
    result = cli("ingest", "--input", source, "--out", out, "--roi", "none", *args, "--json")
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout)


def test_vessels_parquet_names_every_vessel_of_a_report_and_the_tracks_repeat_it(processed):
    """The NY hour: one row per MMSI of reports.parquet, from the CSV's VesselName, VesselType
    and Length; each track carries its vessel's."""
    vessels = pq.read_table(processed / "vessels.parquet")
    assert vessels.schema.equals(VESSEL_SCHEMA)
    reports = pq.read_table(processed / "reports.parquet", columns=["mmsi"])
    mmsi = vessels.column("mmsi").to_numpy()
    assert np.array_equal(mmsi, np.unique(reports.column("mmsi").to_numpy()))
    by_mmsi = {row["mmsi"]: row for row in vessels.to_pylist()}
    assert by_mmsi[367000140]["name"] == "SAMUEL I NEWHOUSE"
    assert by_mmsi[367000140]["ship_type"] == "Passenger"
    tracks = pq.read_table(processed / "tracks.parquet").to_pylist()
    for track in tracks:
        vessel = by_mmsi[track["mmsi"]]
        assert [track[c] for c in ("name", "ship_type")] == [vessel["name"], vessel["ship_type"]]
    assert sum(t["name"] is not None for t in tracks) == len(tracks) - 1  # one vessel unnamed


def test_frio_is_named_from_its_type_5_messages(cli, tmp_path):
    report = ingested(cli, FRIO, tmp_path, "--min-points", "5")
    (frio,) = pq.read_table(tmp_path / "vessels.parquet").to_pylist()
    assert frio == {"mmsi": 538004030, "name": "FRIO", "ship_type": "Tanker", "length_m": 274.0}
    tracks = pq.read_table(tmp_path / "tracks.parquet").to_pandas()
    assert len(tracks) == report["tracks"]["total"] and (tracks["name"] == "FRIO").all()
