"""Progress display for training: one rich bar over all members' episodes."""

from __future__ import annotations

from types import TracebackType

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


class EpisodeProgress:
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

    def __enter__(self) -> EpisodeProgress:
        self.progress.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.progress.stop()
