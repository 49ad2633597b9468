"""The measure of record of events: what the analyst meets on untouched traffic of a later
period, every event counted (on a track or not): alerts and activity per 1,000 vessel-days by
kind, tracks and vessels flagged, same-kind overlaps and the longest event of each kind beside
its bound, each rate with a 95 % bootstrap interval over vessels."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from aisdati.events.kinds import ALERT, KINDS
from aisdati.metrics import interval


def vessel_day_table(reports: pd.DataFrame) -> pd.Series:
    """Vessel-days per MMSI: the UTC days on which each vessel reported."""
    days = pd.to_datetime(reports["time"], utc=True).dt.floor("D")
    return (
        pd.DataFrame({"mmsi": reports["mmsi"], "day": days})
        .drop_duplicates()
        .groupby("mmsi")
        .size()
    )


def per_1000(
    counts: np.ndarray, days: np.ndarray, resamples: int = 1000
) -> tuple[float, tuple[float | None, float | None]]:
    """Events per 1,000 vessel-days of vessels with `counts` events in `days` vessel-days, and
    its 95 % bootstrap interval over the vessels (NaN where no day)."""
    total = float(days.sum())
    value = 1000.0 * counts.sum() / total if total else float("nan")
    ci = interval(lambda i: 1000.0 * counts[i].sum() / days[i].sum(), len(days), resamples)
    return float(value), ci


def overlaps(events: pd.DataFrame) -> int:
    """How many events overlap an earlier one of the same vessel and kind in time (sharing only
    an end is not overlapping)."""
    count = 0
    for _, g in events.groupby(["mmsi", "kind"]):
        g = g.sort_values("start")
        ends = pd.to_datetime(g["end"], utc=True).cummax().shift()
        count += int((pd.to_datetime(g["start"], utc=True) < ends).sum())
    return count


def alert_rates(
    events: pd.DataFrame,
    reports: pd.DataFrame,
    track_ids: np.ndarray,
    resamples: int = 1000,
) -> dict[str, Any]:
    """The measure of record of `events` found over untouched `reports` (every report judged)
    whose tracks are `track_ids`."""
    per_vessel = vessel_day_table(reports)
    mmsis = per_vessel.index.to_numpy()
    days = per_vessel.to_numpy(np.float64)
    total_days = float(days.sum())
    alerts = events[events["class"] == ALERT]

    def rate(frame: pd.DataFrame) -> tuple[float, tuple[float | None, float | None]]:
        counts = frame.groupby("mmsi").size().reindex(mmsis, fill_value=0).to_numpy(np.float64)
        return per_1000(counts, days, resamples)

    out: dict[str, Any] = {"vessels": len(mmsis), "vessel_days": total_days}
    out["alerts"] = len(alerts)
    out["alerts_per_1000"], out["alerts_per_1000_ci"] = rate(alerts)
    out["activity_per_1000"], _ = rate(events[events["class"] != ALERT])
    out["by_kind"] = {}
    for kind, g in events.groupby("kind"):
        per, ci = rate(g)
        bound = KINDS[kind].max_s
        out["by_kind"][kind] = {
            "class": KINDS[kind].cls, "events": len(g), "per_1000": per, "per_1000_ci": ci,
            "median_h": float(g["duration_s"].median() / 3600),
            "longest_h": float(g["duration_s"].max() / 3600),
            "bound_h": None if bound is None else bound / 3600,
        }  # fmt: skip
    gaps = events[events["kind"] == "gap"]
    out["gaps_by_coverage"] = {
        cover: rate(gaps[gaps["coverage"].fillna("unjudged") == cover])[0]
        for cover in ("heard", "quiet", "unjudged")
    }
    flagged = set(alerts["track_id"].dropna().astype("int64")) & set(track_ids.tolist())
    out["tracks"] = len(track_ids)
    out["tracks_flagged"] = len(flagged)
    out["tracks_flagged_share"] = len(flagged) / len(track_ids) if len(track_ids) else None
    out["vessels_alerted"] = int(alerts["mmsi"].nunique())
    out["most_alerts_one_vessel"] = int(alerts.groupby("mmsi").size().max()) if len(alerts) else 0
    out["alerts_off_track"] = int(alerts["track_id"].isna().sum())
    out["same_kind_overlaps"] = overlaps(events)
    out["over_bound"] = int(
        sum(
            (g["duration_s"] > KINDS[k].max_s + 1e-6).sum()
            for k, g in events.groupby("kind")
            if KINDS[k].max_s is not None
        )
    )
    return out
