"""AIS environment and detection scoring on real NY Harbor tracks (tiny, no training)."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aisdati.ais.source import build_source, make_env, track_reference
from aisdati.detection.run import DetectSettings, relative_thresholds, small_batch_note
from aisdati.dtw import batch_mean_dtw_m, dtw_path_length, matched_distances
from aisdati.errors import UserError
from aisdati.geo import haversine_m, spherical_step
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    from typer.testing import CliRunner

    from aisdati.cli import app

    out = tmp_path_factory.mktemp("processed")
    src = Path(__file__).parent / "data" / "NYHarbor_2020_06_30_first_hour.csv"
    args = ["ingest", "--input", str(src), "--roi", "none", "--min-points", "30"]
    result = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_perfect_policy_reproduces_real_tracks(processed):
    ids = read_track_table(processed)["track_id"].tolist()[:4]
    tracks = load_tracks(processed, ids)
    env = make_env(build_source(tracks))
    for track in tracks:
        env.reset(seed=0, options={"reference": track_reference(track)})
        rewards = []
        for action in env.perfect_actions:
            _, reward, terminated, _, info = env.step(action)
            rewards.append(reward)
        assert terminated
        assert info["dtw"] == pytest.approx(0.0, abs=1e-6)
        np.testing.assert_allclose(env.position, track.positions[-1], atol=1e-9)
        assert set(rewards) == {1.0}


def test_tracks_load_in_time_order_from_points_in_any_order(processed, tmp_path):
    """The ingest's points written back as one file with their rows shuffled: each track's
    positions and time steps are those of its own reports sorted by time (pandas, per track),
    in the order the ids are asked for."""
    points = pq.read_table(processed / "points.parquet").to_pandas()
    shuffled = points.sample(frac=1.0, random_state=0).reset_index(drop=True)
    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(processed / "tracks.parquet", data / "tracks.parquet")
    pq.write_table(pa.Table.from_pandas(shuffled, preserve_index=False), data / "points.parquet")
    ids = read_track_table(processed)["track_id"].tolist()[::-1]
    for tid, track in zip(ids, load_tracks(data, ids), strict=True):
        mine = points[points["track_id"] == tid].sort_values("time")
        hours = mine["time"].diff().dt.total_seconds().to_numpy()[1:] / 3600.0
        assert track.track_id == tid
        np.testing.assert_array_equal(track.positions, mine[["lon", "lat"]].to_numpy())
        np.testing.assert_allclose(track.dts, hours, rtol=1e-12)
    shuffled["time"] = shuffled["time"].astype(str)
    pq.write_table(pa.Table.from_pandas(shuffled, preserve_index=False), data / "points.parquet")
    with pytest.raises(UserError, match="not a timestamp"):
        load_tracks(data, ids)


@pytest.mark.parametrize("lat", [0.0, 25.0, 40.7, 60.0])
def test_spherical_rule_one_step_error_below_0_1_percent(lat):
    rng = np.random.default_rng(1)
    sog = rng.uniform(0.5, 30.0, 200)
    cog = rng.uniform(0.0, 360.0, 200)
    dist_m = rng.uniform(10.0, 5000.0, 200)
    dt = dist_m / 1852.0 / sog
    lon, lat2 = spherical_step(-74.0, lat, sog, cog, dt)
    true = haversine_m(-74.0, lat, lon, lat2)
    assert np.max(np.abs(true - dist_m) / dist_m) < 1e-3


def mean_dtw_m(a: np.ndarray, b: np.ndarray) -> float:
    cost, length = dtw_path_length(a, b, "haversine")
    return cost / length


def _detour(track: np.ndarray, km: float) -> np.ndarray:
    """The track with a smooth bump of `km` peak in its middle third, perpendicular to the line
    from its first to its last point."""
    n = len(track)
    coslat = np.cos(np.radians(track[0, 1]))
    d = (track[-1] - track[0]) * [coslat, 1.0]
    normal = np.array([-d[1], d[0]]) / np.hypot(*d)
    i = np.arange(n)
    bump = np.clip(1 - np.abs(i - n / 2) / (n / 6), 0, 1)
    offset_deg = bump[:, None] * km / 111.2 * normal / [coslat, 1.0]
    return track + offset_deg


def test_planted_detour_scores_above_its_untouched_twin(processed):
    (track,) = load_tracks(processed, [3])
    rng = np.random.default_rng(0)
    # a model that has learnt the route well: rollouts within ~50 m of the track
    rollouts = [track.positions + rng.normal(0, 0.0005, track.positions.shape) for _ in range(3)]
    twin = track.positions.copy()
    detoured = _detour(track.positions, 5.0)
    score_twin = min(mean_dtw_m(r, twin) for r in rollouts)
    score_detour = min(mean_dtw_m(r, detoured) for r in rollouts)
    assert score_detour > 5 * score_twin
    assert score_twin < 0.75 * score_detour  # the paper's rule flags the detour alone
    profile = matched_distances(detoured, rollouts[0])
    dev, idx = profile.max(), int(profile.argmax())
    assert dev > 4000
    assert abs(idx - len(detoured) / 2) <= len(detoured) / 10


def test_batch_relative_rules_flag_by_the_batch_and_warn_of_a_small_one(tmp_path):
    scores = np.array([0.1, 1.0, 0.5, 0.9, 0.2, 0.3, 0.4, 0.6, 0.7, 0.05])
    base = DetectSettings(data_dir=tmp_path, models_dir=tmp_path, out_dir=tmp_path)
    paper = replace(base, threshold=0.75)
    assert paper.rule == "relative" and base.rule == "calibrated"
    assert (scores > relative_thresholds(scores, paper)).tolist() == list(scores > 0.75)
    top = replace(base, top_percent=20)
    assert np.flatnonzero(scores > relative_thresholds(scores, top)).tolist() == [1, 3]
    assert small_batch_note(10, paper) is None and small_batch_note(50, base) is None
    assert "--threshold flags relative to the judged batch, and 1" in small_batch_note(1, paper)
    assert "--top-percent" in small_batch_note(9, top)


def test_label_metrics_weighted_f1_and_auc():
    from aisdati.detection.labels import label_metrics

    y = np.array([1, 1, 0, 0, 0, 0])
    flagged = np.array([1, 0, 1, 0, 0, 0])
    score = np.array([0.9, 0.6, 0.8, 0.1, 0.2, 0.3])
    m = label_metrics(y, flagged, score)
    assert m["precision"] == pytest.approx(0.5) and m["recall"] == pytest.approx(0.5)
    # class 1: F1 0.5 (support 2); class 0: precision 3/4, recall 3/4, F1 0.75 (support 4)
    assert m["f1_weighted"] == pytest.approx((2 * 0.5 + 4 * 0.75) / 6)
    assert m["roc_auc"] == pytest.approx(7 / 8)


def test_batched_parallel_dtw_equals_reference_dtw():
    rng = np.random.default_rng(0)
    origin = np.array([-80.0, 25.0])
    tracks = [np.cumsum(rng.normal(0, 0.001, (n, 2)), 0) + origin for n in (50, 80, 33)]
    rolls = np.cumsum(rng.normal(0, 0.001, (6, 90, 2)), 1) + origin
    lengths = np.array([90, 60, 81, 40, 33, 70])
    owner = np.array([0, 0, 1, 1, 2, 2])
    got = batch_mean_dtw_m(rolls, lengths, tracks, owner)
    want = [mean_dtw_m(rolls[i, : lengths[i]], tracks[owner[i]]) for i in range(6)]
    np.testing.assert_allclose(got, want, rtol=1e-9)


def test_cog_window_is_centred_on_the_traffic_and_keeps_the_rule_exact():
    from aisdati.model.rules import SphericalRule, mean_course

    assert mean_course(np.array([350.0, 10.0])) == pytest.approx(0.0, abs=1e-9)
    assert mean_course(np.array([100.0, 140.0])) == pytest.approx(120.0)
    # a north-going track whose courses straddle 0/360
    lat = 40.0 + np.arange(6) * 0.01
    lon = -74.0 + np.array([0.0, 0.001, 0.0, 0.001, 0.0, 0.001])
    positions = np.stack([lon, lat], axis=1)
    dts = np.full(5, 0.05)
    rule = SphericalRule(max_sog=30.0, max_dt_h=0.1, cog_center=0.0)
    decisions = rule.perfect_decisions(positions, dts)
    assert np.all(np.abs(decisions[:, 1]) < 10.0)  # near 0, not split between ~0 and ~360
    scaled = rule.decision_scaler.scale(decisions)
    assert np.all(np.abs(scaled[:, 1]) < 0.1)
    stepped = rule.step(positions[:-1], decisions)
    np.testing.assert_allclose(stepped, positions[1:], atol=1e-9)
