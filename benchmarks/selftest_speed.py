"""Training-step cost of the batched DATI ensemble, and what it implies for the paper's protocol.

Prints a table: milliseconds per environment step (one training batch + acting) for ensembles of
E members, the cost per member-step, and the projected wall time of the full DATI column of
Table 1 (4 families x 10 seeds x 100 episodes x 200 steps, without early stopping) on this
machine with one worker per core. Run: python benchmarks/selftest_speed.py [--steps 30]
"""

from __future__ import annotations

import argparse
import os
import time

import torch
from rich.console import Console
from rich.table import Table

from aisdati.model.dati import DATIConfig, DATITrainer
from aisdati.model.env import make_family_env
from aisdati.model.selftest import PAPER_FAMILIES

FULL_MEMBER_STEPS = 4 * 10 * 100 * 200


def step_ms(members: int, steps: int) -> float:
    envs = [make_family_env(PAPER_FAMILIES[i % 4]) for i in range(members)]
    trainer = DATITrainer(envs, list(range(members)), DATIConfig(patience=0))
    for _ in range(3):
        trainer.step()
    start = time.perf_counter()
    for _ in range(steps):
        trainer.step()
    return (time.perf_counter() - start) / steps * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=30)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cores = os.cpu_count() or 1
    table = Table(title=f"DATI ensemble training step (1 thread per worker, {cores} cores)")
    for col in ("members E", "ms / step", "ms / member-step", "full Table-1 DATI column"):
        table.add_column(col, justify="right")
    for members in (1, 10, 20, 40):
        ms = step_ms(members, args.steps)
        per_member = ms / members
        workers = min(cores, 40 // members) if members < 40 else 1
        hours = FULL_MEMBER_STEPS * per_member / 1e3 / 3600 / max(workers, 1)
        table.add_row(str(members), f"{ms:.1f}", f"{per_member:.2f}",
                      f"{hours * 60:.0f} min with {max(workers, 1)} worker(s)")
    Console().print(table)
    print("Projection assumes every member runs all 100 episodes; early stopping shortens it.")


if __name__ == "__main__":
    main()
