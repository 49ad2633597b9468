"""Ctrl-C and SIGTERM: both stop a run the same way, and neither lets it commit its outputs.

* `handle_termination` makes SIGTERM behave like Ctrl-C (the same clean-up runs), and ignores
  a second SIGTERM while that clean-up is under way.
* `raise_if_interrupted`, called before every output is committed, raises again a signal whose
  exception a C callback swallowed.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterator
from typing import Any


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C's KeyboardInterrupt so that the same clean-up runs."""


_PENDING: list[type[KeyboardInterrupt]] = []
"""Signals received in `handle_termination`'s block, in case their exception was swallowed."""


def raise_if_interrupted() -> None:
    """Raise a signal's exception again before an output is committed. Python raises a signal's
    exception in whatever code runs when it arrives; inside a C callback (numba compiling a
    function calls back into Python) it is printed as "Exception ignored" and lost, and the run
    would go on to write complete-looking outputs and exit 0 after a Ctrl-C."""
    if _PENDING:
        raise _PENDING[0]()


@contextlib.contextmanager
def handle_termination() -> Iterator[None]:
    """While the block runs, SIGTERM raises `Terminated` (once: a second SIGTERM during the
    clean-up is ignored) and both it and Ctrl-C are remembered for `raise_if_interrupted`.
    Outside the main thread this does nothing (signals cannot be set); a SIGINT that the
    process inherited as ignored (nohup) stays ignored."""

    def on_term(signum: int, frame: Any) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        _PENDING.append(Terminated)
        raise Terminated()

    def on_int(signum: int, frame: Any) -> None:
        _PENDING.append(KeyboardInterrupt)
        raise KeyboardInterrupt()

    try:
        previous = signal.signal(signal.SIGTERM, on_term)
    except ValueError:  # not the main thread
        yield
        return
    before = signal.getsignal(signal.SIGINT)
    if before is signal.default_int_handler:
        signal.signal(signal.SIGINT, on_int)
    hook = sys.unraisablehook

    def quiet(unraisable: Any) -> None:  # a swallowed signal: remembered, so no traceback
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            hook(unraisable)

    sys.unraisablehook = quiet
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, before)
        sys.unraisablehook = hook
        _PENDING.clear()

