"""Synthetic tracks for the geometry and DTW kernels' checks against brute force."""

from __future__ import annotations

import numpy as np


def random_tracks(seed: int, count: int) -> list[np.ndarray]:
    """Random walks near Kitimat, some standing still for a while (points with no course)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        steps = rng.normal(0, 0.01, (int(rng.integers(5, 120)), 2))
        steps[rng.random(len(steps)) < 0.1] = 0.0
        out.append(np.array([-129.0, 53.9]) + rng.normal(0, 0.05, 2) + np.cumsum(steps, 0))
    return out
