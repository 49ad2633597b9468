"""The learned kind live: an area model (`--cluster all`) judges each vessel's recent window as a
track, as `detect` judges a track with it (its own score settings, its calibrated threshold at
the default contamination); a window over the threshold is an off-traffic event on the stretch
where it strays most (`aisdati.detection.events.off_traffic_events`). Route and cluster models
judge only tracks bound the way theirs are, which a window does not tell: they are not used
live."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from aisdati.detection.events import off_traffic_events
from aisdati.detection.routing import is_area_model
from aisdati.detectors import DEFAULT_CONTAMINATION, Detector, ScoreSettings
from aisdati.events.reports import VesselReports
from aisdati.live.decode import Identity
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track

EVERY = 20
"""New reports of a vessel between two judgements by the area model: scoring a window costs far
more than the model-free kinds (a comparison with the training tracks), and 20 reports (a few
minutes of a vessel under way) move its window too little to change the verdict much."""
MIN_REPORTS = 30
"""Fewest reports of a window judged: a shorter stretch says too little of where a vessel goes
to be compared with whole training tracks."""


@dataclass
class AreaJudge:
    """The area models, each with how it scores and its calibrated threshold, and how many
    reports each vessel has had since the models last judged it."""

    models: list[Detector]
    how: list[ScoreSettings] = field(init=False)
    cut: list[float] = field(init=False)
    since: dict[int, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.how = [replace(m.how, score=m.card.score) for m in self.models]
        pairs = zip(self.models, self.how, strict=True)
        self.cut = [m.threshold(h, DEFAULT_CONTAMINATION) for m, h in pairs]

    @classmethod
    def of(cls, models: Sequence[Detector]) -> AreaJudge | None:
        """The judge of the area models among `models` (None: there is none)."""
        area = [m for m in models if is_area_model(m)]
        return cls(area) if area else None

    def due(self, new: dict[int, int]) -> list[int]:
        """The vessels (MMSI: reports new in this chunk) whose `EVERY`-th report since their
        last judgement has come."""
        out = []
        for mmsi, n in new.items():
            self.since[mmsi] = self.since.get(mmsi, 0) + n
            if self.since[mmsi] >= EVERY:
                out.append(mmsi)
        return out

    def forget(self, mmsi: int) -> None:
        """A vessel the watch forgot: its count goes with it (memory stays bounded)."""
        self.since.pop(mmsi, None)

    def judge(
        self, windows: dict[int, VesselReports], who: dict[int, Identity]
    ) -> dict[int, list[dict]]:
        """The off-traffic events (rows of events.parquet) of each window judged; a window too
        short, or outside every model's region, is not judged (its count goes on)."""
        tracks = [as_track(v) for v in windows.values() if len(v) >= MIN_REPORTS]
        out: dict[int, list[dict]] = {}
        owner = self._owners(tracks)
        for k in range(len(self.models)):
            mine = [t for t, o in zip(tracks, owner, strict=True) if o == k]
            if mine:
                out |= self._events(k, mine, who)
        for mmsi in out:
            self.since[mmsi] = 0
        return out

    def _owners(self, tracks: list[Track]) -> list[int]:
        """Which model judges each track: the first whose region holds its start (-1: none)."""
        if not tracks:
            return []
        starts = np.array([t.positions[0] for t in tracks])
        inside = np.stack([m.card.region.contains(starts) for m in self.models], axis=1)
        return [int(np.argmax(row)) if row.any() else -1 for row in inside]

    def _events(
        self, k: int, tracks: list[Track], who: dict[int, Identity]
    ) -> dict[int, list[dict]]:
        """Model `k`'s verdict on `tracks`, scored in one call: each track's events."""
        model = self.models[k]
        got = model.score(tracks, self.how[k])
        scores = pd.DataFrame({"score": got.score, "threshold": self.cut[k], "model": model.name})
        identity = pd.DataFrame(
            [{"name": who[t.mmsi].name, "ship_type": who[t.mmsi].ship_type,
              "length_m": who[t.mmsi].length_m} for t in tracks],
            index=[t.mmsi for t in tracks],
        )  # fmt: skip
        events = off_traffic_events(tracks, scores, got.profiles, identity)
        out: dict[int, list[dict]] = {t.mmsi: [] for t in tracks}
        for row in events.to_dict("records"):
            out[int(row["mmsi"])].append(row | {"track_id": None})
        return out


def as_track(v: VesselReports) -> Track:
    """A vessel's cleaned window as the track a model judges (its reported speed and course
    with it)."""
    return Track(
        track_id=v.mmsi, mmsi=v.mmsi,
        start=pd.Timestamp(round(v.time_s[0] * 1e6), unit="us", tz="UTC"),
        positions=np.column_stack([v.lon, v.lat]), dts=np.diff(v.time_s) / 3600.0,
        cluster=AREA, sog=v.sog, cog=v.cog,
    )  # fmt: skip
