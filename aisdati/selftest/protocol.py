"""`aisdati selftest`: the paper's synthetic protocol (Table 1 and the Table 2 ablation).

Every (method, family, seed) triple is one member. The members of one (method, family) are one
task (`aisdati.execution`: here, or on `workers` local Dask processes, or on a cluster), so the
results do not depend on where the tasks ran; inside a task the DATI members train as one batched
ensemble, the BC members as one ensemble, and the DDPG-TI members as one ensemble per episode
length, all followed by one trainer callback (`aisdati.model.trainer.Callback`; in this process
per episode, on a cluster as each task ends).
Then each member's policy is rolled out from the first point of unseen references of its
family. The paper's metric is the lowest normalised smoothed DTW over seeds x references (Table 2
adds the second lowest). `repeats` runs the whole protocol again on further blocks of seeds, so
that the metric's own spread over repeats can be read beside it. The methods and presets are
`aisdati.selftest.settings`'; the outputs `aisdati.selftest.outputs`'.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from aisdati.execution import Execution, open_runner
from aisdati.model.bc import BCTrainer, bc_act
from aisdati.model.dati import DATITrainer
from aisdati.model.ddpg_ti import DDPGTITrainer, ddpg_ti_act
from aisdati.model.env import Reference, TrajectoryImitationEnv
from aisdati.model.noise import NoiseProcess
from aisdati.model.rollout import Act, dati_policy, rollout_policy
from aisdati.model.trainer import Callback, EpisodeLog, Trainer
from aisdati.selftest.families import Family, get_family
from aisdati.selftest.paper import paper_numbers
from aisdati.selftest.settings import SelftestSettings, get_preset, parse_methods, settings_family
from aisdati.selftest.sources import FamilySource
from aisdati.selftest.summary import Summary, summarize


@dataclass
class MemberResult:
    family: str
    seed: int
    episodes: int
    scores: np.ndarray
    alphas: np.ndarray
    paths: list[np.ndarray]
    method: str = "dati"
    repeat: int = 0


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
    repeat_best: list[float] = field(default_factory=list)
    """The paper's metric of each repeat (its `best` is their mean)."""
    repeat_second: list[float] = field(default_factory=list)


@dataclass
class SelftestResult:
    settings: SelftestSettings
    families: list[FamilyResult]
    wall_seconds: float


def evaluation_references(
    fam: Family, count: int, seed: int, member: int | None = None
) -> list[Reference]:
    """The unseen test references of a family: α drawn from an evaluation-only stream, the
    family's shared one or, given a member seed, that seed's own."""
    key = [seed, sum(map(ord, fam.name)), *([] if member is None else [member])]
    rng = np.random.default_rng(key)
    source = FamilySource(fam)
    return [source.reference(fam.sample_alpha(rng)) for _ in range(count)]


Member = tuple[int, str, str, int]
"""(index, method, family, seed)."""
Group = list[tuple[int, str, int]]
"""The (index, family, seed) of members trained as one ensemble."""
Report = Callable[[int, int, bool], None]
"""`report(member_index, episode, stopped)`: training progress by the members' indices in the
whole protocol (the same from a worker process)."""


def _run_members(
    settings: SelftestSettings, report: Report, members: list[Member]
) -> list[MemberResult]:
    """Train and evaluate a group of members (one task): one ensemble per DATI variant, one per
    BC variant, one DDPG-TI ensemble per episode length."""
    torch.set_num_threads(1)
    results: list[MemberResult] = []
    for method in dict.fromkeys(m for _, m, _, _ in members):
        group = [(i, name, seed) for i, m, name, seed in members if m == method]
        for ensemble in _ensembles(method, group, settings):
            out = _run_ensemble(method, ensemble, settings, report)
            for r in out:
                r.method = method
                r.repeat = r.seed // settings.seeds
            results.extend(out)
    return results


def _ensembles(method: str, group: Group, settings: SelftestSettings) -> list[Group]:
    """A method's members as ensembles: all in one, but DDPG-TI's by episode length."""
    if method != "ddpg-ti":
        return [group]
    steps = [settings_family(settings, name).steps for _, name, _ in group]
    return [
        [m for m, n in zip(group, steps, strict=True) if n == length]
        for length in dict.fromkeys(steps)
    ]


def _run_ensemble(
    method: str, group: Group, settings: SelftestSettings, report: Report
) -> list[MemberResult]:
    """Train one ensemble of a method's members, then roll each out on its references."""
    fams = {name: settings_family(settings, name) for _, name, _ in group}
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in group]
    seeds = [seed for _, _, seed in group]
    noise = [settings.noise_process(fams[name]) for _, name, _ in group]
    trainer, policy = _trainer(method, envs, seeds, settings, noise)
    trainer.train(_reporter(group, report))
    refs, grid = evaluation_grid(group, settings, fams)
    paths, scores = rollout_policy(policy(), grid, refs)
    return [
        MemberResult(
            name,
            seed,
            trainer.episode[k],
            scores[k],
            np.array([r.label["alpha"] for r in refs[k]]),
            paths[k],
        )
        for k, (_, name, seed) in enumerate(group)
    ]


def _trainer(
    method: str,
    envs: list[TrajectoryImitationEnv],
    seeds: list[int],
    settings: SelftestSettings,
    noise: list[NoiseProcess],
) -> tuple[Trainer[Any], Callable[[], Act]]:
    """A method's trainer over the members' environments, and how to make its trained
    policy, batched over the members' references (DATI's latent noise: `noise`)."""
    refs, seed = settings.references, settings.eval_seed
    if method in ("bc", "bc-paper"):
        bc = BCTrainer(envs, seeds, settings.bc_paper if method == "bc-paper" else settings.bc)
        return bc, lambda: bc_act(bc.policy, refs, seed)
    if method == "ddpg-ti":
        ddpg = DDPGTITrainer(envs, seeds, settings.ddpg)
        return ddpg, lambda: ddpg_ti_act(ddpg.actor, seeds, refs, settings.ddpg, seed)
    config = settings.dati_config(method)
    dati = DATITrainer(envs, seeds, config, noise=noise, device=settings.device)
    return dati, lambda: dati_policy(dati.final, config, refs, seed, noise)


def _reporter(group: Group, report: Report) -> Callback:
    """Every trainer's callback: report each ended episode under its member's protocol index."""

    def callback(trainer: Trainer[Any], logs: list[EpisodeLog]) -> None:
        for log in logs:
            report(group[log.member][0], log.episode, log.stopped)

    return callback


def evaluation_grid(
    group: Group, settings: SelftestSettings, fams: dict[str, Family]
) -> tuple[list[list[Reference]], list[list[TrajectoryImitationEnv]]]:
    """Each member's unseen references and one evaluation env per reference."""
    shared = {
        n: evaluation_references(f, settings.references, settings.eval_seed)
        for n, f in fams.items()
    }
    refs = [
        evaluation_references(fams[name], settings.references, settings.eval_seed, seed)
        if settings.distinct_references
        else shared[name]
        for _, name, seed in group
    ]
    grid = [
        [TrajectoryImitationEnv(FamilySource(fams[name])) for _ in range(settings.references)]
        for _, name, _ in group
    ]
    return refs, grid


def run_selftest(settings: SelftestSettings, report: Report | None = None) -> SelftestResult:
    """Run the protocol; `report(member_index, episode, stopped)` follows training progress."""
    report = report or (lambda i, ep, stop: None)
    parse_methods(list(settings.methods))  # unknown names fail before any work starts
    get_preset(settings.preset)
    for name in settings.families:
        get_family(name)
    members = [
        (i, method, name, seed)
        for i, (method, name, seed) in enumerate(
            (method, name, seed)
            for method in settings.methods
            for name in settings.families
            for seed in range(settings.seeds * settings.repeats)
        )
    ]
    start = time.perf_counter()
    tasks = [
        [m for m in members if (m[1], m[2]) == key]
        for key in dict.fromkeys((method, name) for _, method, name, _ in members)
    ]
    execution = Execution(workers=settings.workers, scheduler=settings.scheduler)
    with open_runner(execution) as runner:
        follow = report if not execution.distributed else _unreported

        def ended(k: int) -> None:
            if execution.distributed:
                for i, *_ in tasks[k]:
                    report(i, settings.config.episodes, True)

        done = runner.map(functools.partial(_run_members, settings, follow), tasks, ended)
    results = [r for task in done for r in task]
    wall = time.perf_counter() - start
    return SelftestResult(settings, _aggregate(settings, results), wall)


def _unreported(i: int, episode: int, stopped: bool) -> None:
    """The report of a task on a cluster: episodes are not seen from there."""


def _lowest_two(scores: np.ndarray) -> tuple[float, float]:
    finite = np.sort(scores[np.isfinite(scores)])
    return float(finite[0]), float(finite[1]) if len(finite) > 1 else float("nan")


def _aggregate(settings: SelftestSettings, results: list[MemberResult]) -> list[FamilyResult]:
    """One result per (method, family), methods in the order asked, then families: the paper's
    metrics per repeat (and their mean), robust statistics over every repeat's scores."""
    out = []
    for method in settings.methods:
        for name in settings.families:
            fam = settings_family(settings, name)
            mine = sorted(
                (r for r in results if r.family == name and r.method == method),
                key=lambda r: r.seed,
            )
            scores = np.stack([r.scores for r in mine])
            k, j = np.unravel_index(np.nanargmin(scores), scores.shape)
            best_ref = fam.reference(float(mine[k].alphas[j]))
            per_repeat = [
                _lowest_two(np.stack([r.scores for r in mine if r.repeat == rep]))
                for rep in range(settings.repeats)
            ]
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
                    float(np.mean([b for _, b in per_repeat])),
                    top2,
                    [b for b, _ in per_repeat],
                    [b for _, b in per_repeat],
                )
            )
    return out
