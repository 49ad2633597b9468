"""`aisdati selftest`: the paper's synthetic protocol (Table 1 and the Table 2 ablation).

Every (method, family, seed) triple is one member. The members are shared out over `workers`
processes (one per core); inside a process the DATI members of one variant train as one batched
ensemble, the BC members of one variant as one ensemble, and the DDPG-TI members as one ensemble
per episode length. Then each member's policy is rolled out from the first point of unseen
references of its family. The paper's metric is the lowest normalised smoothed DTW over seeds x
references (Table 2 adds the second lowest). `repeats` runs the whole protocol again on further
blocks of seeds, so that the metric's own spread over repeats can be read beside it.

Methods: `dati`, `bc`, `bc-paper`, `ddpg-ti` (Table 1) and the ablated DATI variants
`dati-no-time-embedding`, `dati-no-reward-input` (Table 2, with `dati`: `ABLATION`).

Presets (`SELFTEST_PRESETS`) name the set-up choices that the paper leaves to its code:
- `paper` (the default): the authors' code (DLR-MI/dati) as far as it can be read: 100 episodes
  and the final actor (its running-sum early stopping never fires once the losses turn
  negative); Time2Vec frozen under the actors' adversarial loss (critic.trainable = False when
  the GAN is compiled); Ornstein-Uhlenbeck noise at the family's own dt for FixedStart, UShaped
  and Circles and Gaussian for Ribbons (its results script takes Ribbons from the Gaussian run);
  the exact bounding box and speeds in [s_min, s_max]; each seed scored on its own references
  (100 distinct ones). It is the default because its DATI median was lower than `ours`' on 3 of
  4 families over 10 seeds x 3 repeats (README, "the paper preset").
- `ours`: early stopping (patience 10) keeping the lowest-loss actor; the shared Time2Vec also
  learns from the actors' adversarial loss; Gaussian latent noise; the region is the family's box
  plus 10 % and speeds decode in [0, 1.25 x s_max]; every seed is scored on the same references.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from queue import Empty
from typing import Any

import numpy as np
import pandas as pd
import torch

from aisdati import __version__
from aisdati.errors import UserError
from aisdati.model.bc import BC_PAPER, BCConfig, BCTrainer, bc_act
from aisdati.model.checkpoint import atomic_write_bytes
from aisdati.model.dati import DATIConfig, DATITrainer, NoiseProcess
from aisdati.model.ddpg_ti import DDPGTIConfig, DDPGTITrainer, ddpg_ti_act
from aisdati.model.env import Reference, TrajectoryImitationEnv
from aisdati.model.rollout import Summary, rollout, rollout_policy, summarize
from aisdati.options import parse_names
from aisdati.plots import plot_best_rollouts, plot_families
from aisdati.selftest.families import PAPER_DATI, Family, get_family
from aisdati.selftest.sources import FamilySource

PAPER_FAMILIES = ("fixedstart", "ushaped", "circles", "ribbons")

METHODS = {
    "dati": "DATI",
    "bc": "BC",
    "bc-paper": "BC (paper's: no time input)",
    "ddpg-ti": "DDPG-TI",
    "dati-no-time-embedding": "DATI, no time embedding",
    "dati-no-reward-input": "DATI, no reward input",
}
"""Method names accepted by `--methods`, with their display labels."""

TABLE1 = ("dati", "bc", "bc-paper", "ddpg-ti")
ABLATION = ("dati", "dati-no-time-embedding", "dati-no-reward-input")

PAPER_TABLE1 = {
    "dati": PAPER_DATI,
    "bc": {"fixedstart": 0.124, "ushaped": 0.365, "circles": 0.106, "ribbons": 0.113},
    "bc-paper": {"fixedstart": 0.124, "ushaped": 0.365, "circles": 0.106, "ribbons": 0.113},
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


NOISES = ("gaussian", "ou", "family")
"""Latent noise of the self-test's DATI: Gaussian, OU at `DATIConfig.ou_dt` for every family, or
"family": the authors' choice per family (`PAPER_NOISE`)."""

PAPER_NOISE = {"ribbons": "gaussian"}
"""The authors' latent noise per family where it is not OU at the family's dt."""


@dataclass(frozen=True)
class SelftestPreset:
    """The set-up choices that the paper leaves to its code (see the module docstring)."""

    keep: str = "best"
    """The actor a DATI seed ends with: "best" (lowest episode loss) or "final"."""
    patience: int = 10
    adversarial_time2vec: bool = True
    noise: str = "gaussian"
    exact_region: bool = False
    """The family's exact box and [s_min, s_max] speeds (`Family.exact`)."""
    distinct_references: bool = False
    """Each seed scored on references of its own instead of the family's shared ones."""


SELFTEST_PRESETS = {
    "paper": SelftestPreset(
        keep="final",
        patience=0,
        adversarial_time2vec=False,
        noise="family",
        exact_region=True,
        distinct_references=True,
    ),
    "ours": SelftestPreset(),
}
"""`aisdati selftest --preset`; the first is the default."""
DEFAULT_SELFTEST_PRESET = next(iter(SELFTEST_PRESETS))
_DEFAULT = SELFTEST_PRESETS[DEFAULT_SELFTEST_PRESET]


def get_preset(name: str) -> SelftestPreset:
    try:
        return SELFTEST_PRESETS[name]
    except KeyError:
        raise UserError(
            f"unknown self-test preset {name!r}; choose from {', '.join(SELFTEST_PRESETS)}"
        ) from None


@dataclass(frozen=True)
class SelftestSettings:
    """The protocol; defaults are the paper's (10 seeds, 10 unseen references, τ = 200) under
    the default preset; `preset_settings` builds them for any preset."""

    families: tuple[str, ...] = PAPER_FAMILIES
    seeds: int = 10
    references: int = 10
    steps: int | None = None
    """Steps per episode τ; None keeps each family's own (200 for the paper's)."""
    workers: int = 1
    eval_seed: int = 2024
    config: DATIConfig = field(default_factory=lambda: preset_config(_DEFAULT))
    methods: tuple[str, ...] = ("dati",)
    bc: BCConfig = field(default_factory=BCConfig)
    bc_paper: BCConfig = BC_PAPER
    ddpg: DDPGTIConfig = field(default_factory=DDPGTIConfig)
    preset: str = DEFAULT_SELFTEST_PRESET
    noise: str = _DEFAULT.noise
    """One of `NOISES`: DATI's latent noise per family (`noise_process`); `config.noise` only
    mirrors it."""
    exact_region: bool = _DEFAULT.exact_region
    distinct_references: bool = _DEFAULT.distinct_references
    repeats: int = 1
    """Runs of the whole protocol, repeat r on seeds r·seeds .. (r+1)·seeds − 1."""

    def dati_config(self, method: str) -> DATIConfig:
        """DATI's configuration for a DATI method name (the ablations switch one input off)."""
        if method == "dati-no-time-embedding":
            return self.config.with_network(time_embedding=False)
        if method == "dati-no-reward-input":
            return self.config.with_network(reward_input=False)
        return self.config

    def noise_process(self, fam: Family) -> NoiseProcess:
        """DATI's latent noise process for a family."""
        if self.noise == "family":
            kind = PAPER_NOISE.get(fam.name, "ou")
            return NoiseProcess(kind, fam.dt)
        return NoiseProcess(self.noise, self.config.ou_dt)


def preset_config(p: SelftestPreset, episodes: int = 100, noise: str | None = None) -> DATIConfig:
    """DATI's configuration under a preset (`noise` overrides the preset's)."""
    noise = noise or p.noise
    return DATIConfig(
        episodes=episodes,
        patience=p.patience,
        keep=p.keep,
        adversarial_time2vec=p.adversarial_time2vec,
        noise="ou" if noise == "family" else noise,  # the family's dt: `noise_process`
    )


def preset_settings(
    preset: str = DEFAULT_SELFTEST_PRESET,
    episodes: int = 100,
    noise: str | None = None,
    **fields: Any,
) -> SelftestSettings:
    """The settings of a named preset with every method's episode budget; `noise` overrides the
    preset's, `fields` set the rest of `SelftestSettings` (a `config` given there is kept)."""
    p = get_preset(preset)
    noise = noise or p.noise
    if noise not in NOISES:
        raise UserError(f"--noise must be one of {', '.join(NOISES)}, got {noise!r}")
    config = fields.pop("config", preset_config(p, episodes, noise))
    return SelftestSettings(
        config=config,
        bc=replace(BCConfig(), episodes=episodes),
        bc_paper=replace(BC_PAPER, episodes=episodes),
        ddpg=replace(DDPGTIConfig(), episodes=episodes),
        preset=preset,
        noise=noise,
        exact_region=p.exact_region,
        distinct_references=p.distinct_references,
        **fields,
    )


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


def family_for(name: str, steps: int | None, exact: bool = False) -> Family:
    """A registered family with τ = `steps` (None: its own) and, if `exact`, the exact region."""
    fam = get_family(name)
    changes: dict[str, Any] = {}
    if steps is not None and steps != fam.steps:
        changes["steps"] = steps
    if exact != fam.exact:
        changes["exact"] = exact
    return replace(fam, **changes) if changes else fam


def settings_family(settings: SelftestSettings, name: str) -> Family:
    return family_for(name, settings.steps, settings.exact_region)


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


def _run_members(
    members: list[Member],
    settings: SelftestSettings,
    report: Callable[[int, int, bool], None],
) -> list[MemberResult]:
    """Train and evaluate a group of members: one ensemble per DATI variant, one per BC variant,
    one DDPG-TI ensemble per episode length."""
    torch.set_num_threads(1)
    results: list[MemberResult] = []
    for method in dict.fromkeys(m for _, m, _, _ in members):
        group = [(i, name, seed) for i, m, name, seed in members if m == method]
        run = {"bc": _run_bc, "bc-paper": _run_bc, "ddpg-ti": _run_ddpg_ti}.get(method, _run_dati)
        out = run(method, group, settings, report)
        for r in out:
            r.method = method
            r.repeat = r.seed // settings.seeds
        results.extend(out)
    return results


def _grid(group, settings, fams):
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


def _results(group, refs, episodes, scores, paths) -> list[MemberResult]:
    return [
        MemberResult(
            name,
            seed,
            episodes[k],
            scores[k],
            np.array([r.label["alpha"] for r in refs[k]]),
            paths[k],
        )
        for k, (_, name, seed) in enumerate(group)
    ]


def _families(group, settings) -> dict[str, Family]:
    return {name: settings_family(settings, name) for _, name, _ in group}


def _run_dati(method, group, settings, report) -> list[MemberResult]:
    config = settings.dati_config(method)
    fams = _families(group, settings)
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in group]
    noise = [settings.noise_process(fams[name]) for _, name, _ in group]
    trainer = DATITrainer(envs, [seed for _, _, seed in group], config, noise=noise)

    def on_step(logs: list) -> None:
        for log in logs:
            report(group[log.member][0], log.episode, log.stopped)

    nets = trainer.train(on_step)
    refs, grid = _grid(group, settings, fams)
    out = rollout(nets, grid, refs, config, seed=settings.eval_seed, noise=noise)
    return _results(group, refs, trainer.episode, out.scores, out.paths)


def _run_bc(method, group, settings, report) -> list[MemberResult]:
    cfg = settings.bc_paper if method == "bc-paper" else settings.bc
    fams = _families(group, settings)
    envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in group]
    trainer = BCTrainer(envs, [seed for _, _, seed in group], cfg)

    def on_episode(episode: int) -> None:
        for i, _, _ in group:
            report(i, episode, episode >= cfg.episodes)

    policy = trainer.train(on_episode)
    refs, grid = _grid(group, settings, fams)
    act = bc_act(policy, settings.references, settings.eval_seed)
    paths, scores = rollout_policy(act, grid, refs)
    return _results(group, refs, [trainer.episode] * len(group), scores, paths)


def _run_ddpg_ti(method, group, settings, report) -> list[MemberResult]:
    cfg = settings.ddpg
    fams = _families(group, settings)
    results = []
    for steps in dict.fromkeys(fams[name].steps for _, name, _ in group):
        part = [m for m in group if fams[m[1]].steps == steps]
        envs = [TrajectoryImitationEnv(FamilySource(fams[name])) for _, name, _ in part]
        seeds = [seed for _, _, seed in part]
        trainer = DDPGTITrainer(envs, seeds, cfg)
        actor = trainer.train(lambda k, ep, part=part: report(part[k][0], ep, ep >= cfg.episodes))
        refs, grid = _grid(part, settings, fams)
        act = ddpg_ti_act(actor, seeds, settings.references, cfg, settings.eval_seed)
        paths, scores = rollout_policy(act, grid, refs)
        results += _results(part, refs, [cfg.episodes] * len(part), scores, paths)
    return results


def _worker(members, settings, queue) -> None:  # pragma: no cover - runs in a child process
    # the parent's SIGTERM handler (clean-up of a command's outputs) is not the child's: a
    # worker stopped by its parent just ends, without a traceback
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
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
        for p in procs:  # each has sent its results: let it flush its queue and exit
            p.join()
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
            p.join()
    return results


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
