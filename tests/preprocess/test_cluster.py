"""Clustering by direction (`aisdati.preprocess.cluster`) on hand-built tracks with known
answers."""

from __future__ import annotations

import numpy as np

from aisdati.preprocess.cluster import cluster_tracks


def test_clusters_up_down_other():
    track = np.array([0, 0, 0, 1, 1, 2, 2, 3, 3])
    cog = np.array([0, 90, 270, 90.5, 269.9, 10, 180, 359.9, 45])
    assert list(cluster_tracks(track, cog, 4)) == ["up", "down", "other", "up"]


def test_boundaries_follow_the_paper():
    # up: COG in [-90, 90] -> 90 and 270 (= -90) are up; down: (90, 270) open.
    assert list(cluster_tracks(np.array([0, 1]), np.array([90.0, 270.0]), 2)) == ["up", "up"]
