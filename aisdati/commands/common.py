"""What every command shares: the two consoles, the one way a failure reaches the user (a red
line and an exit code, never a traceback), warnings, and the lane settings of train and evaluate.
"""

from __future__ import annotations

import contextlib
import errno
import functools
from collections.abc import Callable
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape

from aisdati.errors import UserError
from aisdati.interrupts import Terminated, handle_termination, raise_if_interrupted

console = Console()
err_console = Console(stderr=True)

FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
"""A disk or quota full: one line and exit code 1, wherever it struck (numpy, pyarrow and torch
raise it without a file name)."""
PATH_ERRNOS = (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.ENOENT)
"""A file system refusing a path the user gave: exit code 2 (a user mistake) rather than 1."""

EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


def user_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Turn `UserError` (and Ctrl-C, SIGTERM, a file system refusing a path) into a one-line
    message and a non-zero exit code: 2 for user mistakes, 130 / 143 for SIGINT / SIGTERM."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            with handle_termination():
                result = func(*args, **kwargs)
                raise_if_interrupted()  # a Ctrl-C swallowed where nothing was left to commit
                return result
        except UserError as exc:
            error(str(exc))
            raise typer.Exit(2) from None
        except Terminated:
            err_console.print("[yellow]terminated[/]")
            raise typer.Exit(EXIT_TERMINATED) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/]")
            raise typer.Exit(EXIT_INTERRUPTED) from None
        except OSError as exc:  # disk full, permissions changed mid-run: one line, no traceback
            if exc.errno in FULL_ERRNOS:
                where = f"{exc.filename}: " if exc.filename else ""
                error(f"{where}{exc.strerror or 'No space left on device'}")
                raise typer.Exit(1) from None
            if exc.filename is None:
                raise
            error(f"{exc.filename}: {exc.strerror or type(exc).__name__}")
            raise typer.Exit(2 if exc.errno in PATH_ERRNOS else 1) from None

    return wrapper


def error(message: str) -> None:
    """One red line on stderr (a message may hold [brackets]: printed as text, not markup)."""
    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)


def warn(message: str) -> None:
    """One yellow line on stderr: something the operator should know, not an error."""
    err_console.print(f"[yellow]warning:[/] {escape(message)}", highlight=False, soft_wrap=True)


def shows_progress(as_json: bool) -> bool:
    """Progress unless --json, whose output is the JSON alone (at a terminal as bars; into a
    log, the bars' plain lines; the rich widgets that cannot print plainly, spinners and the
    download bars, show at a terminal only)."""
    return not as_json


def spinner(where: Console, text: str, show: bool = True) -> contextlib.AbstractContextManager:
    """A rich spinner with `text` on `where` while the block runs; nothing when not `show`."""
    return where.status(text, spinner="dots") if show else contextlib.nullcontext()


def default_method(method: str | None, cluster: str) -> str:
    """`--method`, else the area's detector for a whole area (`--cluster all`:
    `aisdati.ais.AREA_METHOD`) and the paper's DATI for a cluster or route."""
    from aisdati.ais import AREA_METHOD, DEFAULT_METHOD
    from aisdati.tracks.schema import AREA

    if method is not None:
        return method
    return AREA_METHOD if cluster.strip().lower() == AREA else DEFAULT_METHOD


def lane_settings(preset: str | None, lane: list[str] | None, cluster: str) -> dict[str, Any]:
    """The `preset` (its name and overrides, for the model card) and `lane` (the resolved
    LaneConfig) of the train and evaluate settings, from --preset and --lane; without
    --preset, the area preset for a whole area (`--cluster all`), else the default."""
    from aisdati.ais import AREA_PRESET, DEFAULT_PRESET
    from aisdati.ais.space import lane_config  # here: cli.py imports this module for --help
    from aisdati.tracks.schema import AREA

    if preset is None:
        preset = AREA_PRESET if cluster.strip().lower() == AREA else DEFAULT_PRESET
    name = preset if not lane else f"{preset} + {', '.join(lane)}"
    return {"preset": name, "lane": lane_config(preset, lane or ())}
