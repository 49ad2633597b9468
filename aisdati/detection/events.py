"""A detection's events: the model-free kinds over each judged vessel's reports, the learned
kinds (off-traffic, unseen-route) over the tracks the models judge; a track is flagged when it
has an alert (`aisdati.events.kinds`: activity flags nothing).

An event is a function of its vessel's reports alone: each judged vessel's reports are read
whole from the ingest output and its events found over them; those that overlap what is judged
are kept (with a model: the judged tracks' time span for the whole area, each judged track's
span for a route or `--track`, never an event on the models' own training tracks; with no
model, every report). So a track's events are the same alone, in any batch and live. Slow
reports are judged with the rest: reports.parquet keeps what the paper's SOG filter keeps out
of the tracks."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from aisdati.detection.routing import od_distances, reach_km
from aisdati.detectors import Detector
from aisdati.events.anchorages import Anchorages
from aisdati.events.budget import ALERTS_PER_1000
from aisdati.events.calibrate import is_calibrated, thresholds_of
from aisdati.events.find import placed
from aisdati.events.fleet import Fleet, fleet_events
from aisdati.events.kinds import ALERT
from aisdati.events.record import EVENT_COLUMNS, event_row
from aisdati.events.reports import vessels
from aisdati.events.rules import EventRules
from aisdati.events.stretch import deviation_stretch
from aisdati.tracks.reports import read_reports
from aisdati.tracks.store import Track

NO_IDENTITY = {"name": None, "ship_type": None, "length_m": np.nan}
UNSEEN_RATE = 0.01
"""The share of its training tracks' own origin-destination distances an unseen route must
exceed."""


def event_rules(
    models: Sequence[Detector],
    budget: float = ALERTS_PER_1000,
    reported_motion: bool = True,
    ports: Anchorages | None = None,
) -> EventRules:
    """What the judging models' areas judge reports by: the alert thresholds of `budget`
    calibrated on their training periods (`aisdati.events.calibrate`; the defaults for models
    from before the budget), the water their training traffic sailed ashore, and the area's
    ports and anchorages (`ports`; None: learned from the reports judged)."""
    seen = [np.asarray(m.card.data.ashore, np.float64).reshape(-1, 2) for m in models]
    return EventRules(
        thresholds=thresholds_of([m.card.calibration for m in models], budget),
        seen=np.concatenate(seen) if seen else None,
        reported_motion=reported_motion,
        ports=ports,
    )


def uncalibrated_note(models: Sequence[Detector]) -> str | None:
    """The warning models trained before the alert budget earn: their alerts are judged by
    the defaults, not by their area's traffic."""
    old = [m.name for m in models if not is_calibrated(m.card.calibration)]
    if not old:
        return None
    return (
        f"{', '.join(old)} predate(s) the alert budget: the alerts' thresholds are the "
        "defaults, not the area's; retrain to calibrate them on its training period"
    )


def judged_windows(tracks: Sequence[Track], every: bool) -> pd.DataFrame:
    """What is judged, per vessel (mmsi, start, end): `every` (the whole area): every vessel
    over the judged tracks' span (mmsi -1: any vessel); else each judged track's span."""
    ends = [t.start + pd.Timedelta(hours=float(np.sum(t.dts))) for t in tracks]
    if every:
        first = min((t.start for t in tracks), default=pd.Timestamp.min.tz_localize("UTC"))
        last = max(ends, default=pd.Timestamp.max.tz_localize("UTC"))
        return pd.DataFrame({"mmsi": [-1], "start": [first], "end": [last]})
    return pd.DataFrame(
        {"mmsi": [t.mmsi for t in tracks], "start": [t.start for t in tracks], "end": ends}
    )


def judged_reports(data_dir: Path, windows: pd.DataFrame) -> pd.DataFrame:
    """The whole reports of every vessel `windows` judge (all vessels where one window is for
    any vessel), so that each vessel's events are found over its own reports."""
    wanted = None if (windows["mmsi"] == -1).any() else sorted(set(windows["mmsi"]))
    return read_reports(data_dir, mmsis=wanted)


def within(
    events: pd.DataFrame, windows: pd.DataFrame, training: Sequence[int] = ()
) -> pd.DataFrame:
    """The events that overlap a window of their vessel (`judged_windows`) and are not placed
    on a training track."""
    if not len(events):
        return events
    keep = np.zeros(len(events), bool)
    start, end = pd.to_datetime(events["start"], utc=True), pd.to_datetime(events["end"], utc=True)
    for w in windows.itertuples():
        mine = (events["mmsi"] == w.mmsi) if w.mmsi != -1 else True
        keep |= np.asarray(mine & (start <= w.end) & (end >= w.start), bool)
    on_training = events["track_id"].isin(list(training)).to_numpy()
    return events[keep & ~on_training].reset_index(drop=True)


def model_free_events(
    reports: pd.DataFrame,
    identity: pd.DataFrame,
    rules: EventRules = EventRules(),
    history: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Every model-free event of every vessel of `reports` by `rules`, the one-vessel kinds and
    the fleet kinds (`aisdati.events.fleet`) (`identity`: vessels.parquet by MMSI; `history`:
    identities.parquet, None where the ingest has none)."""
    frames, fleet = [], Fleet({}, {}, history)
    for v in vessels(reports):
        who = _who(identity, v.mmsi)
        fleet.vessels[v.mmsi], fleet.identity[v.mmsi] = v, who
        found = rules.events(v, who["length_m"])
        if found:
            frames.append(placed(v, found, who, rules.thresholds))
    own = pd.concat(frames, ignore_index=True) if frames else empty_events()
    return fleet_events(fleet, rules, own)


def _who(identity: pd.DataFrame, mmsi: int) -> dict:
    if mmsi not in identity.index:
        return NO_IDENTITY
    row = identity.loc[mmsi]
    return {k: (None if pd.isna(row[k]) else row[k]) for k in NO_IDENTITY} | {
        "length_m": float(row["length_m"]) if pd.notna(row["length_m"]) else np.nan
    }


def off_traffic_events(
    tracks: Sequence[Track],
    scores: pd.DataFrame,
    profiles: Sequence[np.ndarray],
    identity: pd.DataFrame,
) -> pd.DataFrame:
    """For each track whose score is above its threshold, the stretch where it strays most
    (`deviation_stretch`) as an off-traffic event, its strength the score over the threshold."""
    rows = []
    for track, (_, s), profile in zip(tracks, scores.iterrows(), profiles, strict=True):
        if not s["score"] > s["threshold"]:
            continue
        a, b = deviation_stretch(profile)
        peak = int(np.argmax(profile))
        said = f"strays {profile[peak]:,.0f} m from what {s['model']} generates"
        strength = float(s["score"] / s["threshold"])
        rows.append(
            _track_event(
                track, identity, "off-traffic", (a, b - 1, peak), strength, said, s["model"]
            )
        )
    return pd.DataFrame(rows, columns=list(EVENT_COLUMNS))


def unseen_route_events(
    tracks: Sequence[Track],
    scores: pd.DataFrame,
    models: Sequence[Detector],
    identity: pd.DataFrame,
    near_km: float,
) -> pd.DataFrame:
    """Tracks bound where no training track of their judging model went: the origin-destination
    distance (`aisdati.detection.routing.reach_km`) over the larger of `near_km` and the
    (1 - `UNSEEN_RATE`) quantile of the training tracks' own distances to each other;
    the event spans the track, placed at its end. Cards that do not record ends are left out."""
    by_name = {m.name: m for m in models}
    limits = {name: _unseen_limit(m, near_km) for name, m in by_name.items()}
    rows = []
    for track, model in zip(tracks, scores["model"], strict=True):
        card, limit = by_name[model].card, limits[model]
        if limit is None:
            continue
        reach = float(reach_km(card, track.positions[:1], track.positions[-1:])[0])
        if reach > limit:
            said = f"its start and end are {reach:.1f} km from every training track's"
            last = len(track.positions) - 1
            where = (0, last, last)
            rows.append(
                _track_event(track, identity, "unseen-route", where, reach / limit, said, model)
            )
    return pd.DataFrame(rows, columns=list(EVENT_COLUMNS))


def _unseen_limit(model: Detector, near_km: float) -> float | None:
    data = model.card.data
    if data.ends is None or len(data.starts) < 2:
        return None
    own = od_distances(data.starts, data.ends, data.starts, data.ends, leave_one_out=True)
    return max(near_km, float(np.quantile(own, 1.0 - UNSEEN_RATE)) / 1000.0)


def _track_event(
    track: Track,
    identity: pd.DataFrame,
    kind: str,
    where: tuple[int, int, int],
    strength: float,
    evidence: str,
    model: str,
) -> dict:
    """A learned event on a track's points `where` = (first, last, strongest), as a row of
    `EVENT_COLUMNS`; its times the reports' own (microseconds)."""
    a, b, peak = where
    hours = np.r_[0, np.cumsum(track.dts)]
    start_s = track.start.value / 1e9 + hours * 3600.0
    p = track.positions
    return event_row(
        track.mmsi, kind, (start_s[a], start_s[b]), b - a + 1, (p[peak, 0], p[peak, 1]),
        (p[a : b + 1, 0].tolist(), p[a : b + 1, 1].tolist()), strength, evidence,
        identity=_who(identity, track.mmsi), track_id=track.track_id, model=model,
    )  # fmt: skip


def empty_events() -> pd.DataFrame:
    return pd.DataFrame(columns=list(EVENT_COLUMNS))


def with_identity(scores: pd.DataFrame, identity: pd.DataFrame) -> pd.DataFrame:
    """`scores` with each track's vessel name and type (vessels.parquet; null where unknown)."""
    out = scores.copy()
    for key in ("name", "ship_type"):
        known = identity[key] if key in identity.columns else pd.Series(dtype=object)
        out[key] = out["mmsi"].map(known).astype(object).where(lambda v: v.notna(), None)
    return out


def with_events(scores: pd.DataFrame, events: pd.DataFrame) -> pd.DataFrame:
    """`scores` with each track's number of events, of alerts, and their kinds, flagged where it
    has an alert (an activity flags nothing)."""
    on_track = events.dropna(subset=["track_id"])
    ids = on_track["track_id"].astype("int64")
    counts = on_track.groupby(ids).size()
    alerts = on_track[on_track["class"] == ALERT]
    per_alert = alerts.groupby(alerts["track_id"].astype("int64"))["kind"]
    kinds = on_track.groupby(ids)["kind"].agg(lambda k: ", ".join(sorted(set(k))))
    out = scores.copy()
    out["events"] = out["track_id"].map(counts).fillna(0).astype("int64")
    out["alerts"] = out["track_id"].map(per_alert.size()).fillna(0).astype("int64")
    out["event_kinds"] = out["track_id"].map(kinds).astype(object).where(lambda k: k.notna(), "")
    out["flagged"] = out["flagged"] | (out["alerts"] > 0)
    return out


def all_events(parts: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """The events of a detection together, strongest first within each vessel's time order."""
    parts = [p for p in parts if len(p)] or [empty_events()]
    events = pd.concat(parts, ignore_index=True).sort_values(["start", "mmsi", "kind"])
    events.insert(0, "event_id", np.arange(1, len(events) + 1))
    return events.reset_index(drop=True)
