"""How unusual a track's (origin, destination) pair is among the training tracks.

A goal-conditioned model (`LaneConfig.goal`) generates, from a track's start, tracks bound for
that track's own end: it judges *how* a track sails to where it goes, not *whether* anybody goes
there. A track that starts and ends where no training track does must still stand out, so the
`area` score adds the origin-destination (OD) distance: for each track, over the training tracks,
the smallest of max(distance between the starts, distance between the ends), in metres. The
training tracks' own OD distances (each against the others) calibrate it; a track's OD counts
only beyond `OD_QUANTILE` of them (`od_excess`), so the OD spread of ordinary traffic adds
nothing to the lane score and a pair rarer than almost all the training tracks' adds its excess
in metres (`area = lane + od_excess`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from aisdati.detectors.rarity import rarity
from aisdati.geo import haversine_m

OD_QUANTILE = 0.95
"""A track's OD distance adds to its score beyond this quantile of the training tracks' own: a
pair as usual as 95 % of the training tracks' costs nothing. Fixed, not tuned: it states
"rarer than nearly all of what was seen" without reference to any data set."""
CHUNK = 512


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


def od_excess(od_m: np.ndarray, calibration_od_m: np.ndarray) -> np.ndarray:
    """The part of each OD distance beyond `OD_QUANTILE` of the training tracks' own."""
    free = float(np.quantile(np.asarray(calibration_od_m, np.float64), OD_QUANTILE))
    return np.maximum(np.asarray(od_m, np.float64) - free, 0.0)


def area_scores(lane_m: np.ndarray, od_m: np.ndarray, calibration_od_m: np.ndarray) -> np.ndarray:
    """The `area` score: the lane score plus the OD excess (module docstring)."""
    return np.asarray(lane_m, np.float64) + od_excess(od_m, calibration_od_m)


def stepod_scores(
    stepspread: np.ndarray,
    od_m: np.ndarray,
    calibration_stepspread: np.ndarray,
    calibration_od_m: np.ndarray,
) -> np.ndarray:
    """The `stepod` score: the larger of a track's `stepspread` rarity and its OD rarity among
    the training tracks' own (`aisdati.detectors.rarity`), the OD term counting only beyond
    `OD_QUANTILE` of them, as in `area`. `stepspread` judges how a track moves, not where it
    goes: the middle third of a training track moves as its whole track does. The two are in
    different units (multiples of the draws' spread, metres), so they are joined by how rare
    each is, and a track is as abnormal as its rarer term."""
    beyond = od_excess(od_m, calibration_od_m) > 0.0
    od_rarity = np.where(beyond, rarity(od_m, calibration_od_m), 0.0)
    return np.maximum(rarity(stepspread, calibration_stepspread), od_rarity)
