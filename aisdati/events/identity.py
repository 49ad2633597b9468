"""Who a vessel is, judged across its reports: `identity-conflict` (one MMSI from two
transmitters, which ingest's cleaning kept as two vessels: `aisdati.preprocess.transmitters`)
and `identity-change` (a vessel that reports a new name, type or size, from the identity
history: identities.parquet, `aisdati.tracks.schema.IDENTITY_SCHEMA`). Both are fleet kinds
(`aisdati.events.fleet`): a conflict names two vessel ids, a change needs the history, not one
vessel's positions. The live watch raises the same events by the same functions
(`conflict_rows`, `identity_changes`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from aisdati.events.record import event_row
from aisdati.events.reports import VesselReports
from aisdati.geo import haversine_m
from aisdati.preprocess.transmitters import MIN_REPORTS
from aisdati.tracks.schema import KNOT_MPS, VESSEL_COLUMNS, is_second_transmitter, mmsi_of

if TYPE_CHECKING:  # the fleet module registers these finders
    from aisdati.events.fleet import Fleet
    from aisdati.events.rules import EventRules

REACH_KN = 50.0
"""The speed no vessel passes (ingest's `--max-speed` default): a conflict's strength is how far
its switches between the two places are beyond reach at it."""
LENGTH_TOLERANCE_M = 1.0
"""Lengths that differ by less are the same (sources round them differently)."""
STRETCH_GAP_S = 3600.0
"""A silence of both transmitters this long ends a conflict's stretch (a new one begins when
they report again): an analyst reads a day's conflict, not a month's."""
FIELDS = {"name": "name", "ship_type": "type", "length_m": "length"}
"""The fields of an identity compared, and how the evidence calls them."""


def conflict_rows(
    first: VesselReports,
    second: VesselReports,
    who: tuple[dict[str, Any], dict[str, Any]],
) -> list[dict[str, Any]]:
    """The `identity-conflict`s of an MMSI's two transmitters (`first` under the MMSI, `second`
    under its second transmitter's id; `who`: each one's identity as events name it): one per
    stretch in which both report (their reports together, cut where neither reports for
    `STRETCH_GAP_S`; each needing `MIN_REPORTS` of both), over the time both report in it,
    placed at the first's median position there, its stretch the line between the two places;
    strength, the median of how far each switch between them is beyond reach (1: at reach)."""
    times = np.sort(np.r_[first.time_s, second.time_s])
    cuts = np.flatnonzero(np.diff(times) > STRETCH_GAP_S)
    starts, ends = np.r_[times[:1], times[cuts + 1]], np.r_[times[cuts], times[-1:]]
    rows = []
    for lo, hi in zip(starts, ends, strict=True):
        a, b = _within(first, lo, hi), _within(second, lo, hi)
        if a.sum() < MIN_REPORTS or b.sum() < MIN_REPORTS:
            continue
        start = max(first.time_s[a][0], second.time_s[b][0])
        end = min(first.time_s[a][-1], second.time_s[b][-1])
        if start <= end:
            rows.append(_conflict_row(first, second, who, (start, end)))
    return rows


def _conflict_row(
    first: VesselReports,
    second: VesselReports,
    who: tuple[dict[str, Any], dict[str, Any]],
    span: tuple[float, float],
) -> dict[str, Any]:
    a, b = _within(first, *span), _within(second, *span)
    here = (float(np.median(first.lon[a])), float(np.median(first.lat[a])))
    there = (float(np.median(second.lon[b])), float(np.median(second.lat[b])))
    apart_km = float(haversine_m(*here, *there)) / 1000.0
    strength = _beyond_reach(first, second, a, b)
    evidence = (
        f"MMSI {first.mmsi} reports from two places {apart_km:,.1f} km apart at once "
        f"({_place(here)} and {_place(there)}): {int(a.sum())} and {int(b.sum())} reports "
        f"interleaved; the second transmitter is kept as {second.mmsi}"
    )
    return event_row(
        first.mmsi, "identity-conflict", span, int(a.sum() + b.sum()), here,
        ([here[0], there[0]], [here[1], there[1]]), strength, evidence,
        identity=who[0], others=[who[1]],
    )  # fmt: skip


def _within(v: VesselReports, start: float, end: float) -> np.ndarray:
    return (v.time_s >= start) & (v.time_s <= end)


def _beyond_reach(
    first: VesselReports, second: VesselReports, a: np.ndarray, b: np.ndarray
) -> float:
    """The median, over consecutive reports of the two that switch transmitter, of their
    distance over what `REACH_KN` covers in the time between them."""
    time = np.r_[first.time_s[a], second.time_s[b]]
    order = np.argsort(time, kind="stable")
    lon = np.r_[first.lon[a], second.lon[b]][order]
    lat = np.r_[first.lat[a], second.lat[b]][order]
    which = np.r_[np.zeros(a.sum()), np.ones(b.sum())][order]
    switch = np.flatnonzero(which[1:] != which[:-1])
    dist = haversine_m(lon[switch], lat[switch], lon[switch + 1], lat[switch + 1])
    reach = REACH_KN * KNOT_MPS * np.diff(time[order])[switch] + 50.0
    return float(np.median(dist / reach)) if len(switch) else 1.0


def _place(lonlat: tuple[float, float]) -> str:
    lon, lat = lonlat
    return f"{abs(lat):.3f} {'N' if lat >= 0 else 'S'} {abs(lon):.3f} {'E' if lon >= 0 else 'W'}"


def find_conflicts(fleet: Fleet, rules: EventRules) -> list[dict[str, Any]]:
    """An `identity-conflict` for each second transmitter of the fleet whose MMSI's first
    transmitter is judged too (the second named by its id, with its MMSI's name and type: no
    receiver tells their static messages apart)."""
    rows = []
    for vessel, second in fleet.vessels.items():
        first = fleet.vessels.get(mmsi_of(vessel))
        if not is_second_transmitter(vessel) or first is None:
            continue
        who = fleet.who(first.mmsi)
        rows += conflict_rows(first, second, (who, {**who, "mmsi": vessel}))
    return rows


def identity_changes(history: pd.DataFrame, repeats: int) -> list[tuple[dict, dict]]:
    """One vessel's changes of identity, (before, after) each, from its history (rows of
    `IDENTITY_SCHEMA`, any order): the identities reported by at least `repeats` reports, in
    the order first reported, each that gives a field (name, type, or length by
    `LENGTH_TOLERANCE_M` or more) other than the vessel's latest value of it. A field one
    leaves out (a static message in two parts gives the name apart from the type) changes
    nothing; `before` is the vessel's latest values of every field."""
    held = history[(history["reports"] >= repeats) & history["first"].notna()]
    held = held.sort_values(["first", "last"], kind="stable").to_dict("records")
    changes = []
    current: dict = {}
    for after in held:
        if current and differs(current, after):
            changes.append((dict(current), after))
        current.update({f: after[f] for f in VESSEL_COLUMNS if _given(after.get(f))})
    return changes


def _given(value: object) -> bool:
    return value is not None and not pd.isna(value)


def differs(before: dict, after: dict) -> list[str]:
    """The fields (`FIELDS`) two identities both give and give differently."""
    out = []
    for field in VESSEL_COLUMNS:
        old, new = before.get(field), after.get(field)
        if not (_given(old) and _given(new)):
            continue
        same = abs(old - new) < LENGTH_TOLERANCE_M if field == "length_m" else old == new
        if not same:
            out.append(field)
    return out


def change_evidence(before: dict, after: dict) -> str:
    """What changed, before -> after, field by field."""
    said = [
        f"{FIELDS[f]} {_shown(before[f])} -> {_shown(after[f])}" for f in differs(before, after)
    ]
    return "; ".join(said)


def _shown(value: object) -> str:
    return f"{value:g} m" if isinstance(value, float) else repr(value)


def change_row(v: VesselReports, before: dict, after: dict, who: dict) -> dict[str, Any]:
    """The `identity-change` from `before` to `after` of vessel `v`: at the time the new
    identity was first reported, placed at the vessel's report nearest that time."""
    at = pd.Timestamp(after["first"]).value / 1e9
    k = int(np.argmin(np.abs(v.time_s - at))) if len(v) else None
    place = (float(v.lon[k]), float(v.lat[k])) if k is not None else (np.nan, np.nan)
    now = {"name": after.get("name") or who.get("name"), "ship_type": after.get("ship_type")}
    return event_row(
        v.mmsi, "identity-change", (at, at), 1, place, ([place[0]], [place[1]]),
        1.0, change_evidence(before, after), identity=now,
    )  # fmt: skip


def find_changes(fleet: Fleet, rules: EventRules) -> list[dict[str, Any]]:
    """An `identity-change` at each change of identity of a judged vessel (`identity_changes`;
    a second transmitter's id is left out: it shares its MMSI's history)."""
    history = fleet.history
    if history is None or not len(history):
        return []
    rows = []
    judged = history[history["mmsi"].isin(list(fleet.vessels))]
    for mmsi, mine in judged.groupby("mmsi", sort=True):
        v = fleet.vessels[int(mmsi)]
        for before, after in identity_changes(mine, rules.settings.identity_repeats):
            rows.append(change_row(v, before, after, fleet.who(int(mmsi))))
    return rows
