"""Clustering of tracks by direction (section 6 of the paper).

`up`: every COG within [-90, 90] deg (north-going, i.e. [0, 90] or [270, 360) once COG is
normalised); `down`: every COG within (90, 270) (south-going); `other`: anything else, the
tracks that turn between the two.
"""

from __future__ import annotations

import numpy as np


def is_up(cog_deg: np.ndarray) -> np.ndarray:
    """Per report: is the course within [-90, 90] deg (COG normalised into [0, 360))?"""
    return (cog_deg <= 90.0) | (cog_deg >= 270.0)


def cluster_tracks(track: np.ndarray, cog_deg: np.ndarray, n_tracks: int) -> np.ndarray:
    """Cluster name of each of `n_tracks` tracks, given each report's track index and COG."""
    n_points = np.bincount(track, minlength=n_tracks)
    n_up = np.bincount(track, weights=is_up(cog_deg), minlength=n_tracks)
    labels = np.full(n_tracks, "other", dtype=object)
    labels[n_up == n_points] = "up"
    labels[n_up == 0] = "down"
    return labels
