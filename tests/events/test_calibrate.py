"""Event thresholds calibrated on an area's training tracks (Kitimat's July)."""

from __future__ import annotations

import numpy as np

from aisdati.events.calibrate import CALIBRATED, EVENT_RATE, KEY, calibrated, calibration
from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.tracks.reports import read_reports


def _tracks(kitimat) -> list[VesselReports]:
    reports = read_reports(kitimat)
    return [VesselReports.of(g) for _, g in reports.groupby("track_id")]


def test_calibrated_thresholds_raise_events_on_about_the_rate_of_training_tracks(kitimat):
    tracks = _tracks(kitimat)
    recorded = calibration(tracks)
    assert set(recorded) == {KEY + k for k in CALIBRATED}
    assert all(len(v) == len(tracks) for v in recorded.values())
    settings = calibrated(recorded)
    for kind in CALIBRATED:
        raised = sum(any(e.kind == kind for e in find_events(v, settings)) for v in tracks)
        # the quantile's own share, plus ties at it; never above the floor's
        assert raised <= np.ceil(EVENT_RATE * len(tracks)) + 1, kind


def test_a_threshold_is_never_below_its_floor_and_unrecorded_kinds_keep_defaults():
    low = {KEY + kind: [0.0, 0.0] for kind in CALIBRATED}
    settings = calibrated(low)
    for name, floor, _ in CALIBRATED.values():
        assert getattr(settings, name) == floor
    assert calibrated({}) == EventSettings()
