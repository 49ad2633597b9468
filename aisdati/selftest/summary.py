"""The paper's metric and robust statistics over a set of self-test scores (lower is better).

The paper reports the lowest score over seeds x references; because a best-of-100 hides
instability, the median and the interquartile mean (IQM, Agarwal et al. 2021) with a 95%
bootstrap interval are reported beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import trim_mean


@dataclass(frozen=True)
class Summary:
    """The paper's metric (`best`) and robust statistics over a set of scores."""

    best: float
    median: float
    iqm: float
    iqm_low: float
    iqm_high: float
    n: int


def interquartile_mean(values: np.ndarray) -> float:
    return float(trim_mean(values, 0.25))


def summarize(scores: np.ndarray, resamples: int = 2000, seed: int = 0) -> Summary:
    """Best, median and IQM with a percentile-bootstrap 95% interval of the IQM; non-finite
    scores are left out."""
    x = np.asarray(scores, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    rng = np.random.default_rng(seed)
    boots = [interquartile_mean(rng.choice(x, size=len(x))) for _ in range(resamples)]
    low, high = np.percentile(boots, [2.5, 97.5])
    return Summary(
        float(x.min()), float(np.median(x)), interquartile_mean(x), float(low), float(high), len(x)
    )
