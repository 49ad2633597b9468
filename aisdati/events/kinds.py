"""The kinds of event, defined once: what each means, whether it is an alert or an activity,
whether it needs a learned model, how long one may last, and whose definition it follows.
docs/detectors.md prints this table; events.parquet's `kind` and `class` hold the names.

An **alert** says a vessel or its reports behave abnormally: it flags the track and vessel,
and its kind's threshold is set by the alert budget (`aisdati.events.budget`). An
**activity** says what a vessel does that an analyst may want listed (it loitered, it went
silent): it is listed apart and flags nothing. A newcomer adding a kind adds it here, its
finder to `aisdati.events.find.FINDERS`, and its line to docs/detectors.md."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

ALERT, ACTIVITY = "alert", "activity"
HOUR = 3600.0


@dataclass(frozen=True)
class EventKind:
    name: str
    label: str
    """A few words for tables and popups."""
    cls: Literal["alert", "activity"]
    needs_model: bool
    """Whether it comes from a learned model (else: from the reports alone)."""
    max_s: float | None
    """The longest one may last (longer: cut to this around its strongest report); None: as
    long as what it describes lasts (a track, a gap's day)."""
    definition: str
    follows: str
    """Whose definition it follows, and where ours differs."""
    fleet: bool = False
    """Whether it is found across vessels (`aisdati.events.fleet`: an encounter names two, an
    interference an area and its vessels), not from one vessel's reports alone."""
    folds: tuple[str, ...] = ()
    """The one-vessel kinds it explains: those events of the vessels it names, within its time
    span, are folded into it, not raised one by one."""
    area: bool = False
    """Whether an event of it is an area (its `lons`/`lats` a closed ring, drawn as a polygon),
    not a stretch of one vessel's reports (drawn as a line, or a point)."""


KINDS: dict[str, EventKind] = {
    k.name: k
    for k in (
        EventKind(
            "off-traffic", "off the learned traffic", ALERT, True, None,
            "the stretch around a flagged track's largest deviation where its deviation from "
            "what the area model generates stays above half its peak",
            "ours (DATI's score, section 6.2 of the paper, made local)",
        ),
        EventKind(
            "unseen-route", "bound where no training track went", ALERT, True, None,
            "a track whose start and end are farther from every training track's start and end "
            "than --near-km and than 99 % of the training tracks are from each other",
            "ours (the routing's origin-destination distance)",
        ),
        EventKind(
            "position-jump", "position inconsistent with reported motion", ALERT, False,
            12 * HOUR,
            "a stretch of a vessel under way that its positions enter and leave by opposite "
            "jumps of 300 m or more, each within 15 minutes, that its reported speed and course "
            "do not explain (the stretch displaced as a whole: a shifted or spoofed stretch)",
            "ours",
        ),
        EventKind(
            "speed-inconsistent", "reported speed inconsistent", ALERT, False, 3 * HOUR,
            "a stretch of a vessel under way where the reported speed jumps report to report "
            "(from its neighbours' mean) far beyond the vessel's own jumps of the hours around, "
            "accumulated by a CUSUM: a faulty speed log",
            "ours",
        ),
        EventKind(
            "course-inconsistent", "reported course inconsistent", ALERT, False, 3 * HOUR,
            "a stretch of a vessel under way (over 2 kn) where the reported course departs from "
            "the course the positions show (the bearing from the report before to the report "
            "after) far beyond the vessel's own departures of the hours around, accumulated by "
            "a CUSUM",
            "ours",
        ),
        EventKind(
            "drift", "drift", ALERT, False, 24 * HOUR,
            "course over ground more than 45 degrees from the heading and from its reverse, "
            "at 1-5 kn, for at least 10 minutes; vessels known to be under 50 m are left out",
            "AisAbnormal's drift; ours also reports it for vessels of unknown length",
        ),
        EventKind(
            "sudden-speed-change", "sudden speed change", ALERT, False, 600.0,
            "the reported speed falls from over 7 kn to under 1 kn within 30 s and stays under "
            "1 kn for at least a minute; the event ends when that minute is held",
            "AisAbnormal's sudden speed change",
        ),
        EventKind(
            "ashore", "reports ashore", ALERT, False, 24 * HOUR,
            "two or more reports 400 m or more inland on the coastline, where the training "
            "traffic never reported",
            "ours (aisdati.tracks.ashore)",
        ),
        EventKind(
            "loitering", "loitering", ACTIVITY, False, None,
            "under 2 kn (reported and by position) for at least an hour and at most a day "
            "between two stretches under way, not reporting at anchor or moored",
            "Global Fishing Watch's loitering (average speed under 2 kn for an hour or more); "
            "ours needs no distance from shore but excludes the ends of a vessel's reports "
            "(port and anchorage before or after its voyage) and stays of over a day (a vessel "
            "laid up or at its berth)",
        ),
        EventKind(
            "gap", "gap at sea (going dark)", ACTIVITY, False, None,
            "no report for at least 30 minutes and 10 times the vessel's usual interval (at "
            "most a day), after reporting under way, both ends on water; its coverage is heard "
            "where another vessel within 20 km of the line between its ends reported during "
            "it, quiet where none did though others reported near it before and after",
            "Global Fishing Watch's AIS gaps (theirs: 12 hours, 50 nm offshore, for satellite "
            "reception); ours is for terrestrial receivers hearing a vessel every few minutes, "
            "and scales with the vessel's own interval. Its coverage follows their AIS "
            "disabling events (Welch et al. 2022), which keep a gap only where other vessels' "
            "reports show the reception was good; ours asks the vessels near it during it",
        ),
        EventKind(
            "encounter", "encounter at sea", ACTIVITY, False, None,
            "two vessels within 500 m of each other for at least 2 hours, both under 2 kn by "
            "their positions (sampled every 10 minutes), at least 10 km from every port and "
            "anchorage; one event per pair, naming both",
            "Global Fishing Watch's encounters (the same numbers); ours is between any two "
            "vessels (theirs: fishing vessels and carriers), its ports and anchorages are "
            "learned from the area's own traffic (theirs: years of the world's), and it "
            "interpolates across silences of at most an hour",
            fleet=True,
        ),
        EventKind(
            "port-visit", "port visit", ACTIVITY, False, None,
            "a vessel's stay within 3 km of a port or anchorage, until it is 4 km or more from "
            "every one, in which it stopped (under 0.5 kn) and which lasted at least 3 hours: "
            "its arrival, departure and duration; anchorages are learned from where at least 3 "
            "vessels stopped in a cell of 0.5 km, or given as GeoJSON (--ports)",
            "Global Fishing Watch's port visits (3 km in, 4 km out, a stop, 3 hours or more); "
            "theirs stops under 0.2 kn and their anchorages need 20 vessels over years",
            fleet=True, folds=("loitering",),
        ),
        EventKind(
            "identity-conflict", "one MMSI, two transmitters", ALERT, False, None,
            "one MMSI whose positions alternate between places no vessel could join in the time "
            "between them (at --max-speed, 50 kn): two transmitters, each of at least 10 reports,"
            " whose reports switch at least 4 times out of reach of each other, each with at "
            "least 10 reports heard within 3 minutes of one of the other's (both on the air at "
            "once, at AIS's longest reporting interval: one vessel's stale or mistimed report, or"
            " its own track picked up again after a silence, is not), not copies of one another "
            "(a receiver's clock); ingest keeps the second's reports as vessel MMSI + "
            "1000000000 (not dropped as outliers); one event per stretch in which both report (a "
            "silence of an hour ends one), naming both and their places",
            "Global Fishing Watch's segmenter (a report joins the segment it can be reached from;"
            " one MMSI becomes several segments); ours also raises it, and keeps each transmitter"
            " whole",
            fleet=True,
        ),
        EventKind(
            "identity-change", "identity changed", ALERT, False, None,
            "a vessel whose reported name, ship type or length (by 1 m or more) changes to a "
            "value given by at least 3 reports, at the time the new one is first reported, with "
            "before and after (identities.parquet: each identity's first and last time); a value "
            "a message leaves out is no change; call sign and IMO are not read yet",
            "ours (Global Fishing Watch's vessel identity keeps each identity's first and last "
            "time)",
            fleet=True,
        ),
        EventKind(
            "gnss-interference", "positions displaced over an area", ALERT, False, None,
            "3 or more vessels displaced alike within 15 minutes of one another and 50 km of "
            "one another (jumps of 1 km or more that their reported motion does not explain: "
            "by one shift and back, onto or from one point, onto one circle, or ashore), half "
            "or more of the vessels heard where they were: one event with its area, time span "
            "and vessels (an MMSI's two transmitters read as one vessel); their own jumps, reports "
            "ashore and the identity conflicts their displaced reports look like are folded "
            "into it",
            "C4ADS' Above Us Only Stars (2019: spoofed positions on common points and circles) "
            "and gpsjam.org (a cell is jammed when a share of its aircraft lose accuracy); ours "
            "reads each vessel's positions against its reported motion, needs the vessels "
            "displaced alike and most of the area's, and dates it to minutes",
            fleet=True, folds=("position-jump", "ashore", "identity-conflict"), area=True,
        ),
    )
}  # fmt: skip
MODEL_FREE = tuple(n for n, k in KINDS.items() if not k.needs_model and not k.fleet)
"""The kinds found from one vessel's reports alone, with no trained model."""
FLEET = tuple(n for n, k in KINDS.items() if k.fleet)
"""The kinds found across vessels (`aisdati.events.fleet`)."""
READ_REPORTED_MOTION = ("speed-inconsistent", "course-inconsistent", "sudden-speed-change", "drift")
"""The kinds that judge what a vessel reports of its motion: not looked for where ingest derived
SOG and COG from positions (a positions-only file), whose "reported" motion is the positions'."""
BUDGETED = tuple(n for n in MODEL_FREE if KINDS[n].cls == ALERT)
"""The alert kinds whose thresholds the alert budget sets (the learned kinds are bounded by
their model's track-level contamination instead)."""


def is_alert(kind: str) -> bool:
    return KINDS[kind].cls == ALERT
