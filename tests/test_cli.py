"""`aisdati --help` and each command's: the list of commands reads as sentences, and an
80-column terminal (or a pipe, a log) gets click's plain layout instead of rich's squeezed
option panels."""

from __future__ import annotations

import inspect

import pytest
from typer.testing import CliRunner

from aisdati.cli import app, help_markup


def test_each_command_summary_is_its_first_paragraph_on_whole_lines(monkeypatch):
    monkeypatch.setattr(app, "rich_markup_mode", help_markup(1000))
    result = CliRunner().invoke(app, ["--help"], env={"COLUMNS": "1000"})
    assert result.exit_code == 0, result.output
    assert "╭" in result.output  # rich's panels
    for info in app.registered_commands:
        doc = inspect.cleandoc(info.callback.__doc__)
        summary = " ".join(doc.split("\n\n")[0].split())
        assert "\n" in doc.split("\n\n")[0]  # the docstring itself is wrapped
        assert summary in result.output  # one line at 1000 columns, not broken at each newline


@pytest.mark.parametrize("command", ["ingest", "train", "evaluate", "detect", "selftest"])
def test_an_80_column_help_gives_each_option_the_full_width(monkeypatch, command):
    monkeypatch.setattr(app, "rich_markup_mode", help_markup(80))
    result = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert "╭" not in result.output and max(map(len, lines)) <= 80
    helps = [line.strip() for line in lines if line.startswith(" " * 10)]  # options' help
    assert helps and max(map(len, helps)) >= 45  # rich's panels left ~20 characters at 80


def test_rich_panels_from_100_columns():
    assert help_markup(99) is None and help_markup(100) == "rich"


def test_the_help_names_what_a_command_takes():
    """Issue 69, item 6: `train --help` left out `all`; `ingest --help` said MarineCadastre
    only, though it reads the DMA's files and NMEA logs too."""
    train = CliRunner().invoke(app, ["train", "--help"], env={"COLUMNS": "200"})
    assert "all: one model of the whole area" in " ".join(train.output.split())
    ingest = " ".join(CliRunner().invoke(app, ["ingest", "--help"]).output.split())
    assert "Danish Maritime Authority" in ingest and "NMEA" in ingest
    assert "--since" in ingest and "--until" in ingest
