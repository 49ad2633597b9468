"""The evaluation's events: what `aisdati detect` reports of the held-out tracks, by the same
code (`aisdati.detection.events`: the model-free kinds over the reports, off-traffic over the
tracks a model flags), placed on each track's reports so that `event_metrics` can tell which
injected stretches they find.

Each held-out track's reports are judged on their own, not as one vessel's: an injected kind
that re-times its track (loiter, speed, drift) can make it overlap in time the vessel's next
held-out track, which a vessel's reports never do."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from aisdati.detection.events import (
    all_events,
    event_rules,
    model_free_events,
    off_traffic_events,
)
from aisdati.detectors import Detector
from aisdati.evaluation.alerts import alert_rates
from aisdati.evaluation.metrics import EVENT_FIELDS
from aisdati.tracks.reports import motion_derived, read_identities, read_reports, read_vessels
from aisdati.tracks.store import Track, read_track_table

TOLERANCE_US = 1000
"""Event times (from track hours) meet report times (microseconds) within this."""


def model_free(
    data: Path, track_ids: Sequence[int], detectors: Sequence[Detector], ashore: bool
) -> pd.DataFrame:
    """Every model-free event of each of the tracks (`model_free_events`), judged track by
    track, with the alert thresholds the detectors calibrated and the water their training
    traffic sailed ashore, as detect takes them; without `ashore`, no ashore events (as
    `detect --no-ashore`)."""
    reports = read_reports(data, list(track_ids))
    identity = read_vessels(data)
    rules = event_rules(detectors, reported_motion=not motion_derived(data))
    parts = [model_free_events(g, identity, rules) for _, g in reports.groupby("track_id")]
    events = all_events(parts)
    return events if ashore else events[events["kind"] != "ashore"]


def forward_alerts(
    data: Path, before: pd.Timestamp, detectors: Sequence[Detector], resamples: int = 1000
) -> dict:
    """The measure of record on the untouched traffic from `before` on (every report of `data`,
    on a track or not), judged by the detectors' alert thresholds as `detect --cluster all`
    judges it (`aisdati.evaluation.alerts.alert_rates`)."""
    reports = read_reports(data)
    later = reports[reports["time"] >= before]
    rules = event_rules(detectors, reported_motion=not motion_derived(data))
    events = model_free_events(later, read_vessels(data), rules, read_identities(data))
    events = events[pd.to_datetime(events["end"], utc=True) >= before]  # (a change before it)
    tracks = read_track_table(data)
    ids = tracks.loc[tracks["start"] >= before, "track_id"].to_numpy()
    return alert_rates(events, later, ids, resamples) | {"budget": rules.thresholds.budget}


def with_off_traffic(
    free: pd.DataFrame,
    tracks: Sequence[Track],
    values: np.ndarray,
    threshold: float,
    profiles: Sequence[np.ndarray],
    model: str,
) -> pd.DataFrame:
    """The model-free events and the off-traffic events of the tracks whose `values` exceed
    `threshold` (`off_traffic_events`, `model` naming the model)."""
    scores = pd.DataFrame({"score": values, "threshold": threshold, "model": model})
    learned = off_traffic_events(tracks, scores, profiles, pd.DataFrame())
    return all_events([learned, free.drop(columns="event_id", errors="ignore")])


def on_reports(events: pd.DataFrame, tracks: Sequence[Track]) -> pd.DataFrame:
    """The events as `EVENT_FIELDS`: each one's first and last report on its track."""
    times = {t.track_id: _times_us(t) for t in tracks}
    rows = []
    for e in events.dropna(subset=["track_id"]).itertuples():
        t = times.get(int(e.track_id))
        if t is None:
            continue
        first = int(np.searchsorted(t, _us(e.start) - TOLERANCE_US))
        last = int(np.searchsorted(t, _us(e.end) + TOLERANCE_US, side="right")) - 1
        rows.append((int(e.track_id), e.kind, first, last, float(e.strength)))
    return pd.DataFrame(rows, columns=list(EVENT_FIELDS))


def _times_us(track: Track) -> np.ndarray:
    hours = np.r_[0.0, np.cumsum(track.dts)]
    return _us(track.start) + np.round(hours * 3.6e9).astype(np.int64)


def _us(time: pd.Timestamp) -> int:
    return int(pd.Timestamp(time).value) // 1000  # .value: nanoseconds whatever the unit
