"""Progress display for training: rich bars over members' episodes and an episode's steps."""

from __future__ import annotations

from collections.abc import Sequence
from types import TracebackType
from typing import Any

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


class _Bars:
    """A rich `Progress` that is started and stopped as a context manager."""

    progress: Progress

    def __enter__(self) -> _Bars:
        self.progress.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.progress.stop()


class EpisodeProgress(_Bars):
    """Counts training episodes of many members; a member that stops early counts as done."""

    def __init__(self, members: int, episodes: int, label: str, disable: bool = False):
        self.episodes = episodes
        self.done: dict[int, int] = {}
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("episodes"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            disable=disable,
        )
        self.task = self.progress.add_task(label, total=members * episodes)

    def update(self, member: int, episode: int, stopped: bool) -> None:
        self.done[member] = self.episodes if stopped else episode
        self.progress.update(self.task, completed=sum(self.done.values()))

    def on_step(self, trainer: Any, logs: Sequence[Any]) -> None:
        """A trainer's step callback: count the episodes its members ended."""
        for log in logs:
            self.update(log.member, log.episode, log.stopped)


class TrainingProgress(_Bars):
    """Two bars for one training run: episodes, and the steps of the current episode with its
    running mean reward and smoothed DTW (metres)."""

    def __init__(self, episodes: int, label: str, disable: bool = False, every: int = 10):
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
        )
        self.episodes = self.progress.add_task(label, total=episodes, info="episodes")
        self.steps = self.progress.add_task("episode 1", total=None, info="")

    def episode_done(self, episode: int, mean_reward: float, final_dtw: float) -> None:
        self.progress.update(
            self.episodes,
            completed=episode,
            info=f"episodes  last: reward {mean_reward:+.2f}, DTW {final_dtw:,.0f} m",
        )

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
