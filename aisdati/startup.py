"""The first thing `import aisdati` runs: in the `aisdati` console script, a Ctrl-C while the
command line is still importing (about half a second: Gymnasium, Typer, rich) exits 130 with
'interrupted' instead of a KeyboardInterrupt traceback; nothing has run yet that could need
cleaning up. Only os, signal and sys are imported here, so the guard is up within a millisecond
of the package's first line. A library user's `import aisdati` is left alone, and so is a SIGINT
inherited as ignored."""

from __future__ import annotations

import os
import signal
import sys
from typing import Any


def interrupted_while_starting(signum: int, frame: Any) -> None:
    os.write(2, b"interrupted\n")
    os._exit(130)


def guard_startup() -> None:
    script = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    if script.removesuffix(".exe") != "aisdati":
        return
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, interrupted_while_starting)


def end_startup_guard() -> None:
    """Give Ctrl-C back to Python (and so to click and `handle_termination`) once the command
    line has loaded."""
    if signal.getsignal(signal.SIGINT) is interrupted_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)
