"""One conformance check that every registered detector and every score passes, after
scikit-learn's estimator checks: the PyOD-shaped interface (fit returns the detector, scores are
finite and one per track, the threshold falls as the contamination rises, predict is the score
above it, save and load give back the same scores, an unfitted detector refuses in one line), a
track's score independent of the tracks scored with it, and every score declared once with its
unit, evidence, profile, definition and calibration. On real Kitimat tracks, small models; and
non-finite numbers reaching a kernel one line naming the model (issue 27, item 8)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from aisdati.ais.space import PRESETS
from aisdati.ais.training import TrainSettings
from aisdati.detectors import DETECTORS, Detector, ScoreSettings, load_detector
from aisdati.errors import UserError
from aisdati.scores import NEAREST, SCORES
from aisdati.tracks.store import load_tracks, read_track_table

HOW = ScoreSettings(rollouts=2, lane_rollouts=3)
"""Few draws: the checks are of the interface, not of detection quality."""
LANE = replace(PRESETS["lanes"], members=2, pretrain=2, validation_tracks=2, validation_rollouts=1)


@pytest.fixture(scope="module")
def route(kitimat):
    """Twelve tracks of Kitimat's busiest route to fit on, six others to judge."""
    table = read_track_table(kitimat)
    ids = [int(i) for i in table.loc[table["route"] == "route-1", "track_id"]][:18]
    tracks = load_tracks(kitimat, ids)
    return tracks[:12], tracks[12:]


@pytest.fixture(scope="module", params=list(DETECTORS))
def fitted(request, route) -> Detector:
    settings = TrainSettings(cluster="route-1", episodes=2, lane=LANE, preset="lanes")
    detector = DETECTORS[request.param](settings, HOW)
    assert detector.fit(route[0]) is detector  # fit returns the detector
    return detector


def test_every_detector_is_registered_under_its_method():
    assert list(DETECTORS) == ["dati", "bc", "nearest"]
    assert all(cls.method == name for name, cls in DETECTORS.items())


def test_an_unfitted_detector_refuses_in_one_line(route):
    for cls in DETECTORS.values():
        with pytest.raises(UserError, match="not fitted"):
            cls(TrainSettings(cluster="route-1"), HOW).decision_function(route[1])


def test_scores_thresholds_and_flags_agree(fitted, route):
    judged = route[1]
    scores = fitted.decision_function(judged)
    assert scores.shape == (len(judged),) and np.isfinite(scores).all()
    low, high = fitted.threshold(contamination=0.2), fitted.threshold(contamination=0.01)
    assert low <= high  # flagging more of the training tracks lowers the bar
    np.testing.assert_array_equal(fitted.predict(judged, 0.2), scores > low)
    lo, hi = fitted.threshold_spread(contamination=0.2)
    assert lo <= hi


def test_a_track_scores_the_same_alone(fitted, route):
    judged = route[1]
    together = fitted.decision_function(judged)
    for k in (0, len(judged) - 1):
        alone = fitted.decision_function([judged[k]])[0]
        assert alone == pytest.approx(together[k], rel=1e-5)


def test_save_and_load_give_back_the_same_scores(fitted, route, tmp_path):
    fitted.save(tmp_path / fitted.name)
    loaded = load_detector(tmp_path / fitted.name)
    as_saved = json.loads(json.dumps(fitted.card.to_dict()))  # tuples as JSON lists
    assert type(loaded) is type(fitted) and loaded.card.to_dict() == as_saved
    assert type(fitted).load(tmp_path / fitted.name).name == fitted.name
    np.testing.assert_allclose(
        loaded.decision_function(route[1]), fitted.decision_function(route[1]), rtol=1e-5
    )


def test_every_score_is_declared_computed_and_calibrated(fitted, route):
    own = ("nearest", "lane") if fitted.method == "nearest" else tuple(SCORES)
    for name in own:
        declared = NEAREST if name == "nearest" else SCORES[name]
        assert declared.unit in ("m", "x spread")
        assert declared.evidence and declared.profile and declared.definition
        calibration = fitted.card.calibration[name]
        assert len(calibration) == len(route[0]) and np.isfinite(calibration).all()
        if name == "nearest":
            continue
        got = fitted.score(route[1], replace(HOW, score=name))
        assert np.isfinite(got.score).all() and len(got.profiles) == len(route[1])
        assert fitted.threshold(replace(HOW, score=name)) > 0


def test_non_finite_numbers_reaching_a_kernel_are_one_line_naming_the_model(ny_models, tmp_path):
    """The kernels refuse NaN themselves; the detector says which model was scoring."""
    from aisdati.detectors import load_detector
    from aisdati.errors import UserError
    from aisdati.tracks.store import load_tracks

    det = load_detector(ny_models["models"] / "down-nearest")
    (track,) = load_tracks(ny_models["proc"], det.card.data.track_ids[:1])
    positions = track.positions.copy()
    positions[3] = np.nan
    with pytest.raises(UserError, match=r"cannot score with .*down-nearest\.json: .*non-finite"):
        det.score([replace(track, positions=positions)])
