"""Reading a model card's JSON field by field, each failure one line that names the field.

`ModelCard.from_dict` (`aisdati.ais.card`) reads every field through `CardFields`, so a card
edited by hand or damaged fails with `model card models/up.json: rule.max_sog_kn must be a
finite number > 0, got -3` instead of a traceback, or worse, a model that loads and flags other
tracks than it would.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from aisdati.errors import UserError

MISSING: Any = object()
"""`CardFields.get`'s default: the field is required."""


class CardFields:
    """Typed access to a card's fields by dotted path (`rule.max_sog_kn`); every failure is one
    `UserError` naming the card and the field."""

    def __init__(self, doc: Any, path: Path | str) -> None:
        self.doc = doc
        self.path = path

    def fail(self, field: str, rule: str, value: Any, shown: str | None = None) -> UserError:
        got = show(value) if shown is None else shown
        return UserError(f"model card {self.path}: {field} must be {rule}, got {got}")

    def get(self, field: str, default: Any = MISSING) -> Any:
        node = self.doc
        for part in field.split("."):
            if not isinstance(node, dict) or part not in node:
                if default is not MISSING:
                    return default
                raise UserError(f"model card {self.path}: {field} is missing")
            node = node[part]
        return node

    def number(
        self,
        field: str,
        low: float | None = None,
        high: float | None = None,
        low_open: bool = False,
        value: Any = MISSING,
    ) -> float:
        v = self.get(field) if value is MISSING else value
        rule = f"a finite number{_rule(low, high, low_open)}"
        if not is_number(v) or not math.isfinite(v):
            raise self.fail(field, rule, v)
        if low is not None and (v <= low if low_open else v < low):
            raise self.fail(field, rule, v)
        if high is not None and v > high:
            raise self.fail(field, rule, v)
        return float(v)

    def integer(
        self, field: str, low: int | None = None, high: int | None = None, value: Any = MISSING
    ) -> int:
        v = self.get(field) if value is MISSING else value
        if not isinstance(v, int) or isinstance(v, bool):
            raise self.fail(field, f"an integer{_rule(low, high)}", v)
        if (low is not None and v < low) or (high is not None and v > high):
            raise self.fail(field, f"an integer{_rule(low, high)}", v)
        return v

    def choice(self, field: str, allowed: Sequence[Any]) -> Any:
        v = self.get(field)
        if isinstance(v, bool) or v not in allowed:
            raise self.fail(field, "one of " + ", ".join(map(show, allowed)), v)
        return v

    def boolean(self, field: str) -> bool | None:
        """True, false, or None where the field is missing or null."""
        v = self.get(field, None)
        if v is not None and not isinstance(v, bool):
            raise self.fail(field, "true or false", v)
        return v

    def text(self, field: str) -> str:
        v = self.get(field)
        if not isinstance(v, str) or not v.strip():
            raise self.fail(field, "a non-empty string", v)
        return v

    def obj(self, field: str, default: Any = MISSING) -> Any:
        """A JSON object (dict), or `default` where the field is missing or null."""
        v = self.get(field, default)
        if v is None or v is default:
            return default
        if not isinstance(v, dict):
            raise self.fail(field, "an object", v)
        return v

    def array(
        self,
        field: str,
        length: int | None = None,
        min_length: int = 0,
        max_length: int | None = None,
    ) -> list[Any]:
        v = self.get(field)
        if not isinstance(v, list):
            raise self.fail(field, "a list", v)
        if length is not None and len(v) != length:
            raise self.fail(field, f"a list of {length}", v, f"{len(v)} items")
        if len(v) < min_length:
            raise self.fail(field, f"a list of at least {min_length}", v, f"{len(v)} items")
        if max_length is not None and len(v) > max_length:
            raise self.fail(field, f"a list of at most {max_length}", v, f"{len(v)} items")
        return v

    def interval(self, field: str, low: float, high: float) -> tuple[float, float]:
        pair = self.array(field, length=2)
        lo = self.number(f"{field}[0]", low, high, value=pair[0])
        hi = self.number(f"{field}[1]", low, high, value=pair[1])
        if not lo < hi:
            raise self.fail(field, "[low, high] with low < high", pair)
        return lo, hi


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _rule(low: float | None, high: float | None, low_open: bool = False) -> str:
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{_num(low)}, {_num(high)}]"
    if low is not None:
        return f" {'>' if low_open else '>='} {_num(low)}"
    if high is not None:
        return f" <= {_num(high)}"
    return ""


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def show(value: Any) -> str:
    """A value as an error message shows it: short, one line, no raw control characters."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # nan, inf, -inf
    if is_number(value):
        return _num(value)
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
