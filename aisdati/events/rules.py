"""What a vessel's reports are judged by, in one object, the same in `detect`, `evaluate` and
`watch`: the finders' floors, the alert thresholds (`aisdati.events.budget`), where the area's
training traffic reported ashore, its ports and anchorages, and whether the reports' motion is
their own (not derived from positions at ingest). `aisdati.detection.events.event_rules` makes
it from models."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

import numpy as np

from aisdati.events.anchorages import Anchorages
from aisdati.events.budget import Thresholds
from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports
from aisdati.events.settings import EventSettings
from aisdati.events.stretch import Found


@dataclass(frozen=True, eq=False)
class EventRules:
    settings: EventSettings = field(default_factory=EventSettings)
    thresholds: Thresholds = field(default_factory=Thresholds)
    seen: np.ndarray | None = None
    """[m, 2] lon/lat where the training traffic reported ashore (`aisdati.tracks.ashore`)."""
    reported_motion: bool = True
    ports: Anchorages | None = None
    """The area's ports and anchorages (`aisdati.events.anchorages`); None: learned from the
    stopped reports of the vessels judged together (`aisdati.events.fleet.Fleet.anchorages`)."""

    def events(
        self,
        v: VesselReports,
        length_m: float = np.nan,
        kinds: Collection[str] | None = None,
        land: np.ndarray | None = None,
    ) -> list[Found]:
        """The vessel's model-free events (`aisdati.events.find.find_events`: `kinds` only,
        `land` its reports ashore if known)."""
        return find_events(
            v, self.thresholds, self.settings, length_m, self.seen, self.reported_motion, kinds,
            land,
        )  # fmt: skip
