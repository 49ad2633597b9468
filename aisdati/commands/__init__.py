"""The bodies of aisdati's commands: one module per command (ingest, selftest, train, evaluate,
detect), each with a `run` that takes the command's options; `tables` builds every rich table
they print and `common` holds what they share (consoles, error handling, lane settings).

`cli.py` declares the options and hands them over with `run_command`, which imports the
command's module only when that command runs: `aisdati --help` loads none of them (nor torch).
"""

from __future__ import annotations

import importlib
from typing import Any


def run_command(name: str, options: dict[str, Any]) -> None:
    """Run command `name` (the module `aisdati.commands.<name>`) with the parsed `options`."""
    importlib.import_module(f"aisdati.commands.{name}").run(**options)
