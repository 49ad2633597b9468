"""Interference over an area and gaps' coverage from the command line, on real traffic (the New
York Harbor hour, MarineCadastre: 295 vessels with their reported motion): each constructed
case (`aisdati.evaluation.constructed.CONSTRUCTORS`) written into the ingest output's reports
is found by `aisdati detect --models none`, naming its vessels; the untouched hour raises no
interference; an interference is drawn as an area."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import shapely

from aisdati.evaluation.constructed import CONSTRUCTORS, Case, found, named
from aisdati.tracks.reports import read_reports, read_vessels
from aisdati.tracks.schema import REPORTS_SCHEMA
from tests.helpers.cli import run


def _detect(data: Path, out: Path) -> tuple[pd.DataFrame, dict, dict]:
    got = run("detect", "--data", data, "--models", "none", "--out", out)
    assert got.exit_code == 0, got.output
    report = json.loads((out / "report.json").read_text())
    geojson = json.loads((out / "events.geojson").read_text())
    return pd.read_parquet(out / "events.parquet"), report, geojson


def _written(processed: Path, tmp_path: Path, name: str, tries: int = 400) -> tuple[Path, Case]:
    """A copy of the ingest output with the first case `name`'s constructor writes into its
    reports (seeds 0, 1, ... until the traffic offers one)."""
    reports, identity = read_reports(processed), read_vessels(processed)
    for seed in range(tries):
        built = CONSTRUCTORS[name](reports, identity, np.random.default_rng(seed))
        if built is not None:
            break
    else:
        pytest.fail(f"no place for a {name} case in {tries} draws")
    written, _, case = built
    data = tmp_path / "data"
    shutil.copytree(processed, data)
    shutil.rmtree(data / "reports.parquet")
    (data / "reports.parquet").mkdir()
    table = pa.Table.from_pandas(written[REPORTS_SCHEMA.names], schema=REPORTS_SCHEMA)
    pq.write_table(table, data / "reports.parquet" / "part-00000.parquet")
    return data, case


def test_the_untouched_hour_raises_no_interference(processed, tmp_path):
    events, report, _ = _detect(processed, tmp_path / "out")
    assert "gnss-interference" not in set(events["kind"])
    assert set(report["gaps_by_coverage"]) == {"heard", "quiet", "unjudged"}


def test_a_block_displaced_together_is_one_interference_drawn_as_an_area(processed, tmp_path):
    data, case = _written(processed, tmp_path, "gnss-interference")
    events, report, geojson = _detect(data, tmp_path / "out")
    assert found(case, events), events[["kind", "mmsi", "start", "end", "evidence"]]
    area = events[events["kind"] == "gnss-interference"]
    assert len(area) == 1  # one event for the area, not one per vessel
    assert set(case.mmsis) <= named(area.iloc[0])
    # the vessels' own position jumps during it are folded into it
    jumps = events[(events["kind"] == "position-jump") & events["mmsi"].isin(case.mmsis)]
    assert not ((jumps["start"] <= case.end) & (jumps["end"] >= case.start)).any()
    outline = shapely.from_wkb(area["geometry"].iloc[0])
    assert outline.geom_type == "Polygon" and outline.is_valid
    drawn = [f for f in geojson["features"] if f["properties"]["kind"] == "gnss-interference"]
    assert drawn[0]["geometry"]["type"] == "Polygon"
    assert report["events_by_kind"]["gnss-interference"] == 1


@pytest.mark.parametrize("name", ["gap-heard", "gap-quiet"])
def test_a_silenced_vessel_says_whether_its_area_kept_being_heard(processed, tmp_path, name):
    data, case = _written(processed, tmp_path, name)
    events, report, _ = _detect(data, tmp_path / "out")
    assert found(case, events), events[events["kind"] == "gap"]
    assert report["gaps_by_coverage"][case.coverage] >= 1
