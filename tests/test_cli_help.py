"""`aisdati --help`: the list of commands reads as sentences, not as docstrings' line breaks."""

from __future__ import annotations

import inspect

from typer.testing import CliRunner

from aisdati.cli import app


def test_each_command_summary_is_its_first_paragraph_on_whole_lines():
    result = CliRunner().invoke(app, ["--help"], env={"COLUMNS": "1000"})
    assert result.exit_code == 0, result.output
    for info in app.registered_commands:
        doc = inspect.cleandoc(info.callback.__doc__)
        summary = " ".join(doc.split("\n\n")[0].split())
        assert "\n" in doc.split("\n\n")[0]  # the docstring itself is wrapped
        assert summary in result.output  # one line at 1000 columns, not broken at each newline
