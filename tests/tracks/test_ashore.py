"""The ashore rule (`aisdati.tracks.ashore`) on real tracks. Kitimat: no real track of the two
months has a report ashore; a report just inside the coastline (within the margin) is not
ashore; a stretch of a real track moved inland flags the track whatever its score, ranks it
first, and `--no-ashore` judges by the model alone. NY Harbor: the creeks and rivers that the
coastline calls land are excused where other vessels' traffic sailed them, and a model's card
records that water (older cards, without it, still load). `evaluate --at-sea` writes only
anomalies that stay off the land."""

from __future__ import annotations

import json
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from aisdati.ais.training import TrainSettings
from aisdati.coastline import on_land
from aisdati.detection.run import DetectSettings, detect
from aisdati.detectors import load_detector
from aisdati.detectors.nearest import NearestDetector
from aisdati.geo import EARTH_RADIUS_M, courses_deg
from aisdati.tracks import ashore
from aisdati.tracks.ashore import LIFT_M, AshoreCheck, ashore_counts
from aisdati.tracks.store import Track, load_tracks, read_track_table
from tests.helpers.area import AUGUST, save_nearest

RULE = AshoreCheck()
NY_WEEK = Path(__file__).parents[1] / "data" / "NYHarbor_2020_12_first_week_points.csv.gz"


def moved(point: np.ndarray, bearing_deg: float, metres: float) -> np.ndarray:
    b = np.radians(bearing_deg)
    dlat = np.degrees(metres * np.cos(b) / EARTH_RADIUS_M)
    dlon = np.degrees(metres * np.sin(b) / EARTH_RADIUS_M) / np.cos(np.radians(point[1]))
    return point + np.array([dlon, dlat])


def first_land(point: np.ndarray, bearing: float) -> float:
    """Metres from `point` (at sea) along `bearing` to the coastline, to within 5 m."""
    lo, hi = 0.0, 500.0
    while not on_land(*moved(point, bearing, hi))[()]:
        lo, hi = hi, hi + 500.0
    while hi - lo > 5.0:
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if on_land(*moved(point, bearing, mid))[()] else (mid, hi)
    return hi


@pytest.fixture(scope="module")
def tracks(kitimat) -> list[Track]:
    table = read_track_table(kitimat)
    return load_tracks(kitimat, [int(i) for i in table["track_id"]])


@pytest.fixture(scope="module")
def inland(tracks) -> tuple[Track, slice, float, np.ndarray]:
    """An August track, the stretch of 6 reports to move, the bearing across its course and
    the distance that puts the stretch's first report 2 km past the coastline."""
    track = next(t for t in tracks if t.start >= AUGUST)
    at = len(track.positions) // 2
    bearing = float(courses_deg(track.positions)[at]) + 90.0
    coast_m = first_land(track.positions[at], bearing)
    return track, slice(at, at + 6), bearing, np.float64(coast_m + 2000.0)


def test_no_real_track_of_the_two_months_has_a_report_ashore(tracks):
    counts = RULE.counts([t.positions for t in tracks])
    assert len(tracks) == 158 and counts.sum() == 0


def test_a_report_inside_the_margin_is_on_land_but_not_ashore(inland):
    track, stretch, bearing, _ = inland
    point = track.positions[stretch.start]
    coast_m = first_land(point, bearing)
    near = moved(point, bearing, coast_m + 0.25 * RULE.margin_m)[None, :]
    assert on_land(near[:, 0], near[:, 1])[0]
    assert not RULE.reports(near)[0]


def test_a_stretch_moved_inland_flags_its_track_and_ranks_it_first(
    kitimat, tracks, inland, tmp_path
):
    track, stretch, bearing, metres = inland
    data = tmp_path / "data"
    shutil.copytree(kitimat, data)
    shutil.rmtree(data / "points.parquet")  # one file instead of ingest's folder of parts
    shutil.rmtree(data / "reports.parquet")  # the events read the moved points too
    points = ds.dataset(kitimat / "points.parquet").to_table()
    frame = points.to_pandas()
    rows = np.flatnonzero(frame["track_id"].to_numpy() == track.track_id)[stretch]
    for r in rows:
        frame.loc[r, ["lon", "lat"]] = moved(frame.loc[r, ["lon", "lat"]].to_numpy(float),
                                             bearing, metres)  # fmt: skip
    table = pa.Table.from_pandas(frame, schema=points.schema, preserve_index=False)
    pq.write_table(table, data / "points.parquet")
    models = tmp_path / "models"
    models.mkdir()
    save_nearest([t for t in tracks if t.start < AUGUST], "all", models)
    settings = DetectSettings(data_dir=data, models_dir=models, out_dir=tmp_path / "out",
                              method="nearest", cluster="all", contamination=0.05)  # fmt: skip
    ruled = detect(settings).scores.set_index("track_id")
    assert ruled.loc[track.track_id, "ashore_reports"] >= RULE.min_reports
    assert ruled.loc[track.track_id, "rank"] == 1 and ruled.loc[track.track_id, "flagged"]
    assert (ruled.drop(track.track_id)["ashore_reports"] == 0).all()
    model = detect(replace(settings, ashore=False))
    alone = model.scores.set_index("track_id")
    cut = model.models[0].threshold(settings.how_for(model.models[0]), 0.05)
    assert (alone["ashore_reports"] == 0).all()
    assert (alone["flagged"] == ((alone["score"] > cut) | (alone["alerts"] > 0))).all()
    # the rule adds its flag to the model's and leaves every score as the model gave it
    assert np.allclose(ruled["score"], alone.loc[ruled.index, "score"])
    by_rule = (ruled["ashore_reports"] >= 2) | (ruled["alerts"] > 0)
    assert (ruled["flagged"] == (alone.loc[ruled.index, "flagged"] | by_rule)).all()


def test_ranked_puts_tracks_ashore_above_every_track_at_sea():
    scores = np.array([5.0e5, 10.0, 20.0, 3.0])
    counts = np.array([0, 2, 1, 4])
    lengths = np.array([100, 100, 100, 10])
    ranked = RULE.ranked(scores, counts, lengths)
    assert list(np.argsort(-ranked)) == [3, 1, 0, 2]  # 40 % ashore, 2 %, then by score
    assert ranked[0] == scores[0] and ranked[2] == scores[2] and ranked[1] > LIFT_M


def test_evaluate_reports_the_rule_and_scores_without_it(cli, kitimat, tmp_path):
    args = (
        "evaluate",
        "--data",
        kitimat,
        "--cluster",
        "all",
        "--before",
        "2018-08-01",
        "--detectors",
        "nearest",
        "--kinds",
        "detour,jump",
        "--altered",
        "0.5",
        "--fleet-kinds",
        "none",
    )
    ruled = cli(*args, "--out", tmp_path / "ruled")  # fmt: skip
    assert ruled.exit_code == 0, ruled.output
    alone = cli(*args, "--no-ashore", "--models", tmp_path / "ruled" / "models",
                "--out", tmp_path / "alone")  # fmt: skip
    assert alone.exit_code == 0, alone.output
    doc = {
        k: json.loads((tmp_path / k / "evaluation.json").read_text()) for k in ("ruled", "alone")
    }
    assert doc["alone"]["ashore"] == {"normal": 0, "altered": 0}
    assert doc["ruled"]["ashore"]["normal"] == 0 and doc["ruled"]["ashore"]["altered"] > 0
    auc = {k: next(r["roc_auc"] for r in d["results"] if (r["score"], r["kind"]) == ("lane", "all"))
           for k, d in doc.items()}  # fmt: skip
    # no normal track is ashore, so lifting altered tracks ashore can only raise the AUC
    assert auc["ruled"] >= auc["alone"]
    scores = pq.read_table(tmp_path / "ruled" / "scores.parquet")
    flagged = pc.sum(pc.greater_equal(scores["ashore_reports"], 2)).as_py()
    assert flagged > 0


@pytest.fixture(scope="module")
def ny_tracks(tmp_path_factory) -> list[Track]:
    """NY Harbor's first week of December 2020 (`--roi none --min-points 50`: 206 tracks)."""
    from aisdati.cli import app

    out = tmp_path_factory.mktemp("nyweek")
    args = ["ingest", "--input", str(NY_WEEK), "--roi", "none", "--min-points", "50"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    table = read_track_table(out)
    return load_tracks(out, [int(i) for i in table["track_id"]])


def test_water_other_vessels_sailed_is_not_ashore(ny_tracks):
    """Newtown Creek, the Bronx River, the Raritan: the coastline calls them land. Each track
    is checked with the water that the other vessels' tracks reported in (as a card records
    its training traffic's): most of the creek traffic is then not ashore."""
    positions = [t.positions for t in ny_tracks]
    alone = RULE.flags(RULE.counts(positions))
    excused = []
    for i in np.flatnonzero(alone):
        others = [p for p, t in zip(positions, ny_tracks, strict=True)
                  if t.mmsi != ny_tracks[i].mmsi]  # fmt: skip
        seen = np.asarray(RULE.seen(others))
        excused.append(not RULE.flags(RULE.counts([positions[i]], seen))[0])
    assert alone.sum() >= 10 and sum(excused) >= alone.sum() / 2
    # the water a track sailed itself is always excused: training tracks are never ashore
    seen = np.asarray(RULE.seen(positions))
    assert len(seen) < sum(len(p) for p in positions) / 100  # a few points per creek
    assert RULE.counts(positions, seen).sum() == 0


def test_a_card_records_its_traffics_water_and_old_cards_still_load(ny_tracks, tmp_path):
    det = NearestDetector(TrainSettings(cluster="all")).fit(ny_tracks)
    det.save(tmp_path / "all")
    loaded = load_detector(tmp_path / "all")
    assert np.allclose(loaded.card.data.ashore, RULE.seen([t.positions for t in ny_tracks]))
    assert len(loaded.card.data.ashore) > 0
    card = json.loads((tmp_path / "all.json").read_text())
    card["data"].pop("ashore_points")
    (tmp_path / "old.json").write_text(json.dumps(card))
    for f in tmp_path.glob("all.*"):
        if f.suffix != ".json":  # all.npz, all.corridor.npz
            shutil.copy2(f, tmp_path / f.name.replace("all.", "old.", 1))
    old = load_detector(tmp_path / "old")
    assert old.card.data.ashore_points is None and old.card.data.ashore.shape == (0, 2)


def test_evaluate_at_sea_writes_only_anomalies_a_vessel_could_sail(cli, kitimat, tmp_path):
    out = tmp_path / "sea"
    r = cli("evaluate", "--data", kitimat, "--cluster", "all", "--before",
            "2018-08-01", "--detectors", "nearest", "--kinds", "detour,jump", "--altered", "0.5",
            "--at-sea", "--fleet-kinds", "none", "--out", out)  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "--at-sea:" in r.output
    doc = json.loads((out / "evaluation.json").read_text())
    split = doc["split"]
    drawn = round(split["heldout_tracks"] * 0.5)
    assert split["injected"] + len(split["not_at_sea"]) == drawn and split["injected"] > 0
    assert doc["ashore"] == {"normal": 0, "altered": 0}  # none of them is flagged by the rule
    labels = pd.read_csv(out / "data" / "labels.csv")
    altered = labels[labels["label"] == 1]
    mine = load_tracks(out / "data", [int(i) for i in altered["track_id"]])
    assert RULE.counts([t.positions for t in mine]).sum() == 0


def test_the_check_on_two_dask_workers_counts_as_in_process(ny_tracks, monkeypatch):
    """NY Harbor's later tracks judged by a nearest model of the first four days, the check
    split into tasks of 16 tracks on a real local cluster of 2 worker processes."""
    import distributed

    from aisdati.execution.runner import DaskRunner

    before = pd.Timestamp("2020-12-05", tz="UTC")
    past = [t for t in ny_tracks if t.start < before]
    later = [t for t in ny_tracks if t.start >= before]
    model = NearestDetector(TrainSettings(cluster="all")).fit(past)
    monkeypatch.setattr(ashore, "ASHORE_TRACKS", 16)
    seen, positions = [model.card.data.ashore], [t.positions for t in later]
    owner = [0] * len(later)
    here = ashore_counts(seen, positions, owner)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                 dashboard_address=":0") as local,
        distributed.Client(local) as client,
    ):  # fmt: skip
        there = ashore_counts(seen, positions, owner, DaskRunner(client))
    assert len(later) > 2 * 16 and here.sum() > 0
    np.testing.assert_array_equal(here, there)
    alone = RULE.counts([t.positions for t in later])  # the model's water excuses some
    assert (here <= alone).all()


def test_on_the_coarse_fallback_coastline_the_rule_is_off_with_a_warning(
    ny_tracks, monkeypatch
):
    """Natural Earth's 1:110m outline puts harbour water on land; the rule then flags nothing
    and says why (the fallback is what an install without roaring-landmask gets)."""
    from aisdati import coastline

    model = NearestDetector(TrainSettings(cluster="all")).fit(ny_tracks[:20])
    assert AshoreCheck.available()
    seen, positions = [model.card.data.ashore], [t.positions for t in ny_tracks]
    with_osm = ashore_counts(seen, positions, [0] * len(ny_tracks))
    coastline.clear_caches()
    monkeypatch.setitem(sys.modules, "roaring_landmask", None)  # its import raises ImportError
    try:
        with (
            pytest.warns(RuntimeWarning, match="roaring-landmask is not installed"),
            pytest.warns(RuntimeWarning, match="ashore rule is off"),
        ):
            assert not AshoreCheck.available()
            off = ashore_counts(seen, positions, [0] * len(ny_tracks))
    finally:
        monkeypatch.undo()
        coastline.clear_caches()
    assert with_osm.sum() > 0 and off.sum() == 0
