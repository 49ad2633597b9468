"""Event metrics (`aisdati.evaluation.metrics.event_metrics`) on events found in real Kitimat
tracks with stretches injected into them."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from sklearn.metrics import roc_auc_score

from aisdati.evaluation.inject import inject
from aisdati.evaluation.metrics import EVENT_FIELDS, event_metrics
from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports
from aisdati.metrics import interval, roc_auc


def _reports(frame, got=None):
    frame = frame.sort_values("time").reset_index(drop=True)
    if got is None:
        return VesselReports.of(frame)
    t0 = frame["time"].iloc[0]
    return VesselReports.of(
        pd.DataFrame(
            {
                "mmsi": frame["mmsi"].iloc[0],
                "time": t0 + pd.to_timedelta(got.times_s, unit="s"),
                "lon": got.positions[:, 0],
                "lat": got.positions[:, 1],
                "sog": got.motion[:, 0],
                "cog": got.motion[:, 1],
                "heading": got.motion[:, 2],
            }
        )
    )


def test_shifted_stretches_are_found_by_position_jumps_and_normal_tracks_stay_quiet(kitimat):
    points = pq.read_table(kitimat / "points.parquet").to_pandas()
    ids = sorted(points["track_id"].unique())[:12]
    labels, events = [], []
    for k, tid in enumerate(ids):
        frame = points[points["track_id"] == tid]
        v = _reports(frame)
        label = (tid, 0, "", -1, -1)
        if k % 2:
            motion = np.column_stack([v.sog, v.cog, v.heading])
            p = np.column_stack([v.lon, v.lat])
            got = inject("shift", p, v.time_s - v.time_s[0], np.random.default_rng(k), None,
                         motion)  # fmt: skip
            v = _reports(frame, got)
            label = (tid, 1, "shift", *got.stretch)
        labels.append(label)
        events += [(tid, e.kind, e.start, e.end, e.strength) for e in find_events(v)]
    labels = pd.DataFrame(labels, columns=["track_id", "label", "kind", "start", "end"])
    events = pd.DataFrame(events, columns=list(EVENT_FIELDS))
    shift, anything = event_metrics(labels, events, ["shift"], resamples=200)
    assert shift["anomalies"] == 6 and shift["right_events"] == "position-jump"
    assert shift["overlapped"] >= 0.5 and shift["overlapped_any"] >= shift["overlapped"]
    assert shift["roc_auc"] >= 0.75 and shift["false_events_per_100"] <= 50
    low, high = shift["overlapped_ci"]
    assert low <= shift["overlapped"] <= high
    assert shift["median_start_error"] is not None and shift["median_start_error"] <= 2
    assert anything["kind"] == "any" and anything["false_events_per_100"] >= 0


def test_interval_brackets_the_statistic_and_is_none_without_values():
    x = np.arange(100.0)
    low, high = interval(lambda k: float(x[k].mean()), len(x))
    assert low < 49.5 < high
    assert interval(lambda k: None, 5) == (None, None)


def test_roc_auc_is_scikit_learns_with_ties_and_none_for_one_class():
    rng = np.random.default_rng(0)
    for _ in range(100):
        n = int(rng.integers(2, 200))
        y = rng.integers(0, 2, n)
        score = np.round(rng.normal(size=n), int(rng.integers(0, 3)))  # rounding: many ties
        if y.min() == y.max():
            assert roc_auc(y, score) is None
        else:
            assert roc_auc(y, score) == pytest.approx(roc_auc_score(y, score), abs=1e-12)
    assert roc_auc(np.zeros(5), np.arange(5)) is None
