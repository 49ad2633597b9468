"""Checks of numeric options and lists of names, shared by every command, before any work.

`check_options` validates CLI numbers in one place: every float option must be finite (typer
reads `nan` and `inf` as floats, and NaN compares false with every bound, so a NaN threshold
would silently switch its filter off) and inside the range `OPTION_RANGES` gives it.
`parse_names` reads a comma-separated list of names against the known ones; `parse_time` a
date or ISO 8601 time.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

import pandas as pd

from aisdati.errors import UserError


# ------------------------------------------------------------------------------ lists of names
def parse_names(text: str | Iterable[str], known: Iterable[str], what: str) -> tuple[str, ...]:
    """'a,b' (or several such strings) -> ('a', 'b'), lower-cased, without repeats; none, or a
    name not in `known`, is a one-line `UserError` that lists the choices (`what`: "method",
    "detector", ...)."""
    known = list(known)
    items = [text] if isinstance(text, str) else list(text)
    names = tuple(
        dict.fromkeys(n.strip().lower() for t in items for n in t.split(",") if n.strip())
    )
    if not names:
        raise UserError(f"no {what} given; choose from {', '.join(known)}")
    for name in names:
        if name not in known:
            raise UserError(f"unknown {what} {name!r}; choose from {', '.join(known)}")
    return names


# ------------------------------------------------------------------------------ times
ISO_TIME = (
    r"\d{4}-\d{2}-\d{2}"  # the date
    r"(?:[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?)?"  # a time of day
    r"(?:Z|[+-]\d{2}(?::?\d{2})?)?"  # a zone
)
"""What a time given by a user may be: ISO 8601, date first, nothing else. Looser parsing read
`07/08/2018` month-first in one place and day-first in the next, and took `now` as a time."""


def parse_time(text: str, option: str) -> pd.Timestamp:
    """'2018-08-01', '2018-08-01T06:30', '2018-08-01 06:30:00+02:00' -> that instant in UTC (UTC
    unless a zone is given); anything else is a one-line `UserError` naming `option`."""
    stamp = text.strip()
    try:
        time = pd.Timestamp(stamp) if re.fullmatch(ISO_TIME, stamp) else pd.NaT
    except ValueError:  # 2018-13-01, 2018-02-30
        time = pd.NaT
    if pd.isna(time):
        raise UserError(
            f"{option} {text!r}: expected a date or an ISO 8601 time such as 2018-08-01 or "
            "2018-08-01T06:30 (UTC unless a zone is given)"
        )
    return time.tz_localize("UTC") if time.tzinfo is None else time.tz_convert("UTC")


# ------------------------------------------------------------------------------ numeric options
@dataclass(frozen=True)
class Range:
    """Allowed values of a numeric option: finite, and within (or at) the bounds given."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def accepts(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            return False
        return not (
            self.high is not None and (value >= self.high if self.high_open else value > self.high)
        )

    def describe(self) -> str:
        if self.low is not None and self.high is not None:
            left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
            return f"in {left}{_fmt(self.low)}, {_fmt(self.high)}{right}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {_fmt(self.low)}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {_fmt(self.high)}"
        return ""


def _fmt(x: float) -> str:
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    if float(x).is_integer() and abs(x) < 1e15:
        return str(int(x))
    return f"{x:g}"


SEED_MAX = 2**32 - 1
OPTION_RANGES: dict[str, Range] = {
    # ingest
    "--min-sog": Range(high=102.2, high_open=True),  # negative: keep every SOG, even 0
    "--max-speed": Range(low=0.0, low_open=True),
    "--stop-gap": Range(low=0.0, low_open=True, high=365 * 86400.0),  # seconds
    "--dwell-time": Range(low=0.0, high=365 * 86400.0),  # seconds; 0: no dwell stops
    "--dwell-radius": Range(low=0.0, low_open=True, high=100_000.0),  # metres
    "--route-eps-km": Range(low=0.0, low_open=True, high=20_037.5),
    # detect
    "--threshold": Range(low=0.0, low_open=True, high=1.0),
    "--top-percent": Range(low=0.0, low_open=True, high=100.0),
    "--near-km": Range(low=0.0, low_open=True, high=20_037.5),  # half the Earth's circumference
    "--lane-course-km": Range(low=0.0, high=1000.0),
    "--contamination": Range(low=0.0, low_open=True, high=1.0, high_open=True),
    # evaluate
    "--train-fraction": Range(low=0.1, high=0.9),
    # integers that reach a random generator (numpy refuses negative seeds, torch huge ones)
    "--seed": Range(low=0, high=SEED_MAX),
    "--route-seed": Range(low=0, high=SEED_MAX),
    "--routes-per-task": Range(low=0),
}
"""Every numeric option that needs more than its type, with its allowed range. Floats are always
checked for finiteness, ranged or not."""


def check_option(name: str, value: float | None) -> None:
    """Raise a one-line `UserError` unless `value` is finite and in the range of `name` (None, an
    option left unset, passes)."""
    if value is None:
        return
    allowed = OPTION_RANGES.get(name, Range())
    if not allowed.accepts(float(value)):
        kind = "an integer" if isinstance(value, int) else "a finite number"
        rule = allowed.describe()
        raise UserError(f"{name} must be {kind}{' ' + rule if rule else ''}, got {_fmt(value)}")


def check_options(values: dict[str, float | None]) -> None:
    """`check_option` for each (option name, value): call it first thing in a command."""
    for name, value in values.items():
        check_option(name, value)
