"""The self-test's figures: the families (the paper's Fig. 1) and the best rollouts (Fig. 2)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from aisdati.plots import grid, save
from aisdati.selftest.families import Family


def plot_families(families: Sequence[Family], path: Path, members: int = 9) -> None:
    """Each family with its boundary members highlighted (the paper's Fig. 1)."""
    fig, axes = grid(len(families))
    for ax, fam in zip(axes, families, strict=False):
        for alpha in np.linspace(*fam.alpha_range, members):
            ref = fam.reference(alpha)
            ax.plot(ref[:, 0], ref[:, 1], color="0.75", lw=0.8)
        for alpha, color in zip(fam.boundary_alphas(), ("tab:blue", "tab:green"), strict=True):
            ref = fam.reference(alpha)
            ax.plot(ref[:, 0], ref[:, 1], color=color, lw=2, label=f"α = {alpha:.3g}")
            ax.plot(*ref[0], "o", color=color)
        ax.set_title(f"{fam.name}  (DTW diameter {fam.diameter:.3g})")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")
    fig.suptitle("Synthetic families: boundary members define the DTW diameter")
    save(fig, path)


def plot_best_rollouts(
    panels: Sequence[tuple[str, np.ndarray, dict[str, np.ndarray], dict[str, float]]], path: Path
) -> None:
    """Per family, the reference and each method's best rollout from its first point (Fig. 2).

    A panel is (title, reference [n, 2], {method: rollout [n, 2]}, {method: score})."""
    fig, axes = grid(len(panels))
    for ax, (title, ref, rollouts, scores) in zip(axes, panels, strict=False):
        ax.plot(ref[:, 0], ref[:, 1], color="black", lw=2.2, label="reference")
        ax.plot(*ref[0], "ko")
        for method, path_xy in rollouts.items():
            ax.plot(path_xy[:, 0], path_xy[:, 1], lw=1.4, label=f"{method} ({scores[method]:.3f})")
        ax.set_title(title)
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")
    fig.suptitle("Best rollout per family (normalised smoothed DTW in brackets)")
    save(fig, path)
