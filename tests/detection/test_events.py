"""A detection's learned events on real Kitimat tracks (`aisdati.detection.events`): a track
bound where no training track went, and the judged reports."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from aisdati.detection.events import judged_reports, unseen_route_events
from aisdati.detectors import load_detector
from aisdati.geo import moved_m
from aisdati.tracks.reports import read_vessels
from tests.helpers.area import save_nearest


def test_a_track_bound_where_no_training_track_went_is_an_event(months, kitimat, tmp_path):
    july, august, _ = months
    save_nearest(july, "all", tmp_path)
    model = load_detector(tmp_path / "all-nearest")
    far = replace(august[0], track_id=10**6)
    lon, lat = moved_m(far.positions[:, 0], far.positions[:, 1], 0.0, 60_000.0)
    far = replace(far, positions=np.column_stack([lon, lat]))  # 60 km north: a new route
    tracks = [*august, far]
    scores = pd.DataFrame({"model": [model.name] * len(tracks)})
    events = unseen_route_events(tracks, scores, [model], read_vessels(kitimat), near_km=10.0)
    assert far.track_id in set(events["track_id"])
    assert len(events) <= 1 + np.ceil(0.05 * len(august))  # August sails where July did
    row = events.set_index("track_id").loc[far.track_id]
    assert row["kind"] == "unseen-route" and row["strength"] > 1
    assert (row["lon"], row["lat"]) == (far.positions[-1, 0], far.positions[-1, 1])


def test_the_judged_reports_leave_the_training_tracks_out(months, kitimat):
    july, august, _ = months
    every = judged_reports(kitimat, august, [t.track_id for t in july], every=True)
    assert not every["track_id"].isin([t.track_id for t in july]).any()
    assert every["time"].min() >= min(t.start for t in august)
    chosen = judged_reports(kitimat, august[:3], [], every=False)
    assert set(chosen["track_id"]) == {t.track_id for t in august[:3]}
