"""The bodies of aisdati's commands: one module per command (ingest, selftest, train, evaluate,
detect), each with a `run` that takes the command's options; `tables` builds every rich table
they print and `common` holds what they share (consoles, error handling, lane settings).

`options` declares every command's options (one dataclass per command); `cli.py` builds the
commands from them and hands the parsed dataclass over with `run_command`, which imports the
command's module only when that command runs: `aisdati --help` loads none of them (nor torch).
"""

from __future__ import annotations

import importlib
from typing import Any


def run_command(name: str, options: Any) -> None:
    """Run command `name` (the module `aisdati.commands.<name>`) with its parsed options (its
    dataclass of `aisdati.commands.options`)."""
    importlib.import_module(f"aisdati.commands.{name}").run(options)
