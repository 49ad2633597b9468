"""`nearest` (`aisdati.detectors.nearest`) on real Kitimat tracks: its calibration leaves each
vessel out, its lane score sees a jump and needs the course weight it was calibrated with."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from aisdati.ais.space import LaneConfig
from aisdati.ais.training import TrainSettings
from aisdati.detectors import ScoreSettings
from aisdati.detectors.nearest import NearestDetector
from aisdati.errors import UserError
from aisdati.evaluation.inject import inject
from aisdati.tracks.store import load_tracks, read_track_table


def nearest(tracks, how=None):
    """A fitted `nearest` (the paper's lane set-up: its card needs no corridor)."""
    return NearestDetector(TrainSettings(lane=LaneConfig()), how).fit(tracks)


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_nearest_calibration_leaves_each_vessel_out(tracks):
    det = nearest(tracks)
    cal = np.asarray(det.card.calibration["nearest"])
    assert np.all(cal > 0)  # no track is compared with itself or its own vessel
    scored = det.score(tracks[:3], ScoreSettings())
    np.testing.assert_allclose(scored.score, 0.0, atol=1e-6)  # its own training tracks


def test_a_threshold_needs_the_course_weight_the_model_was_calibrated_with(tracks):
    det = nearest(tracks, ScoreSettings(lane_course_km=2.0))
    assert det.card.calibrated_with.lane_course_km == 2.0
    how = ScoreSettings(score="lane", lane_course_km=2.0)
    assert det.threshold(how, 0.05) > 0
    with pytest.raises(UserError, match=r"calibrated with lane_course_km=2\.0, not 0\.0"):
        det.threshold(replace(how, lane_course_km=0.0), 0.05)
    det.card.calibrated_with = None  # a card from before the course weight
    assert det.threshold(replace(how, lane_course_km=0.0), 0.05) > 0


def test_nearest_calibrates_a_route_sailed_by_one_vessel_on_its_other_tracks(tracks):
    ferry = [replace(t, mmsi=100000001) for t in tracks[:6]]  # one boat runs the whole line
    det = nearest(ferry)
    for key in ("nearest", "lane"):
        cal = np.asarray(det.card.calibration[key])
        assert len(cal) == 6 and np.all(np.isfinite(cal)) and np.all(cal > 0)
    assert det.threshold(ScoreSettings(score="lane"), 0.05) > 0


def test_nearest_lane_score_sees_a_jump_and_is_calibrated_per_vessel(kitimat):
    table = read_track_table(kitimat)
    held, *lane = load_tracks(kitimat, table.loc[table["route"] == "route-1", "track_id"][:20])
    det = nearest([t for t in lane if t.mmsi != held.mmsi])
    assert np.all(np.asarray(det.card.calibration["lane"]) >= 0)
    times = np.r_[0.0, np.cumsum(held.dts)] * 3600.0
    params = {"jump": {"span": (0.1, 0.2), "km": (5.0, 5.0)}}
    got = inject("jump", held.positions, times, np.random.default_rng(1), params)
    jumped = replace(held, positions=got.positions, dts=np.diff(got.times_s) / 3600.0)
    how = ScoreSettings(score="lane")
    scored = det.score([held, jumped], how, also=("nearest",))
    assert set(scored.parts) == {"nearest", "lane"}
    assert scored.score[1] > scored.score[0] + 2000  # the jumped stretch is 5 km off
    assert len(scored.profiles[1]) == len(jumped.positions)
    assert det.calibration_key(how) == "lane" and det.threshold(how, 0.05) > 0


def test_the_tail_fraction_runs_from_the_largest_deviation_to_the_mean(tracks):
    det = nearest(tracks[3:])
    times = np.r_[0.0, np.cumsum(tracks[0].dts)] * 3600.0
    jumped = inject("jump", tracks[0].positions, times, np.random.default_rng(1))
    how = ScoreSettings(score="lane")
    profile = det.training_tracks.lane_scores([jumped.positions], how)[1][0]
    by_tail = {
        f: det.training_tracks.lane_scores([jumped.positions], replace(how, tail=f))[0][0]
        for f in (1e-9, 0.1, 0.5, 1.0)
    }
    assert by_tail[1e-9] == pytest.approx(profile.max())  # at least one report: the worst
    assert by_tail[1.0] == pytest.approx(profile.mean())
    k = int(np.ceil(0.1 * len(profile)))
    assert by_tail[0.1] == pytest.approx(np.sort(profile)[-k:].mean())
    assert by_tail[1e-9] > by_tail[0.1] > by_tail[0.5] > by_tail[1.0]
