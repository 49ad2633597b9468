"""Progress for long runs: a live bar on a terminal, plain lines in a log file."""

from __future__ import annotations

import io

from rich.console import Console

from aisdati import progress
from aisdati.progress import EpisodeProgress, TrainingProgress


def _console(terminal: bool) -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, force_terminal=terminal, width=100), out


def test_a_log_file_gets_a_plain_line_now_and_then_and_at_the_end(monkeypatch):
    console, out = _console(terminal=False)
    with EpisodeProgress(2, 3, "training dati", console=console) as bars:
        bars.update(0, 1, False)  # the first line: nothing logged yet
        bars.update(1, 1, False)  # within LOG_EVERY of it: no line
        monkeypatch.setattr(progress, "LOG_EVERY", 0.0)
        bars.update(0, 2, False)
        bars.update(0, 2, True)  # a member that stops early counts as done
        bars.update(1, 3, True)
        bars.update(1, 3, True)  # complete already: no second line
    assert "━" not in out.getvalue()  # nor the bar's last frame
    lines = [line for line in out.getvalue().splitlines() if line.startswith("training dati:")]
    assert [line.split(" (")[0] for line in lines] == [
        "training dati: 1/6",
        "training dati: 3/6",
        "training dati: 4/6",
        "training dati: 6/6",
    ]
    assert lines[-1].endswith(" min)")  # elapsed, and no time left once complete


def test_training_progress_logs_its_episodes():
    console, out = _console(terminal=False)
    with TrainingProgress(2, "training route-1", console=console) as bars:
        bars.episode_done(1, 0.5, 1200.0)
        bars.episode_done(2, 0.6, 900.0)
    assert "training route-1: 2/2 (" in out.getvalue()


def test_a_terminal_gets_the_bar_not_the_lines():
    console, out = _console(terminal=True)
    with EpisodeProgress(1, 2, "training dati", console=console) as bars:
        bars.update(0, 2, True)
    assert "training dati:" not in out.getvalue()
    assert "2/2" in out.getvalue()


def test_no_output_when_disabled():
    console, out = _console(terminal=False)
    with EpisodeProgress(1, 2, "training dati", disable=True, console=console) as bars:
        bars.update(0, 2, True)
    assert out.getvalue() == ""


def test_nearest_counts_its_route_models_not_episodes(kitimat, cli, tmp_path):
    """`nearest` learns each route in one pass: its bar counts the routes' models (Kitimat's
    4), not members times `--episodes` (4 x 170 before)."""
    r = cli("train", "--method", "nearest", "--cluster", "routes", "--data", kitimat,
            "--out", tmp_path)  # fmt: skip
    assert r.exit_code == 0, r.output
    lines = [line for line in r.output.splitlines() if line.startswith("training nearest:")]
    assert lines and lines[-1].startswith("training nearest: 4/4 (")
