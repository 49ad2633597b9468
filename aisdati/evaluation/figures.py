"""The figures of `aisdati evaluate`: ROC and precision-recall curves, and the top-scored
injected anomaly of each kind."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import MaxNLocator

from aisdati.plots import draw_land, grid, save, set_map_limits


def plot_roc_pr(curves: dict[str, tuple[np.ndarray, np.ndarray]], path: Path) -> None:
    """ROC and precision-recall curves, one line per detector and score (labels 1 = injected)."""
    from sklearn.metrics import precision_recall_curve, roc_curve

    fig, (roc, pr) = plt.subplots(1, 2, figsize=(11, 4.6))
    for name, (y, score) in curves.items():
        if y.min() == y.max():
            continue
        fpr, tpr, _ = roc_curve(y, score)
        prec, rec, _ = precision_recall_curve(y, score)
        roc.plot(fpr, tpr, lw=1.5, label=name)
        pr.plot(rec, prec, lw=1.5, label=name)
    roc.plot([0, 1], [0, 1], color="0.6", ls=":", lw=1)
    roc.set(xlabel="false positive rate", ylabel="true positive rate", title="ROC")
    pr.set(xlabel="recall", ylabel="precision", title="precision-recall", ylim=(0, 1.02))
    roc.legend(fontsize=8, loc="lower right")
    fig.suptitle("Detection of injected anomalies (held-out tracks)")
    save(fig, path)


def plot_injected_examples(
    panels: Sequence[tuple[str, np.ndarray, np.ndarray, tuple[int, int], np.ndarray | None]],
    path: Path,
) -> None:
    """Per anomaly kind, the top-scored altered track over the offline coastline: (title, source
    track, altered track, altered stretch [start, end), what the detector compared it with or
    None)."""
    fig, axes = grid(len(panels))
    for ax, (title, source, track, (i, j), evidence) in zip(axes, panels, strict=False):
        ax.plot(source[:, 0], source[:, 1], color="0.7", lw=2.5, label="original track")
        if evidence is not None:
            ax.plot(evidence[:, 0], evidence[:, 1], color="tab:blue", lw=1, label="compared with")
        ax.plot(track[:, 0], track[:, 1], color="black", lw=1, label="altered track")
        ax.plot(track[i:j, 0], track[i:j, 1], color="tab:red", lw=2, label="altered stretch")
        ax.plot(*track[0], "o", color="black", ms=4)
        shown = np.concatenate([source, track, *([] if evidence is None else [evidence])])
        lo, hi = np.nanmin(shown, axis=0), np.nanmax(shown, axis=0)
        pad = np.maximum((hi - lo) * 0.08, 0.005)
        set_map_limits(ax, lo - pad, hi + pad)
        draw_land(ax)
        ax.set_xlabel("")
        ax.set_ylabel("")
        ax.set_title(title, fontsize=9)
        ax.tick_params(labelsize=7)
        # a narrow panel of a long coast took a tick every 0.05 degrees, their labels overlapping
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.yaxis.set_major_locator(MaxNLocator(5))
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle("Top-scored injected anomaly of each kind")
    save(fig, path)
