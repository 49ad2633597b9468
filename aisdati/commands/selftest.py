"""`aisdati selftest`: the paper's synthetic protocol (Tables 1 and 2) from the command line."""

from __future__ import annotations

import json
from dataclasses import replace
from datetime import datetime
from pathlib import Path

from rich.markup import escape

from aisdati.commands.common import console, shows_progress
from aisdati.commands.options import SelftestOptions
from aisdati.commands.tables import ablation_table, selftest_table
from aisdati.errors import UserError
from aisdati.execution import Execution, resolve_device
from aisdati.outdir import prepare_output_dir
from aisdati.progress import EpisodeProgress
from aisdati.selftest.families import FAMILIES
from aisdati.selftest.outputs import result_rows, write_outputs
from aisdati.selftest.paper import PAPER_FAMILIES
from aisdati.selftest.protocol import run_selftest
from aisdati.selftest.settings import ABLATION, QUICK, TABLE2, parse_methods, preset_settings


def run(o: SelftestOptions) -> None:
    """`aisdati selftest` with its options (`aisdati.commands.options.SelftestOptions`)."""
    ablation = o.methods.strip().lower() == TABLE2
    names = family_names(o.family, ablation)
    method_names = ABLATION if ablation else parse_methods(o.methods)
    for name in names:
        if name not in FAMILIES:
            raise UserError(f"unknown family {name!r}; choose from {', '.join(FAMILIES)}")
    if o.quick:
        o = replace(o, **QUICK)
    check_counts(o.seeds, o.episodes, o.references, o.repeats, o.steps)
    execution = Execution.parse(o.workers)
    settings = preset_settings(
        o.preset,
        o.episodes,
        families=tuple(names),
        seeds=o.seeds,
        references=o.references,
        steps=o.steps,
        workers=execution.workers,
        scheduler=execution.scheduler,
        device=resolve_device(o.device),
        methods=tuple(method_names),
        repeats=o.repeats,
    )
    out = o.out or Path("runs") / f"selftest-{datetime.now():%Y%m%d-%H%M%S}"
    prepare_output_dir(out, "--out")
    total = len(method_names) * len(names) * o.seeds * o.repeats
    label = "training DATI" if list(method_names) == ["dati"] else "training"
    with EpisodeProgress(
        total, o.episodes, label, disable=not shows_progress(o.as_json)
    ) as progress:
        result = run_selftest(settings, progress.update)
    files = write_outputs(result, out)
    rows = result_rows(result)
    if o.as_json:
        print(json.dumps({"results": rows, "wall_seconds": result.wall_seconds, "out": str(out)}))
    else:
        make_table = ablation_table if ablation else selftest_table
        console.print(make_table(rows, result.wall_seconds))
        names = ", ".join(f.name for f in files)
        console.print(f"wrote {names} to [bold]{escape(str(out))}[/]")


def family_names(family: list[str], ablation: bool) -> list[str]:
    """--family as a list of names; none or 'all': the paper's four (the ablation: circles)."""
    names = [n.strip().lower() for item in family for n in item.split(",") if n.strip()]
    default_families = ["circles"] if ablation else list(PAPER_FAMILIES)
    return default_families if names in ([], ["all"]) else names


def check_counts(
    seeds: int, episodes: int, references: int, repeats: int, steps: int | None
) -> None:
    """Every count option is at least 1 (--steps at least 2), or a one-line `UserError`."""
    for label, value in (
        ("--seeds", seeds),
        ("--episodes", episodes),
        ("--references", references),
        ("--repeats", repeats),
    ):
        if value < 1:
            raise UserError(f"{label} must be at least 1, got {value}")
    if steps is not None and steps < 2:
        raise UserError(f"--steps must be at least 2, got {steps}")
