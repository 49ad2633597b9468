"""Identity from the command line, on real Kitimat traffic: two real vessels' reports under one
MMSI give one `identity-conflict` naming the MMSI and its second transmitter's id (no report of
the second dropped as an outlier, the ingest report lists the MMSI), and a vessel renamed
mid-period gives one `identity-change` with before and after (and the shared MMSI's two
lengths another); `detect --models none` finds
both, and untouched traffic gives neither."""

from __future__ import annotations

import json

import pandas as pd
import pytest

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
    outputs = {}
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
    (conflict,) = events[events["kind"] == "identity-conflict"].to_dict("records")
    assert conflict["mmsi"] == FIRST and conflict["class"] == "alert"
    assert [o["mmsi"] for o in json.loads(conflict["others"])] == [FIRST + 1_000_000_000]
    assert "km apart at once" in conflict["evidence"]


def test_a_rename_is_raised_with_before_and_after(traffic):
    _, events = traffic["changed"]
    changes = events[events["kind"] == "identity-change"].set_index("mmsi")
    (change,) = changes.loc[[RENAMED]].itertuples()
    assert change.name == "SPIRIT OF KITIMAT"
    assert "name 'NORTHERN SPIRIT' -> 'SPIRIT OF KITIMAT'" in change.evidence
    # the two vessels under one MMSI report two lengths: that is a change too
    assert "length 20 m -> 14 m" in changes.loc[FIRST, "evidence"]


def test_untouched_traffic_raises_neither(traffic):
    data, events = traffic["untouched"]
    assert not events["kind"].isin(["identity-conflict", "identity-change"]).any()
    assert json.loads((data / "ingest_report.json").read_text())["two_transmitters"] == []
