"""The self-test's outputs: one row per (method, family), the files of a run (results.csv,
results.json, scores.csv, families.png, rollouts.png) and the panels of its rollout figure."""

from __future__ import annotations

import json
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from aisdati import __version__
from aisdati.outdir import atomic_write_bytes
from aisdati.selftest.figures import plot_best_rollouts, plot_families
from aisdati.selftest.protocol import FamilyResult, SelftestResult
from aisdati.selftest.settings import METHODS, settings_family


def _sd(values: list[float]) -> float:
    return float(np.std(values, ddof=1)) if len(values) > 1 else float("nan")


def result_rows(result: SelftestResult) -> list[dict]:
    """One row per (method, family): the paper's metric (per repeat, and its mean and standard
    deviation over repeats), robust statistics over all scores and the paper's number."""
    return [
        {
            "method": f.method,
            "family": f.family,
            "best": float(np.mean(f.repeat_best)),
            "best_sd": _sd(f.repeat_best),
            "best_per_repeat": f.repeat_best,
            "second_best": f.second_best,
            "second_best_sd": _sd(f.repeat_second),
            "median": f.summary.median,
            "iqm": f.summary.iqm,
            "iqm_ci_low": f.summary.iqm_low,
            "iqm_ci_high": f.summary.iqm_high,
            "paper_best": f.paper,
            "paper_second_best": f.paper_second,
            "n_scores": f.summary.n,
            "repeats": len(f.repeat_best),
            "mean_episodes": f.mean_episodes,
        }
        for f in result.families
    ]


def write_outputs(result: SelftestResult, out_dir: Path) -> list[Path]:
    """results.csv, results.json, scores.csv and the two figures, each written atomically."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = result_rows(result)
    scores = pd.DataFrame(
        [
            {
                "method": m.method,
                "family": m.family,
                "seed": m.seed,
                "reference": j,
                "repeat": m.repeat,
                "alpha": m.alphas[j],
                "score": m.scores[j],
                "episodes": m.episodes,
            }
            for f in result.families
            for m in f.members
            for j in range(len(m.scores))
        ]
    )
    s = result.settings
    doc = {
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "aisdati_version": __version__,
        "wall_seconds": result.wall_seconds,
        "settings": {
            **asdict(s),
            "config": s.config.to_dict(),
            "bc": s.bc.to_dict(),
            "bc_paper": s.bc_paper.to_dict(),
            "ddpg": s.ddpg.to_dict(),
        },
        "results": rows,
    }
    written = [out_dir / "results.csv", out_dir / "results.json", out_dir / "scores.csv"]
    flat = [
        {**r, "best_per_repeat": " ".join(f"{b:.6g}" for b in r["best_per_repeat"])} for r in rows
    ]
    atomic_write_bytes(written[0], pd.DataFrame(flat).to_csv(index=False).encode())
    atomic_write_bytes(written[1], json.dumps(doc, indent=2, default=float).encode())
    atomic_write_bytes(written[2], scores.to_csv(index=False).encode())
    fams = [settings_family(s, name) for name in dict.fromkeys(f.family for f in result.families)]
    plot_families(fams, out_dir / "families.png")
    plot_best_rollouts(rollout_panels(result), out_dir / "rollouts.png")
    return [*written, out_dir / "families.png", out_dir / "rollouts.png"]


def rollout_panels(result: SelftestResult) -> list[tuple]:
    """Per family, one panel of the paper's Fig. 2. With one method: its best rollout and the
    reference it was best on. With several: the reference on which the first method did best,
    and every method's best rollout on that same reference (over the seeds scored on it: all of
    them with shared references, the same seed with distinct ones), with its score there."""
    panels = []
    by_family: dict[str, list[FamilyResult]] = {}
    for f in result.families:
        by_family.setdefault(f.family, []).append(f)
    for name, entries in by_family.items():
        first = entries[0]
        if len(entries) == 1:
            label = METHODS.get(first.method, first.method)
            panels.append(
                (
                    name,
                    first.best_reference,
                    {label: first.best_rollout},
                    {label: first.summary.best},
                )
            )
            continue
        scores = np.stack([m.scores for m in first.members])
        k, j = np.unravel_index(np.nanargmin(scores), scores.shape)
        alpha = float(first.members[k].alphas[j])
        reference = settings_family(result.settings, name).reference(alpha)
        rollouts, values = {}, {}
        for f in entries:
            on_it = [
                (float(m.scores[i]), m.paths[i])
                for m in f.members
                for i in np.flatnonzero(m.alphas == alpha)
                if np.isfinite(m.scores[i])
            ]
            if not on_it:
                continue
            label = METHODS.get(f.method, f.method)
            values[label], rollouts[label] = min(on_it, key=lambda v: v[0])
        panels.append((name, reference, rollouts, values))
    return panels
