"""A detection's learned events on real Kitimat tracks (`aisdati.detection.events`): a track
bound where no training track went, and the judged reports."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aisdati.detection.events import (
    judged_reports,
    judged_windows,
    model_free_events,
    unseen_route_events,
    within,
)
from aisdati.detectors import load_detector
from aisdati.events.anchorages import of_area
from aisdati.events.rules import EventRules
from aisdati.geo import moved_m
from aisdati.tracks.reports import read_reports, read_vessels
from aisdati.tracks.store import load_tracks, read_track_table
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


def _own(events: pd.DataFrame) -> pd.DataFrame:
    return events[events["kind"] != "encounter"]


def _events_of(frame: pd.DataFrame) -> set[tuple]:
    return {(int(e.mmsi), e.kind, e.start, e.end, e.strength) for e in frame.itertuples()}


@pytest.mark.parametrize("area", ["kitimat", "processed"])
def test_a_vessels_events_are_its_own_alone_in_any_batch_and_any_chunking(area, request):
    """Kitimat's two months and the NY Harbor hour, judged by the area's ports and anchorages
    (as detect judges): each vessel's events are the same found with every vessel, with half
    of them, and alone; a track judged alone (`--track`) keeps exactly the batch's events that
    overlap it. Encounters are left out: one needs the other vessel."""
    data = request.getfixturevalue(area)
    reports, identity = read_reports(data), read_vessels(data)
    rules = EventRules(ports=of_area(data))
    every = _own(model_free_events(reports, identity, rules))
    assert len(every)
    mmsis = sorted(reports["mmsi"].unique())
    half = _own(model_free_events(reports[reports["mmsi"].isin(mmsis[::2])], identity, rules))
    assert _events_of(half) == _events_of(every[every["mmsi"].isin(mmsis[::2])])
    for mmsi in every["mmsi"].unique()[:5]:
        alone = model_free_events(reports[reports["mmsi"] == mmsi], identity, rules)
        assert _events_of(alone) == _events_of(every[every["mmsi"] == mmsi])
    tracks = load_tracks(data, read_track_table(data)["track_id"].tolist())
    batch = within(every, judged_windows(tracks, every=True))
    for track in tracks[:10]:
        windows = judged_windows([track], every=False)
        own = judged_reports(data, windows)
        assert set(own["mmsi"]) == {track.mmsi}
        alone = within(model_free_events(own, identity, rules), windows)
        start, end = windows.loc[0, "start"], windows.loc[0, "end"]
        mine = batch[(batch["mmsi"] == track.mmsi) & (batch["start"] <= end)
                     & (batch["end"] >= start)]  # fmt: skip
        assert _events_of(alone) == _events_of(mine)


def test_events_on_training_tracks_and_outside_the_windows_are_left_out(kitimat):
    reports, identity = read_reports(kitimat), read_vessels(kitimat)
    events = model_free_events(reports, identity)
    on_track = events.dropna(subset=["track_id"])
    training = on_track["track_id"].astype("int64").unique()[:3].tolist()
    kept = within(events, pd.DataFrame({"mmsi": [-1], "start": [events["start"].min()],
                                        "end": [events["end"].max()]}), training)  # fmt: skip
    assert len(kept) == len(events) - int(on_track["track_id"].isin(training).sum())
    later = events["start"].sort_values().iloc[len(events) // 2]
    windows = pd.DataFrame({"mmsi": [-1], "start": [later], "end": [events["end"].max()]})
    assert (within(events, windows)["end"] >= later).all()
