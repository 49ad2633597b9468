"""`aisdati evaluate` end to end on the real Kitimat tracks."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd

from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import read_track_table


def _evaluate(cli, data, out, *extra):
    return cli(
        "evaluate", "--data", data, "--cluster", "other", "--detectors", "nearest", "--out", out,
        "--fleet-kinds", "none",
        *extra,
    )


def test_evaluate_nearest_is_deterministic_and_writes_everything(cli, kitimat, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert _evaluate(cli, kitimat, a, "--seed", "3").exit_code == 0
    r = _evaluate(cli, kitimat, b, "--seed", "3")
    assert r.exit_code == 0, r.output
    la, lb = pd.read_csv(a / "data" / "labels.csv"), pd.read_csv(b / "data" / "labels.csv")
    pd.testing.assert_frame_equal(la, lb)
    assert set(la["kind"].dropna()) == {"detour", "jump", "loiter", "speed", "gap", "noise"}
    sa, sb = pd.read_parquet(a / "scores.parquet"), pd.read_parquet(b / "scores.parquet")
    pd.testing.assert_frame_equal(sa, sb)
    doc = json.loads((a / "evaluation.json").read_text())
    train = set(doc["split"]["training_track_ids"])
    table = read_track_table(kitimat).set_index("track_id")
    held = set(la["source_track_id"])
    assert not set(table.loc[list(train), "mmsi"]) & set(table.loc[list(held), "mmsi"])
    alld = next(r for r in doc["results"] if r["kind"] == "detour+jump+loiter")
    assert alld["roc_auc"] > 0.5
    for name in ("roc_pr.png", "examples.png"):
        assert (a / name).stat().st_size > 10_000
    # the injected set is an ingest output: detect reads it
    det = cli(
        "detect", "--data", a / "data", "--models", a / "models", "--method", "nearest",
        "--cluster", "other", "--labels", a / "data" / "labels.csv", "--out", tmp_path / "r",
        "--contamination", "0.05", "--score", "lane",
    )
    assert det.exit_code == 0, det.output
    assert "ROC AUC" in det.output
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["score_definition"].startswith("mean of the largest 10%")


def test_evaluate_other_seed_changes_the_injected_set(cli, kitimat, tmp_path):
    assert _evaluate(cli, kitimat, tmp_path / "a", "--seed", "1").exit_code == 0
    assert _evaluate(cli, kitimat, tmp_path / "b", "--seed", "2").exit_code == 0
    la = pd.read_csv(tmp_path / "a" / "data" / "labels.csv")
    lb = pd.read_csv(tmp_path / "b" / "data" / "labels.csv")
    assert not la.equals(lb)


def test_evaluate_bad_input_is_one_line_and_writes_nothing(cli, kitimat, tmp_path):
    cases = [
        (("--cluster", "down"), "evaluate needs at least"),
        (("--kinds", "detour,teleport"), "unknown anomaly kind"),
        (("--fleet-kinds", "encounter,teleport"), "unknown fleet kind 'teleport'"),
        (("--fleet-cases", "0"), "--fleet-cases must be at least 1"),
        (("--detectors", "nearest,magic"), "unknown detector"),
        (("--param", "jump.km=9-3"), "--param"),
        (("--lane", "region=land"), "region must be one of"),
    ]
    for i, (extra, needle) in enumerate(cases):
        out = tmp_path / f"o{i}"
        args = ["evaluate", "--data", kitimat, "--cluster", "other", "--detectors", "nearest"]
        r = cli(*args, "--out", out, *extra)
        assert r.exit_code == 2, r.output
        errors = [line for line in r.stderr.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and needle in errors[0], r.output  # beside the stages run
        assert "Traceback" not in r.output
        assert not (out / "evaluation.json").exists()


def test_evaluate_refuses_models_of_another_region(cli, kitimat, tmp_path):
    models = tmp_path / "models"
    r = cli("train", "--cluster", "other", "--method", "nearest", "--data", kitimat, "--out",
            models)
    assert r.exit_code == 0, r.output
    card_path = models / "other-nearest.json"
    card = json.loads(card_path.read_text())
    card["region"]["lon"] = [x + 30 for x in card["region"]["lon"]]
    card_path.write_text(json.dumps(card))
    out = tmp_path / "ev"
    r = cli("evaluate", "--data", kitimat, "--cluster", "other", "--detectors", "nearest",
            "--models", models, "--out", out)  # not quiet: no progress line before the error
    assert r.exit_code == 2, r.output
    assert "another region" in r.output and len(r.output.strip().splitlines()) == 1
    assert not (out / "evaluation.json").exists()


def test_evaluate_every_route_pools_scores_on_each_routes_threshold(cli, kitimat, tmp_path):
    out = tmp_path / "routes"
    r = cli("evaluate", "--data", kitimat, "--cluster", "routes", "--detectors", "nearest",
            "--kinds", "detour,jump,loiter", "--fleet-kinds", "none", "--out", out)
    assert r.exit_code == 0, r.output
    assert "over 2 routes" in " ".join(r.output.split())
    doc = json.loads((out / "evaluation.json").read_text())
    routes = read_track_table(kitimat)["route"].dropna().value_counts()
    small = sorted(n for n, c in routes.items() if c < 20)
    assert sorted(doc["routes"]) == ["route-1", "route-2"] and sorted(doc["skipped"]) == small
    assert all("evaluate needs at least" in why for why in doc["skipped"].values())
    scores = pd.read_parquet(out / "scores.parquet")
    assert set(scores["route"]) == {"route-1", "route-2"}
    np.testing.assert_allclose(scores["ratio"], scores["value"] / scores["threshold"])
    ashore = scores["ashore_reports"] >= AshoreCheck().min_reports  # flagged by the rule too
    np.testing.assert_array_equal(scores["flagged"], (scores["ratio"] > 1) | ashore)
    assert set(scores["score"]) == {"nearest", "lane"}  # nearest's DTW and lane scores
    for route, info in doc["routes"].items():
        per = json.loads((out / route / "evaluation.json").read_text())
        assert per["split"]["heldout_tracks"] == info["heldout_tracks"]
        for _, g in scores[scores["route"] == route].groupby("score"):
            assert len(g) == info["heldout_tracks"]
    pooled = next(r for r in doc["results"] if r["kind"] == "all")
    assert pooled["anomalies"] == sum(i["injected"] for i in doc["routes"].values())
    assert pooled["roc_auc"] > 0.5


def test_evaluate_every_route_needs_routes(cli, kitimat, tmp_path):
    data = tmp_path / "direction"  # as ingest --clusters direction writes it: no routes
    data.mkdir()
    shutil.copytree(kitimat / "points.parquet", data / "points.parquet")  # a dataset folder
    tracks = pd.read_parquet(kitimat / "tracks.parquet")
    tracks.assign(route=None).to_parquet(data / "tracks.parquet")
    r = cli("evaluate", "--data", data, "--cluster", "routes", "--detectors", "nearest",
            "--out", tmp_path / "o")
    assert r.exit_code == 2 and "no route in" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1


def test_evaluate_reports_events_on_the_reported_motion_kinds_thinned(cli, kitimat, tmp_path):
    """Issue 59 (part 5): the new kinds, --thin, and the event metrics in evaluation.json and
    the printed table, from the events detect would find."""
    out = tmp_path / "ev"
    kinds = "shift,course-noise,speed-noise,gap,drift,detour"
    r = _evaluate(cli, kitimat, out, "--kinds", kinds, "--thin", "2min", "--altered", "0.6")
    assert r.exit_code == 0, r.output
    assert "Events on the injected stretches" in r.output
    doc = json.loads((out / "evaluation.json").read_text())
    assert doc["settings"]["thin_s"] == 120.0
    rows = {row["kind"]: row for row in doc["events"]["results"]}
    assert set(rows) == {*kinds.split(","), "any"}
    assert doc["events"]["right_events"]["drift"] == ["drift"]
    for kind in kinds.split(","):
        row = rows[kind]
        assert row["anomalies"] >= 1 and 0 <= row["overlapped"] <= row["overlapped_any"] <= 1
        low, high = row["overlapped_ci"]
        assert low <= row["overlapped"] <= high
    found = sum(rows[k]["overlapped"] * rows[k]["anomalies"] for k in ("shift", "gap"))
    assert found >= 1  # a shifted stretch or a gap is found on real tracks
    points = pd.read_parquet(out / "data" / "points.parquet")
    labels = pd.read_csv(out / "data" / "labels.csv")
    points = points[~points["track_id"].isin(labels.loc[labels["label"] == 1, "track_id"])]
    gaps = points.sort_values("time").groupby("track_id")["time"].diff().dropna()
    assert gaps.min() >= pd.Timedelta("2min")
    bad = cli("evaluate", "--data", kitimat, "--cluster", "other", "--thin", "soon",
              "--out", tmp_path / "bad")  # fmt: skip
    assert bad.exit_code == 2 and "--thin" in bad.output
