"""Segmentation (`aisdati.preprocess.segment`) on hand-built tracks with known answers."""

from __future__ import annotations

import numpy as np

from aisdati.preprocess.report import CODE
from aisdati.preprocess.segment import segment

H = 3_600_000_000  # one hour in microseconds


def test_split_at_gaps_longer_than_stop_gap_and_drop_short_segments():
    mmsi = np.array([1, 1, 1, 1, 1, 2, 2, 2])
    minutes = np.array([0, 10, 20, 90, 100, 0, 10, 70])
    track, codes, n_short = segment(mmsi, minutes * 60_000_000, 3600, 2)
    # vessel 1: [0,10,20] | gap 70 min | [90,100]; vessel 2: [0,10,70] (gap of exactly 60 min kept)
    assert list(track) == [0, 0, 0, 1, 1, 2, 2, 2]
    assert n_short == 0 and not codes.any()
    track, codes, n_short = segment(mmsi, minutes * 60_000_000, 3600, 3)
    assert list(track) == [0, 0, 0, -1, -1, 1, 1, 1]
    assert n_short == 1 and list(codes[3:5]) == [CODE["short_segment"]] * 2
