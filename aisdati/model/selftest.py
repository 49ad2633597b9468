"""`aisdati selftest`: the paper's synthetic protocol (Table 1 and the Table 2 ablation).

Every (method, family, seed) triple is one member. The members are shared out over `workers`
processes (one per core); inside a process the DATI members of one variant train as one batched
ensemble (with early stopping), the BC members as one ensemble, and the DDPG-TI members one SB3
model after another. Then each member's policy is rolled out from the first point of the same
unseen references of its family. The paper's metric is the lowest normalised smoothed DTW over
seeds x references (Table 2 adds the second lowest).

Methods: `dati`, `bc`, `ddpg-ti` (Table 1) and the ablated DATI variants
`dati-no-time-embedding`, `dati-no-reward-input` (Table 2, with `dati`: `ABLATION`).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from queue import Empty

import numpy as np
import pandas as pd
import torch

from aisdati import __version__
from aisdati.model.baselines import (
    BCConfig,
    BCTrainer,
    DDPGTIConfig,
    bc_act,
    ddpg_ti_act,
    train_ddpg_ti,
)
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import FamilySource, Reference, TrajectoryImitationEnv
from aisdati.model.evaluate import Summary, rollout, rollout_policy, summarize
from aisdati.model.families import PAPER_DATI, Family, get_family
from aisdati.options import parse_names
from aisdati.plots import plot_best_rollouts, plot_families

PAPER_FAMILIES = ("fixedstart", "ushaped", "circles", "ribbons")

METHODS = {
    "dati": "DATI",
    "bc": "BC",
    "ddpg-ti": "DDPG-TI",
    "dati-no-time-embedding": "DATI, no time embedding",
    "dati-no-reward-input": "DATI, no reward input",
}
"""Method names accepted by `--methods`, with their display labels."""

TABLE1 = ("dati", "bc", "ddpg-ti")
ABLATION = ("dati", "dati-no-time-embedding", "dati-no-reward-input")

PAPER_TABLE1 = {
    "dati": PAPER_DATI,
    "bc": {"fixedstart": 0.124, "ushaped": 0.365, "circles": 0.106, "ribbons": 0.113},
    "ddpg-ti": {"fixedstart": 0.489, "ushaped": 2.138, "circles": 0.972, "ribbons": 0.172},
}
"""Table 1 of the paper: best normalised smoothed DTW over 10 seeds x 10 references."""

PAPER_ABLATION = {
    "dati": (0.058, 0.074),
    "dati-no-time-embedding": (1.829, 1.976),
    "dati-no-reward-input": (0.305, 0.451),
}
"""Table 2 of the paper (Circles): top-1 and top-2 normalised smoothed DTW."""


def parse_methods(text: str | Sequence[str]) -> tuple[str, ...]:
    """'dati,bc' -> ('dati', 'bc'); an unknown name is a one-line `UserError`."""
    return parse_names(text, METHODS, "method")


def paper_numbers(method: str, family: str) -> tuple[float | None, float | None]:
    """The paper's (top-1, top-2) for a method and family, where it reports them."""
    top2 = PAPER_ABLATION.get(method) if family == "circles" else None
    top1 = PAPER_TABLE1.get(method, {}).get(family)
    if top1 is None and top2 is not None:
        top1 = top2[0]
    return top1, (top2[1] if top2 else None)


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
    methods: tuple[str, ...] = ("dati",)
    bc: BCConfig = field(default_factory=BCConfig)
    ddpg: DDPGTIConfig = field(default_factory=DDPGTIConfig)

    def dati_config(self, method: str) -> DATIConfig:
        """DATI's configuration for a DATI method name (the ablations switch one input off)."""
        if method == "dati-no-time-embedding":
            return self.config.with_network(time_embedding=False)
        if method == "dati-no-reward-input":
            return self.config.with_network(reward_input=False)
        return self.config


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
    method: str = "dati"


@dataclass
class FamilyResult:
    family: str
    summary: Summary
    paper: float | None
    mean_episodes: float
    best_reference: np.ndarray
    best_rollout: np.ndarray
    members: list[MemberResult]
    method: str = "dati"
    second_best: float = float("nan")
    paper_second: float | None = None


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


Member = tuple[int, str, str, int]
"""(index, method, family, seed)."""


def _run_members(
    members: list[Member],
    settings: SelftestSettings,
    report: Callable[[int, int, bool], None],
) -> list[MemberResult]:
    """Train and evaluate a group of members: one ensemble per DATI variant, one BC ensemble,
    one SB3 model per DDPG-TI member."""
    torch.set_num_threads(1)
    results: list[MemberResult] = []
    for method in dict.fromkeys(m for _, m, _, _ in members):
        group = [(i, name, seed) for i, m, name, seed in members if m == method]
        run = {"bc": _run_bc, "ddpg-ti": _run_ddpg_ti}.get(method, _run_dati)
        out = run(method, group, settings, report)
        for r in out:
            r.method = method
        results.extend(out)
    return results


def _grid(group, settings, fams):
    """The unseen references of each member's family and one evaluation env per reference."""
    refs = {
        n: evaluation_references(f, settings.references, settings.eval_seed)
        for n, f in fams.items()
    }
    grid = [
        [TrajectoryImitationEnv(FamilySource(fams[name])) for _ in range(settings.references)]
        for _, name, _ in group
    ]
    return refs, grid


def _results(group, refs, episodes, scores, paths) -> list[MemberResult]:
    return [
        MemberResult(
            name,
            seed,
            episodes[k],
            scores[k],
            np.array([r.label["alpha"] for r in refs[name]]),
            paths[k],
        )
        for k, (_, name, seed) in enumerate(group)
    ]


def _run_dati(method, group, settings, report) -> list[MemberResult]:
    config = settings.dati_config(method)
    fams = {name: family_for(name, settings.steps) for _, name, _ in group}
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in group]
    trainer = DATITrainer(envs, [seed for _, _, seed in group], config)

    def on_step(logs: list) -> None:
        for log in logs:
            report(group[log.member][0], log.episode, log.stopped)

    nets = trainer.train(on_step)
    refs, grid = _grid(group, settings, fams)
    out = rollout(nets, grid, [refs[name] for _, name, _ in group], config, seed=settings.eval_seed)
    return _results(group, refs, trainer.episode, out.scores, out.paths)


def _run_bc(method, group, settings, report) -> list[MemberResult]:
    cfg = settings.bc
    fams = {name: family_for(name, settings.steps) for _, name, _ in group}
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in group]
    trainer = BCTrainer(envs, [seed for _, _, seed in group], cfg)

    def on_episode(episode: int) -> None:
        for i, _, _ in group:
            report(i, episode, episode >= cfg.episodes)

    policy = trainer.train(on_episode)
    refs, grid = _grid(group, settings, fams)
    act = bc_act(policy, settings.references, settings.eval_seed)
    paths, scores = rollout_policy(act, grid, [refs[name] for _, name, _ in group])
    return _results(group, refs, [trainer.episode] * len(group), scores, paths)


def _run_ddpg_ti(method, group, settings, report) -> list[MemberResult]:
    cfg = settings.ddpg
    fams = {name: family_for(name, settings.steps) for _, name, _ in group}
    refs, grid = _grid(group, settings, fams)
    results = []
    for k, (i, name, seed) in enumerate(group):
        env = TrajectoryImitationEnv(FamilySource(fams[name]))
        model = train_ddpg_ti(env, seed, cfg, lambda ep, i=i: report(i, ep, ep >= cfg.episodes))
        act = ddpg_ti_act([model], [seed], settings.references, cfg, settings.eval_seed)
        paths, scores = rollout_policy(act, [grid[k]], [refs[name]])
        results += _results([(i, name, seed)], refs, [cfg.episodes], scores, paths)
    return results


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
    parse_methods(list(settings.methods))  # unknown names fail before any work starts
    for name in settings.families:
        get_family(name)
    members = [
        (i, method, name, seed)
        for i, (method, name, seed) in enumerate(
            (method, name, seed)
            for method in settings.methods
            for name in settings.families
            for seed in range(settings.seeds)
        )
    ]
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
    """One result per (method, family), methods in the order asked, then families."""
    out = []
    for method in settings.methods:
        for name in settings.families:
            fam = family_for(name, settings.steps)
            mine = sorted(
                (r for r in results if r.family == name and r.method == method),
                key=lambda r: r.seed,
            )
            scores = np.stack([r.scores for r in mine])
            k, j = np.unravel_index(np.nanargmin(scores), scores.shape)
            best_ref = fam.reference(float(mine[k].alphas[j]))
            finite = np.sort(scores[np.isfinite(scores)])
            top1, top2 = paper_numbers(method, name)
            out.append(
                FamilyResult(
                    name,
                    summarize(scores),
                    top1,
                    float(np.mean([r.episodes for r in mine])),
                    best_ref,
                    mine[k].paths[j],
                    mine,
                    method,
                    float(finite[1]) if len(finite) > 1 else float("nan"),
                    top2,
                )
            )
    return out


def result_rows(result: SelftestResult) -> list[dict]:
    """One row per family: the paper's metric, robust statistics and the paper's number."""
    return [
        {
            "method": f.method,
            "family": f.family,
            "best": f.summary.best,
            "second_best": f.second_best,
            "median": f.summary.median,
            "iqm": f.summary.iqm,
            "iqm_ci_low": f.summary.iqm_low,
            "iqm_ci_high": f.summary.iqm_high,
            "paper_best": f.paper,
            "paper_second_best": f.paper_second,
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
                "method": m.method,
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
        "settings": {
            **asdict(s),
            "config": s.config.to_dict(),
            "bc": s.bc.to_dict(),
            "ddpg": s.ddpg.to_dict(),
        },
        "results": rows,
    }
    written = [out_dir / "results.csv", out_dir / "results.json", out_dir / "scores.csv"]
    atomic_write_bytes(written[0], pd.DataFrame(rows).to_csv(index=False).encode())
    atomic_write_bytes(written[1], json.dumps(doc, indent=2, default=float).encode())
    atomic_write_bytes(written[2], scores.to_csv(index=False).encode())
    fams = [family_for(name, s.steps) for name in dict.fromkeys(f.family for f in result.families)]
    plot_families(fams, out_dir / "families.png")
    plot_best_rollouts(rollout_panels(result), out_dir / "rollouts.png")
    return [*written, out_dir / "families.png", out_dir / "rollouts.png"]


def rollout_panels(result: SelftestResult) -> list[tuple]:
    """Per family, one panel of the paper's Fig. 2. With one method: its best rollout and the
    reference it was best on. With several: the reference on which the first method did best,
    and every method's best rollout (over seeds) on that same reference, with its score there
    (all methods are evaluated on the same references)."""
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
        j = int(np.unravel_index(np.nanargmin(scores), scores.shape)[1])
        reference = family_for(name, result.settings.steps).reference(
            float(first.members[0].alphas[j])
        )
        rollouts, values = {}, {}
        for f in entries:
            col = np.array([m.scores[j] for m in f.members])
            k = int(np.nanargmin(col))
            label = METHODS.get(f.method, f.method)
            rollouts[label], values[label] = f.members[k].paths[j], float(col[k])
        panels.append((name, reference, rollouts, values))
    return panels
