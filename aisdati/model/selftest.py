"""`aisdati selftest`: the paper's synthetic protocol (Table 1, DATI column).

Every (family, seed) pair is one member of a batched DATI ensemble; the members are shared out
over `workers` processes (one per core), trained with early stopping, then each member's best
forward actor is rolled out from the first point of the same unseen references of its family.
The paper's metric is the lowest normalised smoothed DTW over seeds x references.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from queue import Empty

import numpy as np
import pandas as pd
import torch

from aisdati import __version__
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import FamilySource, Reference, TrajectoryImitationEnv
from aisdati.model.evaluate import Summary, rollout, summarize
from aisdati.model.families import PAPER_DATI, Family, get_family
from aisdati.plots import plot_best_rollouts, plot_families

PAPER_FAMILIES = ("fixedstart", "ushaped", "circles", "ribbons")


@dataclass(frozen=True)
class SelftestSettings:
    """The protocol; defaults are the paper's (10 seeds, 10 unseen references, τ = 200)."""

    families: tuple[str, ...] = PAPER_FAMILIES
    seeds: int = 10
    references: int = 10
    steps: int | None = None
    """Steps per episode τ; None keeps each family's own (200 for the paper's)."""
    workers: int = 1
    eval_seed: int = 2024
    config: DATIConfig = field(default_factory=DATIConfig)


QUICK = {"seeds": 2, "references": 3, "steps": 40, "episodes": 3}
"""`--quick`: a smoke check of a fresh install in well under two minutes on two cores."""


@dataclass
class MemberResult:
    family: str
    seed: int
    episodes: int
    scores: np.ndarray
    alphas: np.ndarray
    paths: list[np.ndarray]


@dataclass
class FamilyResult:
    family: str
    summary: Summary
    paper: float | None
    mean_episodes: float
    best_reference: np.ndarray
    best_rollout: np.ndarray
    members: list[MemberResult]


@dataclass
class SelftestResult:
    settings: SelftestSettings
    families: list[FamilyResult]
    wall_seconds: float


def family_for(name: str, steps: int | None) -> Family:
    fam = get_family(name)
    return fam if steps is None or steps == fam.steps else replace(fam, steps=steps)


def evaluation_references(fam: Family, count: int, seed: int) -> list[Reference]:
    """The unseen test references of a family: α drawn from an evaluation-only stream."""
    rng = np.random.default_rng([seed, sum(map(ord, fam.name))])
    source = FamilySource(fam)
    return [source.reference(fam.sample_alpha(rng)) for _ in range(count)]


def _run_members(
    members: list[tuple[int, str, int]],
    settings: SelftestSettings,
    report: Callable[[int, int, bool], None],
) -> list[MemberResult]:
    """Train and evaluate a group of (index, family, seed) members as one ensemble."""
    torch.set_num_threads(1)
    fams = {name: family_for(name, settings.steps) for _, name, _ in members}
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in members]
    trainer = DATITrainer(envs, [seed for _, _, seed in members], settings.config)

    def on_step(logs: list) -> None:
        for log in logs:
            report(members[log.member][0], log.episode, log.stopped)

    nets = trainer.train(on_step)
    refs = {
        n: evaluation_references(f, settings.references, settings.eval_seed)
        for n, f in fams.items()
    }
    grid = [
        [TrajectoryImitationEnv(FamilySource(fams[name])) for _ in range(settings.references)]
        for _, name, _ in members
    ]
    out = rollout(
        nets, grid, [refs[name] for _, name, _ in members], settings.config, seed=settings.eval_seed
    )
    return [
        MemberResult(
            name,
            seed,
            trainer.episode[k],
            out.scores[k],
            np.array([r.label["alpha"] for r in refs[name]]),
            out.paths[k],
        )
        for k, (_, name, seed) in enumerate(members)
    ]


def _worker(members, settings, queue) -> None:  # pragma: no cover - runs in a child process
    try:
        results = _run_members(
            members, settings, lambda i, ep, stop: queue.put(("ep", i, ep, stop))
        )
        queue.put(("done", results))
    except BaseException as exc:
        queue.put(("error", f"{type(exc).__name__}: {exc}"))


def run_selftest(
    settings: SelftestSettings, report: Callable[[int, int, bool], None] | None = None
) -> SelftestResult:
    """Run the protocol; `report(member_index, episode, stopped)` follows training progress."""
    report = report or (lambda i, ep, stop: None)
    members = [
        (i, name, seed)
        for i, (name, seed) in enumerate(
            (name, seed) for name in settings.families for seed in range(settings.seeds)
        )
    ]
    for name in settings.families:
        get_family(name)  # unknown names fail before any work starts
    start = time.perf_counter()
    workers = max(1, min(settings.workers, len(members)))
    if workers == 1:
        results = _run_members(members, settings, report)
    else:
        results = _run_in_processes(members, settings, workers, report)
    wall = time.perf_counter() - start
    return SelftestResult(settings, _aggregate(settings, results), wall)


def _run_in_processes(members, settings, workers, report) -> list[MemberResult]:
    ctx = mp.get_context("fork")  # children inherit user-registered families
    queue = ctx.Queue()
    groups = [members[w::workers] for w in range(workers)]
    procs = [ctx.Process(target=_worker, args=(g, settings, queue), daemon=True) for g in groups]
    for p in procs:
        p.start()
    results: list[MemberResult] = []
    finished = 0
    try:
        while finished < workers:
            try:
                msg = queue.get(timeout=1.0)
            except Empty:
                if any(p.exitcode not in (None, 0) for p in procs):
                    raise RuntimeError("a selftest worker died") from None
                continue
            if msg[0] == "ep":
                report(*msg[1:])
            elif msg[0] == "done":
                results.extend(msg[1])
                finished += 1
            else:
                raise RuntimeError(f"selftest worker failed: {msg[1]}")
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
            p.join()
    return results


def _aggregate(settings: SelftestSettings, results: list[MemberResult]) -> list[FamilyResult]:
    out = []
    for name in settings.families:
        fam = family_for(name, settings.steps)
        mine = sorted((r for r in results if r.family == name), key=lambda r: r.seed)
        scores = np.stack([r.scores for r in mine])
        k, j = np.unravel_index(np.nanargmin(scores), scores.shape)
        best_ref = fam.reference(float(mine[k].alphas[j]))
        out.append(
            FamilyResult(
                name,
                summarize(scores),
                PAPER_DATI.get(name),
                float(np.mean([r.episodes for r in mine])),
                best_ref,
                mine[k].paths[j],
                mine,
            )
        )
    return out


def result_rows(result: SelftestResult) -> list[dict]:
    """One row per family: the paper's metric, robust statistics and the paper's number."""
    return [
        {
            "family": f.family,
            "best": f.summary.best,
            "median": f.summary.median,
            "iqm": f.summary.iqm,
            "iqm_ci_low": f.summary.iqm_low,
            "iqm_ci_high": f.summary.iqm_high,
            "paper_best": f.paper,
            "n_scores": f.summary.n,
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
                "family": m.family,
                "seed": m.seed,
                "reference": j,
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
        "settings": {**asdict(s), "config": s.config.to_dict()},
        "results": rows,
    }
    written = [out_dir / "results.csv", out_dir / "results.json", out_dir / "scores.csv"]
    atomic_write_bytes(written[0], pd.DataFrame(rows).to_csv(index=False).encode())
    atomic_write_bytes(written[1], json.dumps(doc, indent=2, default=float).encode())
    atomic_write_bytes(written[2], scores.to_csv(index=False).encode())
    fams = [family_for(f.family, s.steps) for f in result.families]
    plot_families(fams, out_dir / "families.png")
    panels = [
        (f.family, f.best_reference, {"DATI": f.best_rollout}, {"DATI": f.summary.best})
        for f in result.families
    ]
    plot_best_rollouts(panels, out_dir / "rollouts.png")
    return [*written, out_dir / "families.png", out_dir / "rollouts.png"]
