"""The command line as a user meets it: `run` invokes the real `aisdati` in process;
`one_line_error` asserts a user mistake's contract (exit 2, one red line naming the problem, no
traceback)."""

from __future__ import annotations

import re

from typer.testing import CliRunner

from aisdati.cli import app


def run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def one_line_error(result, needle: str, code: int = 2) -> None:
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    assert result.stderr.startswith("error:"), result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert re.search(needle, " ".join(result.stderr.split())), result.stderr
