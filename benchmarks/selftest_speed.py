"""Speed of the self-test: what the full Tables 1 and 2 cost, and where the time goes.

The self-test shares its members out round-robin over one worker per core; inside a worker the
DATI members of a variant train as one ensemble (all repeats together), and so do the BC members
of a variant and the DDPG-TI members. This script measures, with
one torch thread, the cost of one training step of each of those pieces *at the size it has in
a worker* of the full protocol, and projects the wall time of

- Table 1: `aisdati selftest --methods dati,bc,bc-paper,ddpg-ti --repeats R` (4 families x 10
  seeds x R repeats; default R = 3), and
- Table 2: `aisdati selftest --methods table2` (3 DATI variants x 10 seeds on Circles),

on W workers (default 2, one per core), assuming every DATI and DDPG-TI member runs the full 100
episodes x 200 steps (the paper preset does; the `ours` preset's early stopping only shortens it)
and BC its full number of updates. It is a projection from measured step costs, not a run of the
tables: rollouts and scoring (seconds) are left out, and two workers sharing a machine with other
jobs run slower than the single measurement here. `--run` adds a reduced end-to-end Table 1
through `run_selftest` (the CLI's code path) as a sanity check of the wiring, not of the scale.

    python benchmarks/selftest_speed.py [--steps 20] [--repeats 3] [--workers 2] [--run]
        [--json PATH]

(prints a table, its rows as JSON in benchmarks/results/selftest_speed.json)
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import torch
from report import Report, add_json_option  # (this folder: run as a script)
from rich.console import Console

from aisdati.model.bc import BC_PAPER, BCConfig, BCTrainer
from aisdati.model.dati import DATITrainer
from aisdati.model.ddpg_ti import DDPGTIConfig, DDPGTITrainer
from aisdati.model.env import TrajectoryImitationEnv
from aisdati.selftest.paper import PAPER_FAMILIES
from aisdati.selftest.protocol import run_selftest
from aisdati.selftest.settings import SelftestSettings, preset_settings, settings_family
from aisdati.selftest.sources import FamilySource

EPISODES, STEPS = 100, 200
"""The paper's budget per member: 100 episodes of τ = 200 steps."""


def _envs(settings: SelftestSettings, names: list[str]) -> list[TrajectoryImitationEnv]:
    return [TrajectoryImitationEnv(FamilySource(settings_family(settings, n))) for n in names]


def dati_ms(settings: SelftestSettings, method: str, names: list[str], steps: int) -> float:
    """ms per training step (one batch and one action of every member) of one DATI ensemble."""
    fams = [settings_family(settings, n) for n in names]
    noise = [settings.noise_process(f) for f in fams]
    config = replace(settings.dati_config(method), patience=0)
    trainer = DATITrainer(_envs(settings, names), list(range(len(names))), config, noise=noise)
    for _ in range(3):
        trainer.step()
    start = time.perf_counter()
    for _ in range(steps):
        trainer.step()
    return (time.perf_counter() - start) / steps * 1e3


def bc_ms(settings: SelftestSettings, cfg: BCConfig, names: list[str], updates: int) -> float:
    """ms per gradient update of one BC ensemble."""
    cfg = replace(cfg, episodes=2, epochs=None, updates_per_episode=updates)
    trainer = BCTrainer(_envs(settings, names), list(range(len(names))), cfg)
    trainer.step()  # warm-up, then time one episode's updates
    start = time.perf_counter()
    trainer.step()
    return (time.perf_counter() - start) / updates * 1e3


def ddpg_ms(settings: SelftestSettings, names: list[str], steps: int) -> float:
    """ms per environment step (with its gradient step) of one DDPG-TI ensemble."""
    cfg = DDPGTIConfig()
    trainer = DDPGTITrainer(_envs(settings, names), list(range(len(names))), cfg)
    for _ in range(cfg.learning_starts + 3):  # past the random warm-up and the DTW's compilation
        trainer.step()
    start = time.perf_counter()
    for _ in range(steps):
        trainer.step()
    return (time.perf_counter() - start) / steps * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=20, help="DATI steps timed per ensemble")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of Table 1")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (cores)")
    parser.add_argument("--preset", default="paper", help="self-test preset (ours or paper)")
    parser.add_argument("--run", action="store_true", help="also time a reduced end-to-end run")
    add_json_option(parser, "selftest_speed")
    args = parser.parse_args()
    with Report.from_args("selftest_speed", args) as report:
        run(args, report)


def run(args: argparse.Namespace, report: Report) -> None:
    """Measure every piece, print the projection (and with `--run`, the reduced run)."""
    torch.set_num_threads(1)
    w, reps = args.workers, args.repeats
    settings = preset_settings(args.preset)
    # what one worker holds: members are dealt round-robin, so each gets 1/W of every method
    t1 = math.ceil(len(PAPER_FAMILIES) * 10 * reps / w)
    t2 = math.ceil(10 / w)
    names1 = [PAPER_FAMILIES[i % 4] for i in range(t1)]
    names2 = ["circles"] * t2
    bc_paper_updates = BC_PAPER.epochs * math.ceil(EPISODES * STEPS / BC_PAPER.batch_size)

    pieces = []  # (table, what, ms per step, steps per worker, members)
    for method in ("dati",):
        ms = dati_ms(settings, method, names1, args.steps)
        pieces.append(("Table 1", f"DATI, one ensemble of E={t1}", ms, EPISODES * STEPS, t1))
    ms = bc_ms(settings, BCConfig(), names1, 5 * args.steps)
    pieces.append(("Table 1", f"BC, one ensemble of E={t1}", ms, EPISODES * STEPS, t1))
    ms = bc_ms(settings, BC_PAPER, names1, 5 * args.steps)
    pieces.append(("Table 1", f"BC-paper, E={t1}", ms, bc_paper_updates, t1))
    ms = ddpg_ms(settings, names1, 5 * args.steps)
    pieces.append(("Table 1", f"DDPG-TI, one ensemble of E={t1}", ms, EPISODES * STEPS, t1))
    for method in ("dati", "dati-no-time-embedding", "dati-no-reward-input"):
        ms = dati_ms(settings, method, names2, args.steps)
        pieces.append(("Table 2", f"{method}, E={t2}", ms, EPISODES * STEPS, t2))

    console = Console()
    columns = ("table", "what (per worker)", "ms / step", "ms / member-step", "minutes")
    table = report.table(
        columns,
        title=f"Projected wall time of the full tables ({args.preset} preset, {w} workers, "
        f"1 thread each; Table 1 x {reps} repeats), from measured step costs",
        style="rich",
        justify=["left" if col in ("table", "what (per worker)") else "right" for col in columns],
    )
    minutes: dict[str, float] = {}
    for tab, what, ms, steps, members in pieces:
        m = ms * steps / 1e3 / 60
        minutes[tab] = minutes.get(tab, 0.0) + m
        table.row(
            (tab, what, f"{ms:.1f}", f"{ms / members:.2f}", f"{m:.1f}"),
            {"table": tab, "what": what, "ms_per_step": ms, "steps": steps, "members": members,
             "minutes": m},
        )  # fmt: skip
    for tab, m in minutes.items():
        table.row(
            (f"[bold]{tab}[/]", "total", "", "", f"[bold]{m:.1f}[/]"),
            {"table": tab, "what": "total", "minutes": m},
        )
    total = sum(minutes.values())
    table.row(
        ("[bold]both[/]", "total", "", "", f"[bold]{total:.1f}[/]"),
        {"table": "both", "what": "total", "minutes": total},
    )
    table.show()
    note = (
        "A projection, not a run: every DATI and DDPG-TI member at 100 x 200 steps, rollouts "
        "left out; workers run side by side, so a table's wall time is one worker's sum."
    )
    console.print(note)
    report.note(note)
    if args.run:
        small = dict(episodes=2, steps=40, seeds=2, references=3)
        reduced = preset_settings(
            args.preset,
            small["episodes"],
            families=PAPER_FAMILIES,
            seeds=small["seeds"],
            references=small["references"],
            steps=small["steps"],
            workers=w,
            methods=("dati", "bc", "bc-paper", "ddpg-ti"),
        )
        result = run_selftest(reduced)
        line = (
            f"reduced end-to-end Table 1 ({small}): {result.wall_seconds:.1f} s wall on {w} workers"
        )
        console.print(line)
        report.note(line)


if __name__ == "__main__":
    main()
