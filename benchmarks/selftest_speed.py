"""Speed of the self-test. First the ensemble lever: ms per DATI training step (one batch and
one action per member) for ensembles of E = 1, 10, 20, 40 members. Then the wall time of the
paper's Tables 1 and 2 (`aisdati selftest --methods dati,bc,ddpg-ti` and
`--ablation`): measured per-step costs of each method, and the projection to the full budget.

The self-test shares members out round-robin over one worker per core; inside a worker the DATI
members of a variant train as one ensemble, the BC members as one ensemble, and DDPG-TI (SB3)
one model after another. So a worker of Table 1 runs DATI with E = 20, BC with E = 20 and 20
DDPG-TI models (on 2 cores); a worker of Table 2 runs three DATI ensembles of E = 5.
The projection assumes 100 episodes x 200 steps for every member (DATI's early stopping only
shortens it) and leaves out evaluation (seconds).

    python benchmarks/selftest_speed.py [--steps 30] [--run]

`--run` also times a reduced end-to-end Table 1 (4 families x 2 seeds x 2 episodes x 40 steps,
3 references) through `run_selftest`, the same code path as the CLI.
"""

from __future__ import annotations

import argparse
import os
import time

import torch
from rich.console import Console
from rich.table import Table

from aisdati.model.baselines import BCConfig, BCTrainer, DDPGTIConfig, make_ddpg_ti
from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import make_family_env
from aisdati.model.selftest import PAPER_FAMILIES, TABLE1, SelftestSettings, run_selftest

STEPS = 100 * 200
"""Environment steps (DATI, DDPG-TI) or gradient updates (BC) per member at the full budget."""


def dati_ms(members: int, steps: int) -> float:
    envs = [make_family_env(PAPER_FAMILIES[i % 4]) for i in range(members)]
    trainer = DATITrainer(envs, list(range(members)), DATIConfig(patience=0))
    for _ in range(3):
        trainer.step()
    start = time.perf_counter()
    for _ in range(steps):
        trainer.step()
    return (time.perf_counter() - start) / steps * 1e3


def bc_ms(members: int, steps: int) -> float:
    envs = [make_family_env(PAPER_FAMILIES[i % 4]) for i in range(members)]
    trainer = BCTrainer(envs, list(range(members)), BCConfig(updates_per_episode=steps))
    trainer.train_episode()  # warm-up, then time one episode's updates
    start = time.perf_counter()
    trainer.train_episode()
    return (time.perf_counter() - start) / steps * 1e3


def ddpg_ms(steps: int) -> float:
    cfg = DDPGTIConfig()
    model = make_ddpg_ti(make_family_env("circles"), 0, cfg)
    model.learn(cfg.learning_starts + 10)  # past the random warm-up: every step now trains
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return (time.perf_counter() - start) / steps * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--run", action="store_true", help="also time a reduced end-to-end run")
    args = parser.parse_args()
    torch.set_num_threads(1)
    cores = os.cpu_count() or 1
    workers = max(1, min(cores, 2))
    per_worker = 40 // workers  # members of one method in one worker (Table 1)
    ablation_e = 10 // workers  # members of one DATI variant in one worker (Table 2)

    console = Console()
    sweep = Table(title="DATI ensemble: one training step of E members (1 thread)")
    for col in ("members E", "ms / step", "ms / member-step"):
        sweep.add_column(col, justify="right")
    for members in (1, 10, 20, 40):
        ms = dati_ms(members, args.steps)
        sweep.add_row(str(members), f"{ms:.1f}", f"{ms / members:.2f}")
    console.print(sweep)

    costs = {
        f"DATI, ensemble E={per_worker}": (dati_ms(per_worker, args.steps), 1),
        f"BC, ensemble E={per_worker} (per update)": (bc_ms(per_worker, 5 * args.steps), 1),
        "DDPG-TI, one SB3 model": (ddpg_ms(5 * args.steps), per_worker),
        f"DATI, ensemble E={ablation_e} (Table 2)": (dati_ms(ablation_e, args.steps), 3),
    }
    table = Table(title=f"Tables 1-2 step costs (1 thread per worker, {workers} workers)")
    for col in ("what", "ms / step", "ms / member-step", "worker time, full budget"):
        table.add_column(col, justify="left" if col == "what" else "right")
    minutes = {}
    for (what, (ms, runs)), members in zip(
        costs.items(), (per_worker, per_worker, 1, ablation_e), strict=True
    ):
        minutes[what] = ms * STEPS * runs / 1e3 / 60
        table.add_row(what, f"{ms:.2f}", f"{ms / members:.2f}", f"{minutes[what]:.0f} min")
    console.print(table)
    t1 = sum(v for k, v in minutes.items() if "Table 2" not in k)
    t2 = next(v for k, v in minutes.items() if "Table 2" in k)
    console.print(
        f"Table 1 (3 methods x 4 families x 10 seeds): ~{t1:.0f} min; "
        f"Table 2 (3 DATI variants x 10 seeds, circles): ~{t2:.0f} min; "
        f"together ~{(t1 + t2) / 60:.1f} h on {workers} cores, before early stopping."
    )
    if args.run:
        small = dict(episodes=2, steps=40, seeds=2, references=3)
        settings = SelftestSettings(
            PAPER_FAMILIES,
            small["seeds"],
            small["references"],
            small["steps"],
            workers,
            config=DATIConfig(episodes=small["episodes"]),
            methods=TABLE1,
            bc=BCConfig(episodes=small["episodes"]),
            ddpg=DDPGTIConfig(episodes=small["episodes"]),
        )
        result = run_selftest(settings)
        console.print(
            f"reduced end-to-end Table 1 ({small}): {result.wall_seconds:.1f} s wall "
            f"on {workers} workers"
        )


if __name__ == "__main__":
    main()
