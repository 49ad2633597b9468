"""`aisdati evaluate` and the injected anomalies, on the real Kitimat tracks."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from aisdati.evaluation.inject import DEFAULTS, inject, parse_params
from aisdati.geo import haversine_m
from aisdati.tracks.ashore import AshoreCheck
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def track(kitimat):
    table = read_track_table(kitimat)
    tid = int(table.sort_values("n_points").iloc[len(table) // 2]["track_id"])
    (t,) = load_tracks(kitimat, [tid])
    return t


def _times(t):
    return np.r_[0.0, np.cumsum(t.dts)] * 3600.0


def _dist(a, b):
    return haversine_m(a[:, 0], a[:, 1], b[:, 0], b[:, 1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_detour_moves_only_its_stretch_by_at_most_its_amplitude(track, seed):
    got = inject("detour", track.positions, _times(track), np.random.default_rng(seed))
    i, j = got.stretch
    d = _dist(got.positions, track.positions)
    assert np.all(d[:i] == 0) and np.all(d[j:] == 0)
    lo, hi = DEFAULTS["detour"]["span"]
    assert lo * len(d) - 1 <= j - i <= hi * len(d) + 1
    assert 0.9 * 2000 * np.sin(np.pi * 0.45) ** 2 < d[i:j].max() <= 5000 * 1.01
    np.testing.assert_array_equal(got.times_s, _times(track))


def test_jump_displaces_a_stretch_by_one_vector(track):
    got = inject("jump", track.positions, _times(track), np.random.default_rng(3))
    i, j = got.stretch
    d = _dist(got.positions, track.positions)
    assert np.all(d[:i] == 0) and np.all(d[j:] == 0)
    assert np.all((d[i:j] > 2990) & (d[i:j] < 6010))
    assert d[i:j].max() - d[i:j].min() < 50  # one displacement for the whole stretch


def test_loiter_inserts_circles_and_shifts_later_times(track):
    t = _times(track)
    got = inject("loiter", track.positions, t, np.random.default_rng(4))
    i, j = got.stretch
    m = j - i
    np.testing.assert_array_equal(got.positions[:i], track.positions[:i])
    np.testing.assert_array_equal(got.positions[j:], track.positions[i:])
    assert np.all(np.diff(got.times_s) > 0)
    shift = got.times_s[j:] - t[i:]
    assert np.allclose(shift, shift[0]) and shift[0] > 0
    ring = got.positions[i:j]
    centre = ring.mean(axis=0)
    radius = _dist(ring, np.repeat(centre[None], m, 0))
    assert 400 < np.median(radius) < 1600 and m >= 8


def test_speed_keeps_positions_and_scales_the_stretch_times(track):
    t = _times(track)
    got = inject("speed", track.positions, t, np.random.default_rng(5))
    i, j = got.stretch
    np.testing.assert_array_equal(got.positions, track.positions)
    ratio = np.diff(got.times_s)[i - 1 : j - 1] / np.diff(t)[i - 1 : j - 1]
    assert np.allclose(ratio, ratio[0])
    assert ratio[0] == pytest.approx(1 / 0.3) or 1 / 3 <= ratio[0] <= 1 / 2
    np.testing.assert_allclose(np.diff(got.times_s)[: i - 1], np.diff(t)[: i - 1])


def test_gap_removes_a_stretch(track):
    got = inject("gap", track.positions, _times(track), np.random.default_rng(6))
    removed = len(track.positions) - len(got.positions)
    lo, hi = DEFAULTS["gap"]["span"]
    assert lo * len(track.positions) - 1 <= removed <= hi * len(track.positions) + 1
    i = got.stretch[0] + 1
    np.testing.assert_array_equal(got.positions[:i], track.positions[:i])
    np.testing.assert_array_equal(got.positions[i:], track.positions[i + removed :])


def test_noise_moves_a_share_of_points(track):
    got = inject("noise", track.positions, _times(track), np.random.default_rng(7))
    d = _dist(got.positions, track.positions)
    moved = d > 0
    assert moved.sum() == round(0.2 * (len(d) - 2))
    assert np.all((d[moved] > 490) & (d[moved] < 1010))
    assert not moved[0] and not moved[-1]


def test_params_parse_and_check_their_range():
    from aisdati.errors import UserError

    p = parse_params(["detour.km=1-3", "jump.km=4"])
    assert p["detour"]["km"] == (1.0, 3.0) and p["jump"]["km"] == (4.0, 4.0)
    for bad in ("detour.km=5-1", "detour.span=0.95", "nope.km=1", "detour.km=x", "jump.km=nan"):
        with pytest.raises(UserError):
            parse_params([bad])


def _evaluate(cli, data, out, *extra):
    return cli(
        "evaluate", "--data", data, "--cluster", "other", "--detectors", "nearest", "--out", out,
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


def test_a_3_km_detour_scores_above_its_source_for_nearest_and_dati(kitimat, tmp_path):
    from aisdati.ais.training import TrainSettings
    from aisdati.detectors import ScoreSettings
    from aisdati.detectors.nearest import NearestDetector
    from aisdati.detectors.train import train_detector
    from aisdati.tracks.store import Track

    table = read_track_table(kitimat)
    lane = table[table["route"] == "route-2"].sort_values("track_id")
    train_ids = [int(i) for i in lane["track_id"][:8]]
    (held,) = load_tracks(kitimat, [int(lane["track_id"].iloc[-1])])
    got = inject("detour", held.positions, _times(held), np.random.default_rng(0),
                 parse_params(["detour.km=3"]))
    detoured = Track(-1, held.mmsi, held.start, got.positions, np.diff(got.times_s) / 3600,
                     held.cluster)
    how = ScoreSettings(score="rollout", rollouts=4)
    near = NearestDetector().fit(load_tracks(kitimat, train_ids))
    s = near.score([held, detoured], how).score
    assert s[1] > 1.3 * s[0]
    trained = train_detector(
        "dati",
        TrainSettings(kitimat, "route-2", tmp_path, episodes=2, track_ids=tuple(train_ids)),
        how,
    )
    det = load_detector_from(trained.model)
    s = det.score([held, detoured], how).score
    assert s[1] > s[0]


def load_detector_from(path):
    from aisdati.detectors import load_detector

    return load_detector(path.with_suffix(""))


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
            "--kinds", "detour,jump,loiter", "--out", out)
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
