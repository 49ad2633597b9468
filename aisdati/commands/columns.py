"""Tables that fit the terminal with every figure whole.

Rich shrinks a table to the console's width by folding its cells anywhere, so at 80 columns (a
pipe, a log, a narrow terminal) an MMSI came out as "10000" over "1468" and a kind as
"positi/on-jum/p". Here a column is either a figure (an MMSI, a time, a coordinate pair, a
number: never wrapped) or free text (names, evidence, lists of kinds, a value and its interval:
wrapped at spaces, each word whole), and a table that cannot hold its figures whole at the width
leaves out whole columns, in an order its builder states, instead of cutting any.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from rich import box
from rich.table import Table
from rich.text import Text

GAP = 2
"""Characters between two columns (`box.SIMPLE_HEAD`, padding collapsed, no outer edge)."""
LONGEST_WORD = 24
"""A free-text column need not be wider than this: a longer word (a long name) folds."""


@dataclass(frozen=True)
class Column:
    """A column of a fitted table: its header, its cells (`Text`: styled, never read as markup)
    and whether it is free text (`wraps`) or figures."""

    header: str
    cells: Sequence[Text]
    right: bool = False
    wraps: bool = False
    min_width: int = field(init=False)
    """The narrowest it can be: a figure column its widest cell and header, a free-text column
    its longest word (at most `LONGEST_WORD`)."""
    max_width: int = field(init=False)
    """The widest it needs: its widest line, header included."""

    def __post_init__(self) -> None:
        lines = [line for t in self.cells for line in t.plain.splitlines()]
        widest = max(map(len, [self.header, *lines]))
        if self.wraps:
            words = [w for line in [self.header, *lines] for w in line.split()]
            narrowest = min(LONGEST_WORD, max(map(len, words), default=1))
        else:
            narrowest = widest
        object.__setattr__(self, "min_width", narrowest)
        object.__setattr__(self, "max_width", widest)


def width_needed(columns: Sequence[Column]) -> int:
    """The narrowest a table of these columns can be."""
    return sum(c.min_width for c in columns) + GAP * max(0, len(columns) - 1)


def fitted(
    columns: Sequence[Column], width: int, drop_order: Sequence[str]
) -> tuple[list[Column], list[str]]:
    """The columns that fit `width` with every figure whole: those named in `drop_order` left
    out, in that order, until the rest fit; and the headers left out."""
    kept, dropped = list(columns), []
    for name in drop_order:
        if width_needed(kept) <= width:
            break
        if any(c.header == name for c in kept):
            kept = [c for c in kept if c.header != name]
            dropped.append(name)
    return kept, dropped


def widths(columns: Sequence[Column], width: int) -> list[int]:
    """Each column's width: a figure column its own; the free-text columns share what is left
    of `width`, each at least its longest word and at most its widest line. Given whole to rich,
    which otherwise shrinks a table by its own rules and cut figures doing so."""
    out = [c.min_width for c in columns]
    spare = width - width_needed(columns)
    while spare > 0:
        short = [k for k, c in enumerate(columns) if out[k] < c.max_width]
        if not short:
            break
        for k in short[:spare]:
            out[k] += 1
        spare -= min(spare, len(short))
    return out


def fitted_table(
    title: str, columns: Sequence[Column], width: int, drop_order: Sequence[str] = ()
) -> Table:
    """A rich table of the columns that fit `width` (`fitted`); its caption names the columns
    left out. Figures never wrap; free text wraps at spaces (a word is folded only where it is
    wider than `LONGEST_WORD`)."""
    kept, dropped = fitted(columns, width, drop_order)
    table = Table(
        title=title, box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True, show_edge=False
    )
    for c, given in zip(kept, widths(kept, width), strict=True):
        table.add_column(
            c.header,
            justify="right" if c.right else "left",
            no_wrap=not c.wraps,
            overflow="fold",
            width=given,
        )
    for row in zip(*(c.cells for c in kept), strict=True):
        table.add_row(*row)
    if dropped:
        table.caption = f"left out at {width} columns: {', '.join(dropped)}"
    return table
