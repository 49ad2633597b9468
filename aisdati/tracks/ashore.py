"""Reports ashore: a physical check that every detector's score goes through.

A vessel cannot sail over land, so a track whose positions lie well inland is abnormal whatever
any model of the traffic says: a spoofed or corrupted position (the classic AIS jump), or a
report stream that is not a vessel's. DATI and the nearest-track baseline judge a track by how
far it strays from what they learnt, in metres; a stretch 300 m inland across a headland can be
no farther from the learnt lane than a normal track's wide turn, so neither sees it.

The rule (a departure from the paper, which scores position deviation alone; `--no-ashore`
scores the paper's way): a report is *ashore* when the coastline (`aisdati.coastline`) puts it
on land and `margin_m` inland, i.e. it and all `PROBES` points `margin_m` around it are on
land. The margin absorbs the coastline's resolution (~100-200 m between vertices), piers and
berths, and GPS error: a moored vessel reports a few tens of metres from its quay. A track
with at least `min_reports` reports ashore is flagged whatever its score, and ranks above every
track at sea (`ranked`), the ones with the larger share of reports ashore first.

Water the coastline misses: OpenStreetMap's land polygons end at the coastline. Lakes and
rivers above the tidal limit are water by `aisdati.inland_water` (Natural Earth 1:10m: the
Great Lakes, the Mississippi, the Columbia; `inland_water=False` judges by the coastline alone).
Narrower water still counts as land: tidal creeks, channels, marinas and basins the coastline
leaves out (NY Harbor's Newtown Creek, the Houston Ship Channel, Marina del Rey), and their
everyday traffic would be flagged. A model's card records where its training tracks reported
ashore (`seen`, `DataCard.ashore_points`, on a `SEEN_GRID_DEG` grid); a report within
`margin_m` of one of them is water the area's own traffic sails, not ashore. Cards from before
this record have none.

The calibrated thresholds stay the models' (the share of normal traffic a model flags); the
rule flags on its own and its false alarms are counted with the others (`aisdati evaluate`).

The rule needs the harbour-scale coastline (`roaring-landmask`); on the coarse Natural Earth
fallback, whose outline puts coastal water on land, it is off (`available`), with a warning.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from aisdati.execution import InProcess, Runner
from aisdati.geo import haversine_m, moved_m

PROBES = 8
"""Points around each report (evenly spaced bearings) that must be on land too."""
SEEN_GRID_DEG = 0.001
"""`seen` points are rounded to this grid (~110 m of latitude) and kept once each, so that a
card holds a few of them per creek, not one per report."""
CHUNK = 4096
"""Reports compared with every `seen` point at once."""
LIFT_M = 1.0e7
"""What `ranked` adds to the score of a track ashore: 10,000 km, more than any score of a
track at sea in an area can reach, so that the ashore tracks rank first."""


@dataclass(frozen=True)
class AshoreCheck:
    """Parameters of the rule (module docstring); fixed, not tuned on any data set: the margin
    is twice the coastline's coarsest vertex spacing, and one stray report is not enough."""

    margin_m: float = 400.0
    min_reports: int = 2
    inland_water: bool = True
    """Lakes and rivers are water (`aisdati.inland_water`); False: the coastline alone."""

    @staticmethod
    def available() -> bool:
        """Whether the coastline is fine enough for the rule (OpenStreetMap's, not the coarse
        fallback)."""
        from aisdati.coastline import OSM, source

        return source() == OSM

    def reports(self, positions: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
        """[n] bool: which reports ([n, 2] lon/lat degrees) are ashore; none within `margin_m`
        of a `seen` point ([m, 2]: where training traffic reported ashore)."""
        from aisdati.coastline import on_land

        p = np.asarray(positions, np.float64).reshape(-1, 2)
        out = on_land(p[:, 0], p[:, 1], self.inland_water)
        idx = np.flatnonzero(out)
        if idx.size == 0:
            return out
        bearing = np.arange(PROBES)[None, :] * 360.0 / PROBES
        lon, lat = moved_m(p[idx, 0, None], p[idx, 1, None], bearing, self.margin_m)
        out[idx] = on_land(lon, lat, self.inland_water).all(axis=1)
        if seen is not None and len(seen):
            idx = np.flatnonzero(out)
            out[idx] = ~self.near(p[idx], np.asarray(seen, np.float64).reshape(-1, 2))
        return out

    def near(self, points: np.ndarray, seen: np.ndarray) -> np.ndarray:
        """[n] bool: which points lie within `margin_m` of a `seen` point."""
        out = np.zeros(len(points), dtype=bool)
        for lo in range(0, len(points), CHUNK):
            q = points[lo : lo + CHUNK]
            d = haversine_m(q[:, None, 0], q[:, None, 1], seen[None, :, 0], seen[None, :, 1])
            out[lo : lo + CHUNK] = (d <= self.margin_m).any(axis=1)
        return out

    def counts(self, tracks: Sequence[np.ndarray], seen: np.ndarray | None = None) -> np.ndarray:
        """[N] int: reports ashore per track (positions of each), `seen` as in `reports`; all
        tracks' reports in one pass (2-3x faster than track by track: ~2 M reports/s)."""
        sizes = np.array([len(p) for p in tracks], dtype=np.int64)
        if not sizes.size:
            return sizes
        ashore = self.reports(np.concatenate([np.reshape(p, (-1, 2)) for p in tracks]), seen)
        total = np.concatenate([[0], np.cumsum(ashore, dtype=np.int64)])
        ends = np.cumsum(sizes)
        return total[ends] - total[ends - sizes]

    def seen(self, tracks: Sequence[np.ndarray]) -> list[list[float]]:
        """Where these (training) tracks report ashore, on the `SEEN_GRID_DEG` grid, once each:
        what a card records as water its traffic sails (module docstring); none on the coarse
        fallback coastline, whose outline would put the whole coastal traffic here."""
        if not self.available():
            return []
        points = np.concatenate([np.empty((0, 2)), *[np.reshape(p, (-1, 2)) for p in tracks]])
        points = points[self.reports(points)]
        grid = np.unique(np.round(points / SEEN_GRID_DEG).astype(np.int64), axis=0)
        return [[round(float(x), 6), round(float(y), 6)] for x, y in grid * SEEN_GRID_DEG]

    def flags(self, counts: np.ndarray) -> np.ndarray:
        """[N] bool: the tracks the rule flags."""
        return np.asarray(counts) >= self.min_reports

    def ranked(self, score_m: np.ndarray, counts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
        """Scores to rank tracks by: a flagged track's score lifted by `LIFT_M` x (1 + its share
        of reports ashore), the others' as they are."""
        share = np.asarray(counts, np.float64) / np.maximum(np.asarray(lengths, np.float64), 1.0)
        lift = np.where(self.flags(counts), LIFT_M * (1.0 + share), 0.0)
        return np.asarray(score_m, np.float64) + lift


ASHORE_TRACKS = 1024
"""Tracks per task of the ashore check (`ashore_counts`): ~2 M reports/s, so a task of 1,024
tracks of a few hundred reports takes a fraction of a second, well above a task's overhead."""


def ashore_counts(
    seen: Sequence[np.ndarray],
    tracks: Sequence[np.ndarray],
    owner: Sequence[int],
    runner: Runner | None = None,
) -> np.ndarray:
    """Each track's (positions [n, 2]) reports ashore, excusing the water its judging model's
    training traffic sailed (`seen[owner[i]]`, `aisdati.ais.card.DataCard.ashore`); in chunks
    of `ASHORE_TRACKS`, as tasks of `runner` (default: here)."""
    out = np.zeros(len(tracks), np.int64)
    if not AshoreCheck.available():
        warnings.warn(
            "the ashore rule is off: only the coarse fallback coastline is installed (pip "
            "install roaring-landmask for the harbour-scale one)",
            RuntimeWarning,
            stacklevel=2,
        )
        return out
    owner_of = np.asarray(owner, np.int64)
    rows = []
    jobs = []
    for m in np.unique(owner_of):
        mine = np.flatnonzero(owner_of == m)
        for lo in range(0, len(mine), ASHORE_TRACKS):
            rows.append(mine[lo : lo + ASHORE_TRACKS])
            jobs.append((seen[m], [tracks[i] for i in rows[-1]]))
    for idx, counts in zip(rows, (runner or InProcess()).map(ashore_job, jobs), strict=True):
        out[idx] = counts
    return out


def ashore_job(job: tuple[np.ndarray, list[np.ndarray]]) -> np.ndarray:
    """One task of `ashore_counts`: (seen water, positions of each track) -> counts."""
    seen, positions = job
    return AshoreCheck().counts(positions, seen)
