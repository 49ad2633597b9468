"""How events find injected stretches (`event_metrics`: `aisdati evaluate`), with bootstrap
intervals; the ranking and flagging metrics are `aisdati.metrics`'."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from aisdati.metrics import interval, roc_auc

RIGHT_EVENTS: dict[str, tuple[str, ...]] = {
    "shift": ("position-jump",),
    "jump": ("position-jump",),
    "noise": ("position-jump", "off-traffic"),
    "course-noise": ("course-inconsistent",),
    "speed-noise": ("speed-inconsistent",),
    "gap": ("gap",),
    "drift": ("drift",),
    "detour": ("off-traffic", "position-jump"),
    "loiter": ("off-traffic", "position-jump"),
    "speed": ("speed-inconsistent", "off-traffic"),
}
"""The event kinds (`aisdati.events.kinds`) that name each injected kind rightly."""
EVENT_FIELDS = ("track_id", "kind", "first", "last", "strength")
"""An event as the event metrics read it: its track, kind, first and last report (indices
into the track, inclusive) and strength."""


def event_metrics(
    labels: pd.DataFrame, events: pd.DataFrame, kinds: Sequence[str], resamples: int = 1000
) -> list[dict[str, Any]]:
    """Per injected kind, how the events (`EVENT_FIELDS`) find its stretches (labels: track_id,
    label, kind, start, end: [start, end) report indices): the share of stretches an event of
    any kind overlaps and of the right kind (`RIGHT_EVENTS`), the share of tracks with any
    event, ROC AUC of the track score (the largest strength of a right event, 0 if none),
    right events per 100 normal tracks, and the median distance in reports from the right
    event's start to the stretch's; each with its 95 % bootstrap interval."""
    normal = labels[labels["label"] == 0]
    on_normal = events[events["track_id"].isin(normal["track_id"])]
    rows = [
        _kind_row(kind, labels[labels["kind"] == kind], normal, events, on_normal, resamples)
        for kind in kinds
    ]
    per_100 = _per_100(on_normal, len(normal), resamples)
    rows.append({"kind": "any", "anomalies": int((labels["label"] == 1).sum()), **per_100})
    return rows


def _kind_row(
    kind: str,
    altered: pd.DataFrame,
    normal: pd.DataFrame,
    events: pd.DataFrame,
    on_normal: pd.DataFrame,
    resamples: int,
) -> dict[str, Any]:
    """`event_metrics`' row of one injected kind."""
    right = RIGHT_EVENTS.get(kind, ())
    found = [
        _found(s, events[events["track_id"] == s.track_id], right) for s in altered.itertuples()
    ]
    hit_any, hit, flagged, score, error = np.array(found, float).reshape(-1, 5).T
    normal_score = _scores(normal["track_id"], on_normal, right)
    y = np.r_[np.ones(len(score)), np.zeros(len(normal_score))]
    both = np.r_[score, normal_score]
    missed = error[np.isfinite(error)]
    return {
        "kind": kind,
        "right_events": ", ".join(right),
        "anomalies": len(altered),
        **_share("overlapped_any", hit_any, resamples),
        **_share("overlapped", hit, resamples),
        **_share("flagged", flagged, resamples),
        "roc_auc": roc_auc(y, both) if len(y) else None,
        "roc_auc_ci": interval(lambda k: roc_auc(y[k], both[k]), len(y), resamples),
        **_per_100(on_normal[on_normal["kind"].isin(right)], len(normal), resamples),
        "median_start_error": float(np.median(missed)) if len(missed) else None,
        "median_start_error_ci": interval(
            lambda k: float(np.median(missed[k])), len(missed), resamples
        ),
    }


def _found(stretch: Any, events: pd.DataFrame, right: tuple[str, ...]) -> tuple[float, ...]:
    """Of one injected stretch: whether an event overlaps it, whether a right one does,
    whether its track has any event, its track score and the start error of the nearest
    overlapping right event (NaN: none)."""
    over = (events["first"] < stretch.end) & (events["last"] >= stretch.start)
    is_right = events["kind"].isin(right)
    starts = events.loc[over & is_right, "first"].to_numpy()
    strength = events.loc[is_right, "strength"]
    return (
        float(over.any()),
        float((over & is_right).any()),
        float(len(events) > 0),
        float(strength.max()) if len(strength) else 0.0,
        float(np.min(np.abs(starts - stretch.start))) if len(starts) else np.nan,
    )


def _scores(tracks: pd.Series, events: pd.DataFrame, right: tuple[str, ...]) -> np.ndarray:
    """Each track's score: the largest strength of its right events, 0 where none."""
    best = events[events["kind"].isin(right)].groupby("track_id")["strength"].max()
    return tracks.map(best).fillna(0.0).to_numpy(np.float64)


def _share(name: str, hits: np.ndarray, resamples: int) -> dict[str, Any]:
    """The share of `hits` and its interval, as `name` and `name`_ci."""
    mean = (lambda k: float(hits[k].mean())) if len(hits) else (lambda k: None)
    return {
        name: float(hits.mean()) if len(hits) else None,
        f"{name}_ci": interval(mean, len(hits), resamples),
    }


def _per_100(events: pd.DataFrame, n_tracks: int, resamples: int) -> dict[str, Any]:
    """Events per 100 of `n_tracks` tracks (events: theirs), with its interval over tracks."""
    counts = np.zeros(n_tracks)
    per = events.groupby("track_id").size().to_numpy()
    counts[: len(per)] = per
    return {
        "false_events_per_100": 100.0 * counts.mean() if n_tracks else None,
        "false_events_per_100_ci": interval(
            lambda k: 100.0 * float(counts[k].mean()), n_tracks, resamples
        ),
    }
