"""Segmentation: split each vessel's reports at stops and keep the long segments.

With reports at or below the SOG threshold filtered out, a stop shows up as a gap in time, so a
vessel's history is cut wherever two consecutive kept reports are more than `stop_gap_s` apart
(section 6 of the paper: stop points of more than an hour). Segments with fewer than
`min_points` reports are rejected (the paper keeps at least 900).
"""

from __future__ import annotations

import numpy as np

from aisdati.preprocess.report import CODE


def segment(
    mmsi: np.ndarray, time_us: np.ndarray, stop_gap_s: float, min_points: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """For reports sorted by (MMSI, time): the track index of each report (-1 when its segment is
    too short, tracks numbered 0.. in order), a rejection code per report, and the number of
    segments dropped as too short."""
    n = len(mmsi)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.uint8), 0
    gap_us = int(stop_gap_s * 1e6)
    starts = np.r_[True, (mmsi[1:] != mmsi[:-1]) | (np.diff(time_us) > gap_us)]
    seg = np.cumsum(starts) - 1
    sizes = np.bincount(seg)
    long_enough = sizes >= min_points
    track_of_seg = np.where(long_enough, np.cumsum(long_enough) - 1, -1)
    track = track_of_seg[seg]
    codes = np.where(track < 0, CODE["short_segment"], 0).astype(np.uint8)
    return track, codes, int((~long_enough).sum())
