"""Identity from the command line, on real Kitimat traffic: two real vessels' reports under one
MMSI give one `identity-conflict` naming the MMSI and its second transmitter's id (no report of
the second dropped as an outlier, the ingest report lists the MMSI), and a vessel renamed
mid-period gives one `identity-change` with before and after (and the shared MMSI's two
lengths another); the same traffic as NMEA (positions, and the renamed vessel's type 5
messages) gives the same identity events in `watch` as in ingest + `detect --models none`;
and untouched traffic gives neither."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from pyais.encode import encode_dict

from tests.helpers.cli import run
from tests.helpers.live import ROOT

KITIMAT = ROOT / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz"
FIRST, SECOND, RENAMED = 100000496, 100000692, 100000187
"""Two vessels that sail at once 25 km apart in July 2018, and one with 364 reports."""


@pytest.fixture(scope="module")
def traffic(tmp_path_factory) -> tuple:
    """The three vessels' real rows: as recorded, and with the second's reports under the
    first's MMSI and the third's name changed half way through its reports."""
    rows = pd.read_csv(KITIMAT, dtype=str)
    rows = rows[rows["MMSI"].astype(int).isin([FIRST, SECOND, RENAMED])]
    changed = rows.copy()
    changed.loc[changed["MMSI"] == str(SECOND), "MMSI"] = str(FIRST)
    renamed = changed.index[changed["MMSI"] == str(RENAMED)]
    half = len(renamed) // 2
    changed.loc[renamed[:half], "VesselName"] = "NORTHERN SPIRIT"
    changed.loc[renamed[half:], "VesselName"] = "SPIRIT OF KITIMAT"
    folder = tmp_path_factory.mktemp("identity")
    outputs = {"nmea": as_nmea(changed, folder / "changed.nmea")}
    for name, frame in (("untouched", rows), ("changed", changed)):
        path = folder / f"{name}.csv"
        frame.to_csv(path, index=False)
        data, out = folder / f"{name}-data", folder / f"{name}-detect"
        got = run("ingest", "--input", path, "--roi", "none", "--min-points", "5", "--out", data)
        assert got.exit_code == 0, got.output
        assert run("detect", "--data", data, "--models", "none", "--out", out).exit_code == 0
        outputs[name] = (data, pd.read_parquet(out / "events.parquet"))
    return outputs


def test_one_mmsi_from_two_vessels_is_split_and_raised(traffic):
    data, events = traffic["changed"]
    report = json.loads((data / "ingest_report.json").read_text())
    assert report["two_transmitters"] == [FIRST]
    kept = pd.read_parquet(data / "reports.parquet")
    assert (kept["mmsi"] == FIRST + 1_000_000_000).sum() > 100
    conflicts = events[events["kind"] == "identity-conflict"].to_dict("records")
    assert len(conflicts) >= 5  # one per stretch in which both sail: the days of July 16-25
    for conflict in conflicts:
        assert conflict["mmsi"] == FIRST and conflict["class"] == "alert"
        assert [o["mmsi"] for o in json.loads(conflict["others"])] == [FIRST + 1_000_000_000]
        assert "km apart at once" in conflict["evidence"]


def test_a_rename_is_raised_with_before_and_after(traffic):
    _, events = traffic["changed"]
    changes = events[events["kind"] == "identity-change"].set_index("mmsi")
    (change,) = changes.loc[[RENAMED]].itertuples()
    assert change.name == "SPIRIT OF KITIMAT"
    assert change.evidence == "name 'NORTHERN SPIRIT' -> 'SPIRIT OF KITIMAT'"
    # the two vessels under one MMSI report two lengths: that is a change too
    assert "length 20 m -> 14 m" in changes.loc[FIRST, "evidence"]


def test_untouched_traffic_raises_neither(traffic):
    data, events = traffic["untouched"]
    assert not events["kind"].isin(["identity-conflict", "identity-change"]).any()
    assert json.loads((data / "ingest_report.json").read_text())["two_transmitters"] == []


def as_nmea(rows: pd.DataFrame, path: Path) -> Path:
    """The rows as a receiver would log them: a type 1 report each, and before each of the
    renamed vessel's a type 5 message with its name (a passenger ship of 285 m), each line
    stamped by an NMEA 4.0 tag block."""
    lines = []
    for r in rows.sort_values("BaseDateTime", kind="stable").itertuples():
        stamp = f"\\c:{int(pd.Timestamp(r.BaseDateTime, tz='UTC').timestamp())}*00\\"
        if int(r.MMSI) == RENAMED:
            static = {"type": 5, "mmsi": RENAMED, "shipname": r.VesselName, "ship_type": 60,
                      "to_bow": 200, "to_stern": 85}  # fmt: skip
            lines += [stamp + s for s in encode_dict(static, talker_id="AI")]
        report = {"type": 1, "mmsi": int(r.MMSI), "lat": float(r.LAT), "lon": float(r.LON),
                  "speed": float(r.SOG), "course": float(r.COG) % 360, "heading": 511,
                  "status": 0}  # fmt: skip
        lines.append(stamp + encode_dict(report, talker_id="AI")[0])
    path.write_text("\n".join(lines) + "\n")
    return path


def identity_events(frame: pd.DataFrame) -> pd.DataFrame:
    mine = frame[frame["kind"].isin(["identity-conflict", "identity-change"])]
    return mine.sort_values(["kind", "mmsi", "start"], ignore_index=True)


def test_watch_raises_the_same_identity_events_as_detect(traffic, tmp_path):
    nmea = traffic["nmea"]
    data, out = tmp_path / "data", tmp_path / "detect"
    assert run("ingest", "--input", nmea, "--roi", "none", "--min-points", "5",
               "--out", data).exit_code == 0  # fmt: skip
    assert run("detect", "--data", data, "--models", "none", "--out", out).exit_code == 0
    batch = identity_events(pd.read_parquet(out / "events.parquet"))
    got = run("watch", "--input", nmea, "--speed", "1e9", "--db", tmp_path / "w.sqlite", "--json")
    assert got.exit_code == 0, got.output
    latest = {r["event_id"]: r for r in map(json.loads, got.stdout.splitlines())}
    live = pd.DataFrame(list(latest.values()))
    live["start"] = pd.to_datetime(live["start"], utc=True)
    live = identity_events(live.assign(end=pd.to_datetime(live["end"], utc=True)))
    assert sorted(set(batch["kind"])) == ["identity-change", "identity-conflict"]
    (change,) = live[live["kind"] == "identity-change"].to_dict("records")
    want = batch[batch["kind"] == "identity-change"].iloc[0]
    assert (change["mmsi"], change["start"]) == (RENAMED, want["start"])
    assert change["evidence"] == want["evidence"] == "name 'NORTHERN SPIRIT' -> 'SPIRIT OF KITIMAT'"
    # the watch judges 3-hour windows: it raises a stretch's conflict once a window holds 10
    # reports of each transmitter (these vessels report every 6 minutes), so within the
    # batch's stretch, from its start where the stretch opens with both sailing
    conflicts = live[live["kind"] == "identity-conflict"]
    stretches = batch[batch["kind"] == "identity-conflict"]
    assert set(conflicts["mmsi"]) == {FIRST}
    matched = set()
    for c in conflicts.itertuples():
        (k,) = stretches.index[(stretches["start"] <= c.start) & (stretches["end"] >= c.end)]
        matched.add(k)
    assert len(matched) >= 0.75 * len(stretches)
    assert conflicts["start"].min() == stretches["start"].min()
