"""The alert budget calibrated on a model's training period: what a model's card records of
the events its training period's reports raise at the finders' floors (the strongest
`KEEP` strengths of each budgeted kind, under `event:<kind>`, and the period's vessel-days,
under `event-days`), and the thresholds detection, evaluation and the live watch read back
from the cards (`thresholds_of`), pooled over the judging models."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from aisdati.events.budget import ALERTS_PER_1000, Thresholds, thresholds_for
from aisdati.events.find import found_at_floor
from aisdati.events.kinds import BUDGETED
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings

KEY = "event:"
DAYS = "event-days"
KEEP = 1000
"""The strongest events of a kind a card keeps: enough for a budget of 1,000 alerts per
1,000 vessel-days over a training period of a thousand vessel-days per kind."""


def vessel_days(vessels: Sequence[VesselReports]) -> float:
    """How many (vessel, UTC day) pairs have a report."""
    days = 0
    for v in vessels:
        days += len(np.unique(np.floor(v.time_s / 86400.0)))
    return float(days)


def calibration(
    vessels: Sequence[VesselReports],
    settings: EventSettings = EventSettings(),
    lengths: Mapping[int, float] | None = None,
    seen: np.ndarray | None = None,
    reported_motion: bool = True,
) -> dict[str, list[float]]:
    """What a model's card records of its training period (each vessel's reports, `lengths`
    by MMSI where known, `seen`: where its traffic reported ashore; `reported_motion`: False
    where SOG/COG were derived from positions)."""
    lengths = lengths or {}
    strengths: dict[str, list[float]] = {kind: [] for kind in BUDGETED}
    for v in vessels:
        for e in found_at_floor(v, settings, lengths.get(v.mmsi, np.nan), seen, reported_motion):
            if e.kind in strengths:
                strengths[e.kind].append(e.strength)
    out = {  # a kind with no event is left out (a card's lists are never empty)
        KEY + k: [round(x, 6) for x in sorted(s, reverse=True)[:KEEP]]
        for k, s in strengths.items()
        if s
    }
    return out | {DAYS: [vessel_days(vessels)]}


def is_calibrated(recorded: Mapping[str, Sequence[float]]) -> bool:
    """Whether a card records the alert budget's calibration (cards from before it do not)."""
    return DAYS in recorded


def thresholds_of(
    recorded: Sequence[Mapping[str, Sequence[float]]], budget: float = ALERTS_PER_1000
) -> Thresholds:
    """The thresholds of `budget` from the calibrations of the judging models' cards, pooled
    (the defaults where none records one)."""
    cards = [r for r in recorded if is_calibrated(r)]
    if not cards:
        return Thresholds()
    strengths = {kind: [x for r in cards for x in r.get(KEY + kind, [])] for kind in BUDGETED}
    days = sum(float(r[DAYS][0]) for r in cards)
    return thresholds_for(strengths, days, budget)


def training_period(reports: pd.DataFrame, tracks: pd.DataFrame) -> pd.DataFrame:
    """The reports a model's alert budget is calibrated on: every vessel's within its training
    tracks' time span (`tracks`: start, end). Every vessel's, as detection judges every
    vessel's: calibrated on the vessels with long tracks alone, the budget held for them and not
    for the rest (on a US coastal day, 1,050 vessel-days, 273 alerts per 1,000 against 10)."""
    if not len(tracks):
        return reports.iloc[:0]
    first, last = tracks["start"].min(), tracks["end"].max()
    return reports[(reports["time"] >= first) & (reports["time"] <= last)]
