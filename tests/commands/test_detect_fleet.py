"""`detect --models none` on real Kitimat traffic with one encounter constructed in it (two
real vessels' real reports brought together at sea for hours): the encounter is found from the
command line, naming both vessels and drawn as both vessels' stretches; the anchorages it
judged by are written and read back by `--ports` to the same events; a bad `--ports` file is
one line."""

from __future__ import annotations

import json

import pandas as pd

from aisdati.evaluation.constructed import found, named
from tests.helpers.cli import one_line_error, run
from tests.helpers.meetings import as_ingest_output, met


def test_detect_without_models_finds_a_constructed_encounter_naming_both(kitimat, tmp_path):
    reports, _identity, case = met(kitimat, seed=3)
    data = as_ingest_output(kitimat, reports, tmp_path / "data")
    got = run("detect", "--data", data, "--models", "none", "--out", tmp_path / "out")
    assert got.exit_code == 0, got.output
    events = pd.read_parquet(tmp_path / "out" / "events.parquet")
    assert found(case, events)
    meeting = events[(events["kind"] == "encounter")
                     & events.apply(lambda e: set(case.mmsis) <= named(e), axis=1)]  # fmt: skip
    assert len(meeting) == 1
    others = json.loads(meeting["others"].iloc[0])
    assert {int(meeting["mmsi"].iloc[0]), others[0]["mmsi"]} == set(case.mmsis)
    drawn = json.loads((tmp_path / "out" / "events.geojson").read_text())["features"]
    lines = [f["geometry"] for f in drawn if f["properties"]["kind"] == "encounter"
             and f["properties"]["mmsi"] == int(meeting["mmsi"].iloc[0])]  # fmt: skip
    assert lines[0]["type"] == "MultiLineString" and len(lines[0]["coordinates"]) == 2  # both
    ports = tmp_path / "out" / "anchorages.geojson"
    assert json.loads(ports.read_text())["features"]
    again = run("detect", "--data", data, "--models", "none", "--ports", ports,
                "--out", tmp_path / "again")  # fmt: skip
    assert again.exit_code == 0, again.output
    same = pd.read_parquet(tmp_path / "again" / "events.parquet")
    keys = ["mmsi", "kind", "start", "end"]
    assert same[keys].equals(events[keys])


def test_a_ports_file_that_is_not_geojson_is_one_line(kitimat, tmp_path):
    bad = tmp_path / "ports.geojson"
    bad.write_text("not json")
    got = run("detect", "--data", kitimat, "--models", "none", "--ports", bad,
              "--out", tmp_path / "out")  # fmt: skip
    one_line_error(got, "--ports")
