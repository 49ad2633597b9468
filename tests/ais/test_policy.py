"""A track's score and flag do not depend on the tracks judged with it (issue 58; issue 61,
item 1): every random draw is keyed by the run's seed and the track's own reports
(`aisdati.ais.policy.Draws`), and the default rule is each model's calibrated threshold.
On real Kitimat tracks, the area's default detector (cross-fitted BC, judged by stepspread)
and DATI's lane score; and the one-step errors of a policy (`aisdati.ais.policy`): zero for one
that reproduces the tracks, largest at a position jump."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aisdati.ais.policy import AISPolicy, draw_rows, reported_next
from aisdati.ais.source import build_source
from aisdati.ais.space import PRESETS, LaneConfig
from aisdati.ais.training import TrainSettings
from aisdati.detectors import ScoreSettings, load_detector
from aisdati.detectors.bc import BCDetector
from aisdati.detectors.dati import DATIDetector
from aisdati.evaluation.inject import inject
from aisdati.geo import spherical_step
from aisdati.model.noise import keyed_normal
from aisdati.tracks.store import load_tracks, read_track_table

SMALL = replace(PRESETS["area"], members=2, pretrain=3, validation_tracks=2, validation_rollouts=1)
"""The area preset, small enough for a test."""


@pytest.fixture(scope="module")
def split(kitimat):
    """16 tracks of the busiest lane to train on; 50 other tracks to judge."""
    table = read_track_table(kitimat)
    train = table[table["route"].isin(["route-1", "route-2"])]["track_id"].tolist()[::3][:16]
    others = [int(i) for i in table["track_id"] if i not in set(train)][:50]
    return load_tracks(kitimat, [int(i) for i in train]), load_tracks(kitimat, others)


@pytest.fixture(scope="module")
def area_bc(split, tmp_path_factory):
    """The area's default model, saved and loaded as `detect` loads it."""
    settings = TrainSettings(cluster="all", episodes=4, lane=SMALL, preset="area")
    folder = tmp_path_factory.mktemp("models")
    trained = BCDetector(settings).fit(split[0])
    trained.save(folder / trained.name)
    return load_detector(folder / trained.name)


def test_keyed_noise_is_a_function_of_the_key_alone():
    keys = np.array([1, 2, 3, 2], np.uint64)
    draws = keyed_normal(keys, 7, 4)
    np.testing.assert_array_equal(draws[1], draws[3])  # same key, same draw
    np.testing.assert_array_equal(keyed_normal(keys[2:3], 7, 4)[0], draws[2])  # alone
    assert not np.allclose(keyed_normal(keys, 8, 4), draws)  # the next draw differs
    big = keyed_normal(np.arange(20_000, dtype=np.uint64), 0, 2).ravel()
    assert abs(big.mean()) < 0.02 and abs(big.std() - 1.0) < 0.02  # standard normal
    rows = draw_rows(np.array([5, 9], np.uint64), range(3))
    assert rows.index.tolist() == [0, 1, 2, 0, 1, 2]
    assert sorted(np.bincount(rows[:3].members(3))) == [1, 1, 1]  # a track's draws take turns


def test_the_default_detector_scores_a_track_the_same_alone_and_in_a_batch_of_50(area_bc, split):
    batch = split[1]
    assert len(batch) == 50
    how = area_bc.how
    assert how.score == "stepspread"
    together = area_bc.score(batch, how).score
    shuffled = [batch[i] for i in np.random.default_rng(0).permutation(50)]
    again = area_bc.score(shuffled, how).score
    threshold = area_bc.threshold(how)
    for k in (0, 17, 49):
        alone = area_bc.score([batch[k]], how).score[0]
        assert alone == pytest.approx(together[k], rel=1e-6)
        assert (alone > threshold) == (together[k] > threshold)
    order = {t.track_id: i for i, t in enumerate(shuffled)}
    np.testing.assert_allclose([again[order[t.track_id]] for t in batch], together, rtol=1e-6)


def test_rollouts_and_the_lane_are_the_same_alone_and_in_a_batch(split):
    """DATI's free rollouts run hundreds of steps: keyed draws keep each track's own."""
    settings = TrainSettings(cluster="all", episodes=1, lane=replace(SMALL, crossfit=False,
                             members=1), preset="area")  # fmt: skip
    how = ScoreSettings(score="lane", rollouts=2, lane_rollouts=3)
    dati = DATIDetector(settings, how).fit(split[0])
    batch = split[1][:12]
    together = dati.score(batch, how, also=("rollout",))
    for k in (0, 11):
        alone = dati.score([batch[k]], how, also=("rollout",))
        assert alone.score[0] == pytest.approx(together.score[k], rel=1e-5)
        assert alone.parts["rollout"][0] == pytest.approx(together.parts["rollout"][k], rel=1e-5)


def test_detect_flags_a_track_alone_as_in_its_batch(cli, kitimat, area_bc, split, tmp_path):
    """End to end with the defaults: `detect --cluster all` and `detect --track ID`."""
    models = area_bc.loaded_from.parent
    batch_out, alone_out = tmp_path / "batch", tmp_path / "alone"
    r = cli("detect", "--data", kitimat, "--models", models, "--cluster", "all", "--out", batch_out)
    assert r.exit_code == 0, r.output
    scores = pd.read_parquet(batch_out / "scores.parquet").set_index("track_id")
    assert len(scores) >= 50
    report = json.loads((batch_out / "report.json").read_text())
    assert report["flag_rule"] == "calibrated" and report["score_unit"] == "x spread"
    track = int(split[1][3].track_id)
    r = cli("detect", "--data", kitimat, "--models", models, "--track", track, "--out", alone_out)
    assert r.exit_code == 0, r.output
    alone = pd.read_parquet(alone_out / "scores.parquet").set_index("track_id")
    assert alone.loc[track, "score"] == pytest.approx(scores.loc[track, "score"], rel=1e-6)
    assert alone.loc[track, "flagged"] == scores.loc[track, "flagged"]
    assert alone.loc[track, "threshold"] == scores.loc[track, "threshold"]
    paper = tmp_path / "paper"
    relative = cli("detect", "--data", kitimat, "--models", models, "--track", track,
                   "--threshold", "0.75", "--out", paper)  # fmt: skip
    assert relative.exit_code == 0 and "too few to say what is normal" in relative.output
    assert any("too few" in w for w in json.loads((paper / "report.json").read_text())["warnings"])


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def _perfect_policy(space, tracks, draws):
    """A policy that takes every track's own perfect decisions: it reproduces them exactly."""
    scaled = np.concatenate(
        [
            space.rule.decision_scaler.scale(space.rule.perfect_decisions(t.positions, t.dts))
            for t in tracks
        ]
    ).repeat(draws, axis=0)

    def make(rows, temporal):
        return lambda obs: scaled[: len(obs)]

    return AISPolicy(space, make)


def test_step_errors_of_a_model_that_reproduces_the_tracks_are_zero(tracks):
    space = build_source(tracks, LaneConfig()).space
    policy = _perfect_policy(space, tracks[:5], draws=3)
    errors, predicted = policy.step_errors(
        [t.positions for t in tracks[:5]], [t.dts for t in tracks[:5]], 3
    )
    for e, p, t in zip(errors, predicted, tracks[:5], strict=True):
        assert len(e) == len(t.positions) - 1
        assert e.max() < 1e-3  # metres
        np.testing.assert_allclose(p, t.positions[1:], atol=1e-9)


def test_the_reported_motion_puts_a_steady_vessel_on_its_next_report():
    """Issue 59, item 3: `reported_next` moves each report by the kinematic rule at the mean of
    its and the next report's reported velocity: a vessel that sails as it reports lands on its
    next report; a report without SOG leaves its target unknown."""
    dts = np.full(5, 0.1)
    sog, cog = np.full(6, 12.0), np.full(6, 70.0)
    lon, lat = [-128.7], [53.5]
    for dt in dts:
        x, y = spherical_step(lon[-1], lat[-1], 12.0, 70.0, dt)
        lon.append(float(x))
        lat.append(float(y))
    positions = np.column_stack([lon, lat])
    np.testing.assert_allclose(reported_next(positions, dts, sog, cog), positions[1:], atol=1e-12)
    speeding = reported_next(positions, dts, np.tile([10.0, 14.0], 3), cog)  # 12 kn between
    np.testing.assert_allclose(speeding, positions[1:], atol=1e-12)
    sog[2] = np.nan
    assert np.isnan(reported_next(positions, dts, sog, cog)[1:3]).all()


def _dead_reckoning(space):
    """Continue at the current course and speed (read from the motion state)."""

    def make(rows, temporal):
        def act(obs):
            sog = obs[:, 4] * space.rule.max_sog
            cog = np.degrees(np.arctan2(obs[:, 2], obs[:, 3]))
            decision = np.stack([sog, cog, np.full(len(obs), 0.05)], axis=1)
            return space.rule.decision_scaler.scale(decision)

        return act

    return make


def test_a_position_jump_gives_the_largest_step_error(tracks):
    t = tracks[3]
    times = np.r_[0.0, np.cumsum(t.dts)] * 3600.0
    got = inject("jump", t.positions, times, np.random.default_rng(0))
    i, j = got.stretch
    space = build_source(tracks, LaneConfig(state="motion")).space
    policy = AISPolicy(space, _dead_reckoning(space))
    (errors,), _ = policy.step_errors([got.positions], [np.diff(got.times_s) / 3600.0], 1)
    peak = int(np.argmax(errors)) + 1  # error k is at report k + 1
    # at the jump itself, or the report after it (dead reckoning carries the jump one step on)
    assert min(abs(peak - i), abs(peak - j)) <= 1, (peak, i, j)
    assert errors.max() > 2500
