"""Progress display for training: rich bars over members' episodes and an episode's steps.

Rich draws no live bar when the output is not a terminal (`nohup ... > log`), so a long run
would say nothing until it ends; there the bars print a plain line per task instead, at most
every `LOG_EVERY` seconds and once when the task completes, and the bars' last frame (cut to
the log's 80 columns) is left out."""

from __future__ import annotations

import time
from collections.abc import Sequence
from types import TracebackType
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

LOG_EVERY = 60.0
"""Seconds between plain progress lines when the output is not a terminal."""


class _Bars:
    """A rich `Progress` that is started and stopped as a context manager."""

    progress: Progress
    _logged: dict[int, float]
    _completed: set[int]

    def __enter__(self) -> _Bars:
        self._logged = {}
        self._completed = set()
        self.progress.live.transient = not self.progress.console.is_terminal
        self.progress.start()
        return self

    def _log(self, task_id: Any) -> None:
        """One plain line for a task when nobody sees the live bar (see the module docstring)."""
        if self.progress.disable or self.progress.console.is_terminal or task_id in self._completed:
            return
        task = next(t for t in self.progress.tasks if t.id == task_id)
        now = time.monotonic()
        if task.finished:
            self._completed.add(task_id)
        elif now - self._logged.get(task_id, -LOG_EVERY) < LOG_EVERY:
            return
        self._logged[task_id] = now
        left = task.time_remaining
        eta = f", about {left / 60:.0f} min left" if left is not None and not task.finished else ""
        total = f"/{task.total:.0f}" if task.total is not None else ""
        self.progress.console.print(
            f"{task.description}: {task.completed:.0f}{total} "
            f"({(task.elapsed or 0.0) / 60:.1f} min{eta})",
            highlight=False,
        )

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.progress.stop()


class EpisodeProgress(_Bars):
    """Counts training episodes of many members; a member that stops early counts as done.
    `unit` names what is counted (models, for a detector that learns in one pass)."""

    def __init__(
        self,
        members: int,
        episodes: int,
        label: str,
        disable: bool = False,
        console: Console | None = None,
        unit: str = "episodes",
    ):
        self.episodes = episodes
        self.done: dict[int, int] = {}
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn(unit),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            disable=disable,
            console=console,
        )
        self.task = self.progress.add_task(label, total=members * episodes)

    def update(self, member: int, episode: int, stopped: bool) -> None:
        self.done[member] = self.episodes if stopped else episode
        self.progress.update(self.task, completed=sum(self.done.values()))
        self._log(self.task)

    def on_step(self, trainer: Any, logs: Sequence[Any]) -> None:
        """A trainer's step callback: count the episodes its members ended."""
        for log in logs:
            self.update(log.member, log.episode, log.stopped)

    def members_done(self, members: range) -> None:
        """A task trained elsewhere (a Dask worker) has ended: its members are done."""
        for member in members:
            self.update(member, self.episodes, True)


class TrainingProgress(_Bars):
    """Two bars for one training run: episodes, and the steps of the current episode with its
    running mean reward and smoothed DTW (metres)."""

    def __init__(
        self,
        episodes: int,
        label: str,
        disable: bool = False,
        every: int = 10,
        console: Console | None = None,
    ):
        self.every = every
        self.calls = 0
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            disable=disable,
            console=console,
        )
        self.episodes = self.progress.add_task(label, total=episodes, info="episodes")
        self.steps = self.progress.add_task("episode 1", total=None, info="")

    def episode_done(self, episode: int, mean_reward: float, final_dtw: float) -> None:
        self.progress.update(
            self.episodes,
            completed=episode,
            info=f"episodes  last: reward {mean_reward:+.2f}, DTW {final_dtw:,.0f} m",
        )
        self._log(self.episodes)

    def step(self, episode: int, step: int, horizon: int, reward: float, dtw: float) -> None:
        self.calls += 1
        if self.calls % self.every:
            return
        self.progress.update(
            self.steps,
            description=f"episode {episode}",
            completed=step,
            total=horizon,
            info=f"steps  reward {reward:+.2f}  DTW {dtw:,.0f} m",
        )
