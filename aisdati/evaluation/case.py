"""One constructed case (`aisdati.evaluation.constructed`): what should find it, apart from
the registry of constructors, so that a constructor's module can read it without importing the
registry that imports it."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd


@dataclass(frozen=True)
class Case:
    """One constructed case: the kind that should find it, the vessels it must name, and the
    time it spans (UTC)."""

    kind: str
    mmsis: tuple[int, ...]
    start: pd.Timestamp
    end: pd.Timestamp
    coverage: str | None = None
    """A gap's expected coverage ("heard", "quiet"; `aisdati.events.coverage`): found only by
    a gap that says so; None: not judged."""
