"""What the hardening tests share: `run` invokes the real command line in process;
`one_line_error` asserts a user mistake's contract (exit 2, one red line naming the problem, no
traceback); `card_edit` damages one field of a model card."""

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


def card_edit(path: str, value):
    """An edit of a card (a JSON dict) that sets the dotted `path` to `value`."""

    def edit(card):
        node = card
        *parents, last = path.split(".")
        for p in parents:
            node = node[p]
        node[last] = value

    return edit
