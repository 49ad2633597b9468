"""The kinds of event, defined once: what each means, whether it needs a learned model, and
whose definition it follows. docs/detectors.md prints this table; events.parquet's `kind`
holds the names."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EventKind:
    name: str
    label: str
    """A few words for tables and popups."""
    needs_model: bool
    """Whether it comes from a learned model (else: from the reports alone)."""
    definition: str
    follows: str
    """Whose definition it follows, and where ours differs."""


KINDS: dict[str, EventKind] = {
    k.name: k
    for k in (
        EventKind(
            "off-traffic",
            "off the learned traffic",
            True,
            "the stretch around a flagged track's largest deviation where its deviation from "
            "what the area model generates stays above half its peak",
            "ours (DATI's score, section 6.2 of the paper, made local)",
        ),
        EventKind(
            "unseen-route",
            "bound where no training track went",
            True,
            "a track whose start and end are farther from every training track's start and end "
            "than --near-km and than 99 % of the training tracks are from each other",
            "ours (the routing's origin-destination distance)",
        ),
        EventKind(
            "position-jump",
            "position inconsistent with reported motion",
            False,
            "a stretch that the positions enter and leave by a jump the reported speed and "
            "course do not explain, the two jumps opposite (the stretch displaced as a whole: "
            "a shifted or spoofed stretch)",
            "ours",
        ),
        EventKind(
            "speed-inconsistent",
            "reported speed inconsistent",
            False,
            "a stretch where the reported speed jumps report to report (from its neighbours' "
            "mean) far beyond the vessel's own jumps, accumulated by a CUSUM: a faulty speed log",
            "ours",
        ),
        EventKind(
            "course-inconsistent",
            "reported course inconsistent",
            False,
            "a stretch where the reported course departs from the course the positions show (the "
            "bearing from the report before to the report after) far beyond the vessel's own "
            "departures, under way (over 2 kn), accumulated by a CUSUM",
            "ours",
        ),
        EventKind(
            "drift",
            "drift",
            False,
            "course over ground more than 45 degrees from the heading and from its reverse, "
            "at 1-5 kn, for at least 10 minutes; vessels known to be under 50 m are left out",
            "AisAbnormal's drift; ours also reports it for vessels of unknown length",
        ),
        EventKind(
            "sudden-speed-change",
            "sudden speed change",
            False,
            "the reported speed falls from over 7 kn to under 1 kn within 30 s and stays under "
            "1 kn for at least a minute",
            "AisAbnormal's sudden speed change",
        ),
        EventKind(
            "loitering",
            "loitering",
            False,
            "under 2 kn (reported and by position) for at least an hour between two stretches "
            "under way, not reporting at anchor or moored",
            "Global Fishing Watch's loitering (average speed under 2 kn for an hour or more); "
            "ours needs no distance from shore but excludes the ends of a vessel's reports "
            "(port and anchorage before or after its voyage)",
        ),
        EventKind(
            "gap",
            "gap at sea (going dark)",
            False,
            "no report for more than 10 times the vessel's usual interval and at least 5 "
            "minutes (at most a day), after reporting under way, both ends on water",
            "Global Fishing Watch's AIS gaps (theirs: 12 hours offshore); ours scales with the "
            "vessel's own interval",
        ),
        EventKind(
            "ashore",
            "reports ashore",
            False,
            "two or more reports 400 m or more inland on the coastline, where the training "
            "traffic never reported",
            "ours (aisdati.tracks.ashore)",
        ),
    )
}
MODEL_FREE = tuple(name for name, kind in KINDS.items() if not kind.needs_model)
"""The kinds found from the reports alone, with no trained model."""
