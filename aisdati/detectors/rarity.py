"""How rare a value is among the training tracks' own: the one scale on which scores of
different units (metres, multiples of a spread) can be joined
(`aisdati.detectors.od.stepod_scores`).

A track's rarity under a score is -log10 of the share of training tracks that score as high or
higher, counted as a conformal p-value counts it, (1 + #{training >= x}) / (n + 1): 1 is "as
rare as one training track in ten", 2 "one in a hundred". Beyond the highest training value the
share goes on falling as highest / x, so that tracks beyond every training track keep their
order instead of tying at -log10(1 / (n + 1)).
"""

from __future__ import annotations

import numpy as np


def rarity(values: np.ndarray, calibration: np.ndarray) -> np.ndarray:
    """[N] -log10 of each value's share among `calibration` (module docstring)."""
    cal = np.sort(np.asarray(calibration, np.float64))
    x = np.asarray(values, np.float64)
    n = len(cal)
    as_high = n - np.searchsorted(cal, x, side="left")
    share = (1.0 + as_high) / (n + 1.0)
    top = max(float(cal[-1]), np.finfo(np.float64).tiny) if n else np.inf
    beyond = top / np.maximum(x, top) / (n + 1.0)
    return -np.log10(np.where(x > top, beyond, share))
