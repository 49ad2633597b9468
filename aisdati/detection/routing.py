"""Which model judges which track (section 6.2 of the paper, with the areas and the coverage of
aisdati): the origin-destination geometry of tracks and of a model's training tracks, read from
its card, and the assignment of every test track to a model or to a reason it is not judged.

A route or cluster model judges the tracks bound as its training tracks are (start and end
within `near_km`; by start alone for cards that do not record where their tracks end, the
paper's rule); an area model (`--cluster all`) judges any track of its region no route model
reaches; a model's own training tracks are no candidates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from aisdati.ais.card import ModelCard, training_mask
from aisdati.detectors import Detector
from aisdati.errors import UserError
from aisdati.geo import haversine_m
from aisdati.tracks.schema import AREA
from aisdati.tracks.store import Track

CHUNK = 512
"""Queries per block of `od_distances`: [512, M] distance matrices."""
NOT_JUDGED_FAR = "no model covers its start and end (none within --near-km, no area model)"
NOT_JUDGED_OUTSIDE = "it starts outside every model's region (models of another area)"


def od_pairs_m(
    starts: np.ndarray, ends: np.ndarray, train_starts: np.ndarray, train_ends: np.ndarray
) -> np.ndarray:
    """[N, M] metres: the distance of each (start, end) pair to each training pair, the larger
    of the two starts' and the two ends' great-circle distances."""
    starts, ends = np.asarray(starts, np.float64), np.asarray(ends, np.float64)
    d_start = haversine_m(
        starts[:, None, 0], starts[:, None, 1], train_starts[:, 0], train_starts[:, 1]
    )
    d_end = haversine_m(ends[:, None, 0], ends[:, None, 1], train_ends[:, 0], train_ends[:, 1])
    return np.maximum(d_start, d_end)


def track_ends(positions: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """[N, 2] first and [N, 2] last positions of tracks: taken once for every model that asks
    how far each track is from its training tracks (a list pass per model was 0.7 s at a
    quarter of a million tracks)."""
    starts = np.array([p[0] for p in positions], np.float64).reshape(-1, 2)
    ends = np.array([p[-1] for p in positions], np.float64).reshape(-1, 2)
    return starts, ends


def od_distances(
    starts: np.ndarray,
    ends: np.ndarray,
    train_starts: np.ndarray,
    train_ends: np.ndarray,
    leave_one_out: bool = False,
) -> np.ndarray:
    """[N] metres: each (start, end) pair's distance to the nearest training pair
    (`od_pairs_m`), in chunks of `CHUNK` queries. `leave_one_out`: the queries are the training
    tracks themselves, each compared with the others (calibration)."""
    out = np.empty(len(starts))
    for lo in range(0, len(starts), CHUNK):
        pair = od_pairs_m(starts[lo : lo + CHUNK], ends[lo : lo + CHUNK], train_starts, train_ends)
        if leave_one_out:
            rows = np.arange(len(pair))
            pair[rows, lo + rows] = np.inf
        out[lo : lo + CHUNK] = pair.min(axis=1) if pair.shape[1] else np.inf
    return out


@dataclass(frozen=True)
class Coverage:
    """What became of every track of the chosen test set: a training track of the models that
    could judge it (not a candidate: a model does not judge what it learnt from), judged (by
    which model), or not judged and why (with the ids), so that no track leaves it
    uncounted."""

    candidates: int
    """The tracks asked to be judged, the models' own training tracks left out."""
    judged_by: dict[str, int]
    not_judged: dict[str, list[int]]
    training: list[int] = field(default_factory=list)
    """Ids of the tracks left out as training tracks of every model in reach."""

    @property
    def judged(self) -> int:
        return sum(self.judged_by.values())

    def as_dict(self) -> dict[str, Any]:
        return {
            "candidates": self.candidates,
            "judged": self.judged,
            "judged_by": self.judged_by,
            "not_judged": {k: len(v) for k, v in self.not_judged.items()},
            "not_judged_tracks": self.not_judged,
            "training_tracks": len(self.training),
            "training_track_ids": self.training,
        }


def is_area_model(model: Detector) -> bool:
    """A model of a whole area (`--cluster all`): it judges any track of its region."""
    return model.card.cluster == AREA


def reach_km(card: ModelCard, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """How far (km) each track (its first and last positions) is from being bound the way the
    model's training tracks are: the origin-destination distance (`od_distances`), or for a
    card from before end points were recorded the distance between starts (the paper's rule
    for which model judges a track)."""
    data = card.data
    if data.ends is None:
        return od_distances(starts, starts, data.starts, data.starts) / 1000.0
    return od_distances(starts, ends, data.starts, data.ends) / 1000.0


def route_test_tracks(
    models: Sequence[Detector], table: pd.DataFrame, tracks: list[Track], near_km: float
) -> tuple[np.ndarray, Coverage]:
    """For each track (rows of `table`, loaded as `tracks`), the index of the model that judges
    it (-1: none) and the `Coverage`. A model judges only tracks that start inside its region
    and never its own training tracks, whether the tracks were named or chosen by cluster. A
    route or cluster model judges the tracks bound as its own are (`reach_km` within
    `near_km`), the nearest in reach; a track no such model reaches goes to an area model of its
    region; with none, it is listed as not judged, with the reason."""
    starts, ends = track_ends([t.positions for t in tracks])
    reach = np.stack([reach_km(m.card, starts, ends) for m in models], axis=1)
    inside = np.stack([m.card.region.contains(starts) for m in models], axis=1)
    reach[~inside] = np.inf
    trained = np.stack([training_mask(m.card, table) for m in models], axis=1)
    reach[trained] = np.inf  # by vessel and time where the card can tell
    area = np.array([is_area_model(m) for m in models])
    local = np.where(area[None, :] | (reach > near_km), np.inf, reach)
    spare = np.where(area[None, :], reach, np.inf)
    owner = np.where(np.isfinite(local).any(axis=1), local.argmin(axis=1), -1)
    fallback = np.where(np.isfinite(spare).any(axis=1), spare.argmin(axis=1), -1)
    owner = np.where(owner < 0, fallback, owner)
    return owner, coverage_of(models, table, owner, inside, trained)


def coverage_of(
    models: Sequence[Detector],
    table: pd.DataFrame,
    owner: np.ndarray,
    inside: np.ndarray,
    trained: np.ndarray,
) -> Coverage:
    """What `route_test_tracks` made of each track: judged by which model, a training track of
    every model whose region holds it (no candidate), or not judged and why."""
    ids = table["track_id"].to_numpy()
    names = [m.name for m in models]
    judged = pd.Series([names[o] for o in owner if o >= 0], dtype=object).value_counts()
    left = owner < 0
    outside = left & ~inside.any(axis=1)
    training = left & ~outside & trained.any(axis=1)
    far = left & ~outside & ~training
    reasons = ((NOT_JUDGED_OUTSIDE, outside), (NOT_JUDGED_FAR, far))
    return Coverage(
        candidates=len(ids) - int(training.sum()),
        judged_by={str(k): int(v) for k, v in judged.sort_index().items()},
        not_judged={r: [int(i) for i in ids[mask]] for r, mask in reasons if mask.any()},
        training=[int(i) for i in ids[training]],
    )


def check_region(models: Sequence[Detector], tracks: Sequence[Track]) -> None:
    """Refuse models of another region, in one line."""
    starts = np.array([t.positions[0] for t in tracks])
    inside = np.zeros(len(tracks), dtype=bool)
    for model in models:
        inside |= model.card.region.contains(starts)
    if not inside.any():
        lo, hi = models[0].card.region.bounds
        raise UserError(
            f"no test track starts inside the model's region (lon {lo[0]:.2f}..{hi[0]:.2f}, "
            f"lat {lo[1]:.2f}..{hi[1]:.2f}): is the model from another region?"
        )
