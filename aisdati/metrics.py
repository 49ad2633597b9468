"""Ranking and flagging metrics of a detector against known labels (1 = anomaly): the only
ROC AUC, precision, recall and F1 of aisdati (`aisdati evaluate` and `aisdati detect --labels`),
and the bootstrap interval every measurement reports."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.stats import rankdata
from sklearn.metrics import average_precision_score


def roc_auc(y: np.ndarray, score: np.ndarray) -> float | None:
    """Area under the ROC curve of `score` for labels `y`; None when only one class is present.
    By the Mann-Whitney U statistic (ties count half), which is the AUC exactly: a bootstrap
    interval computes it a thousand times per row, where scikit-learn's input checks cost 200
    times the arithmetic."""
    y = np.asarray(y, bool)
    positives = int(y.sum())
    negatives = len(y) - positives
    if positives == 0 or negatives == 0:
        return None
    ranks = rankdata(np.asarray(score, np.float64))
    return float((ranks[y].sum() - positives * (positives + 1) / 2) / (positives * negatives))


def ranking(y: np.ndarray, score: np.ndarray) -> dict[str, float | None]:
    """ROC AUC and average precision; None when only one class is present."""
    auc = roc_auc(y, score)
    if auc is None:
        return {"roc_auc": None, "average_precision": None}
    return {
        "roc_auc": auc,
        "average_precision": float(average_precision_score(np.asarray(y, int), score)),
    }


def flagging(y: np.ndarray, flagged: np.ndarray) -> dict[str, Any]:
    """Precision, recall and F1 of the anomaly class for a set of flags, and the false-alarm
    rate: the share of the normal tracks flagged (what a calibrated threshold promises)."""
    y, p = np.asarray(y, bool), np.asarray(flagged, bool)
    tp = int((y & p).sum())
    precision = tp / max(int(p.sum()), 1)
    recall = tp / max(int(y.sum()), 1)
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    false_alarms = int((~y & p).sum()) / max(int((~y).sum()), 1)
    return {
        "flagged": int(p.sum()),
        "precision": precision,
        "recall": recall,
        "f1": f1,
        "false_alarm_rate": false_alarms,
    }


def weighted_f1(y: np.ndarray, flagged: np.ndarray) -> float:
    """The paper's F1: the F1 of each class (normal, anomaly) weighted by its support."""
    y, p = np.asarray(y, bool), np.asarray(flagged, bool)
    support = np.array([(~y).sum(), y.sum()], dtype=float)
    f1s = np.array([flagging(~y, ~p)["f1"], flagging(y, p)["f1"]])
    return float((support * f1s).sum() / support.sum())


def interval(
    stat: Callable[[np.ndarray], float | None], n: int, resamples: int = 1000, seed: int = 0
) -> tuple[float | None, float | None]:
    """The 95 % percentile-bootstrap interval of `stat` (of the indices of a resample of `n`
    items); None where no resample gives a value."""
    rng = np.random.default_rng(seed)
    got = [stat(rng.integers(0, n, n)) for _ in range(resamples)] if n else []
    values = np.array([v for v in got if v is not None and np.isfinite(v)])
    if not len(values):
        return None, None
    low, high = np.percentile(values, [2.5, 97.5])
    return float(low), float(high)
