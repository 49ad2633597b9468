"""The Python API as a user writes it (the README's "From Python" example): read ingest's
tracks, fit `nearest` and a tiny DATI, score held-out tracks, flag them with a contamination
threshold, save and load; the events that need no model."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from aisdati.ais.space import PRESETS
from aisdati.detection.events import model_free_events
from aisdati.detectors import (
    DETECTORS,
    DATIDetector,
    NearestDetector,
    ScoreSettings,
    TrainSettings,
    detector_class,
    load_detector,
)
from aisdati.errors import UserError
from aisdati.evaluation.inject import inject
from aisdati.events.kinds import KINDS
from aisdati.events.record import EVENT_COLUMNS
from aisdati.tracks.reports import read_reports, read_vessels
from aisdati.tracks.store import load_tracks, read_track_table


def test_fit_score_flag_save_and_load(kitimat, tmp_path):
    data, out = kitimat, tmp_path
    # ---------------------------------------------------------------- the example
    # data: a folder written by `aisdati ingest --input AIS_2018_07-08_Kitimat.csv.gz --out data`
    table = read_track_table(data)
    lane = load_tracks(data, table.loc[table["route"] == "route-1", "track_id"].tolist())
    train, test = lane[:16], lane[16:20]

    nearest = NearestDetector().fit(train)  # remembers the normal tracks
    scores = nearest.decision_function(test)  # metres, higher = more abnormal
    flagged = nearest.predict(test, contamination=0.05)  # above 95 % of the training tracks' scores

    tiny = TrainSettings(episodes=2, lane=PRESETS["paper"])  # a real model trains 170 episodes
    dati = DATIDetector(tiny, ScoreSettings(rollouts=2, lane_rollouts=4)).fit(train)
    dati_scores, dati_flagged = dati.decision_function(test), dati.predict(test)
    dati.save(out / "route-1")  # route-1.pt and its model card route-1.json
    events = model_free_events(read_reports(data), read_vessels(data))  # drift, gaps, ...: no model

    # ------------------------------------------------------------ what it gives
    assert len(train) == 16 and len(test) == 4
    assert scores.shape == (4,) and np.all(np.isfinite(scores)) and np.all(scores >= 0)
    cut = nearest.threshold(contamination=0.05)  # of the default score, the lane score
    assert cut == pytest.approx(np.quantile(nearest.card.calibration["lane"], 0.95))
    np.testing.assert_array_equal(flagged, scores > cut)
    assert nearest.card.data.track_ids == [t.track_id for t in train]
    # a 5 km jump planted in a held-out track scores km above the track, and is flagged
    held = test[0]
    times = np.r_[0.0, np.cumsum(held.dts)] * 3600.0
    params = {"jump": {"span": (0.1, 0.2), "km": (5.0, 5.0)}}
    got = inject("jump", held.positions, times, np.random.default_rng(1), params)
    jumped = replace(held, positions=got.positions, dts=np.diff(got.times_s) / 3600.0)
    plain, planted = nearest.decision_function([held, jumped])
    assert planted > plain + 2000 and nearest.predict([jumped]).tolist() == [True]
    # DATI trained in memory: two episodes, calibrated, nothing written until saved
    assert dati.card.training.episodes_run == 2 and dati.card.training.finished
    assert np.all(np.isfinite(dati_scores)) and np.all(dati_scores > 0)
    np.testing.assert_array_equal(dati_flagged, dati_scores > dati.threshold())
    assert sorted(p.name for p in out.iterdir()) == ["route-1.json", "route-1.pt"]
    again = DATIDetector.load(out / "route-1")  # the same model: the same scores, to the bit
    assert isinstance(again, DATIDetector) and load_detector(out / "route-1").method == "dati"
    assert again.card.to_dict() == json.loads(json.dumps(dati.card.to_dict()))
    np.testing.assert_array_equal(again.score(test, dati.how).score, dati_scores)
    assert again.threshold(dati.how) == dati.threshold()
    with pytest.raises(UserError, match="route-1 is a dati model, not a NearestDetector"):
        NearestDetector.load(out / "route-1")
    # the events of every report, each with its vessel, kind, times and strength
    assert list(events.columns) == list(EVENT_COLUMNS)
    assert set(events["kind"]) <= set(KINDS) and (events["strength"] >= 1).all()


def test_detectors_register_under_their_method():
    assert list(DETECTORS) == ["dati", "bc", "nearest"]  # the order --method lists them
    assert detector_class("nearest") is NearestDetector
    assert DATIDetector.model_name("route-1") == "route-1"
    assert NearestDetector.model_name("route-1") == "route-1-nearest"
    with pytest.raises(UserError, match="unknown detector 'knn'; choose from dati, bc, nearest"):
        detector_class("knn")
    with pytest.raises(UserError, match="not fitted"):
        NearestDetector().threshold()
