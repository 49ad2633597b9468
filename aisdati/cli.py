"""Command line of aisdati: the Typer app, one command per options dataclass of
`aisdati.commands.options` (where every option is declared). Each command's body is one call into
`aisdati.commands.<command>`, imported only when that command runs, so that `aisdati --help`
stays fast; every user mistake surfaces as a `UserError` and is shown as one red line."""

from __future__ import annotations

import inspect
import os
import shutil
from collections.abc import Callable
from dataclasses import MISSING, Field, fields
from typing import Any, get_type_hints

# Before torch loads: DATI's networks are small and batched, so OpenMP/MKL worker threads only
# spin; on 2 busy cores one such thread made AIS training ~10x slower. Users may still set these.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import typer

from aisdati.commands import run_command
from aisdati.commands.common import user_errors
from aisdati.commands.options import (
    DetectOptions,
    EvaluateOptions,
    IngestOptions,
    SelftestOptions,
    TrainOptions,
    WatchOptions,
)
from aisdati.startup import end_startup_guard

RICH_HELP_COLUMNS = 100
"""Narrowest terminal that gets rich's help panels: their option columns take about 45
characters (`--lane-traffic` beside `--no-lane-traffic`, a metavar), so at 80 columns each
option's help was squeezed into 20."""


def help_markup(columns: int) -> str | None:
    """Rich's help panels at `RICH_HELP_COLUMNS` or more; below (an 80-column terminal, a pipe,
    a log) click's plain layout, which puts a long option's help under it at full width."""
    return "rich" if columns >= RICH_HELP_COLUMNS else None


app = typer.Typer(
    help="aisdati: find abnormal vessel tracks in AIS data with DATI (domain-adaptive trajectory "
    "imitation).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=help_markup(shutil.get_terminal_size().columns),
)


def command(options: type, name: str) -> Callable[..., None]:
    """The typer command of `options` (a dataclass of `aisdati.commands.options`): its fields
    are the parameters, its docstring the help; the body hands the parsed options, as that
    dataclass, to `aisdati.commands.<name>`."""
    hints = get_type_hints(options, include_extras=True)

    def default(f: Field) -> Any:
        if f.default is not MISSING:
            return f.default
        return f.default_factory() if f.default_factory is not MISSING else inspect.Parameter.empty

    def body(**values: Any) -> None:
        run_command(name, options(**values))

    body.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [
            inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=default(f),
                              annotation=hints[f.name])
            for f in fields(options)
        ]
    )  # fmt: skip
    body.__name__, body.__doc__ = name, options.__doc__
    return user_errors(body)


for _options, _name in (
    (IngestOptions, "ingest"),
    (SelftestOptions, "selftest"),
    (TrainOptions, "train"),
    (EvaluateOptions, "evaluate"),
    (DetectOptions, "detect"),
    (WatchOptions, "watch"),
):
    app.command(name=_name)(command(_options, _name))


def one_line_summaries(commands: typer.Typer) -> None:
    """Each command's line in `aisdati --help`: its docstring's first paragraph with the line
    breaks joined (typer's rich help keeps them there, so the list broke mid-sentence)."""
    for info in commands.registered_commands:
        doc = inspect.cleandoc((info.callback.__doc__ if info.callback else None) or "")
        info.short_help = " ".join(doc.split("\n\n")[0].split())


one_line_summaries(app)
end_startup_guard()  # loaded: from here Ctrl-C is click's and each command's to handle

if __name__ == "__main__":
    app()
