"""What every benchmark leaves: its tables printed (markdown, or drawn by rich where the script
always drew one) and the same rows written as JSON beside the other benchmarks' results.

The convention, the same for every script: `--json PATH`, by default
`benchmarks/results/<script>.json` (e.g. `benchmarks/results/ais_speed.json`). The file is
written atomically (a temporary file in the same folder, then renamed) after every row and once
more at the end, so an interrupted run leaves the rows measured so far (`"finished": null`) and
never half a file. It holds the command, the options, the host, the lines printed around the
tables (`notes`) and each table: its columns and its rows as printed (`rows`, one object per
row, by column), with the unformatted measurements where the script gives them (`values`, one
object per row, in the same order).

Used by the scripts of this folder, run as scripts (`from report import Report, add_json_option`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import re
import sys
import tempfile
from collections.abc import Iterable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from types import TracebackType
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"
"""Where the JSON goes unless `--json` says otherwise (ignored by git)."""


def add_json_option(parser: argparse.ArgumentParser, name: str) -> None:
    """`--json PATH`, by default `benchmarks/results/<name>.json`."""
    parser.add_argument(
        "--json",
        type=Path,
        default=RESULTS / f"{name}.json",
        metavar="PATH",
        help=f"where the tables' rows go as JSON (default: benchmarks/results/{name}.json)",
    )


def plain(value: Any) -> Any:
    """`value` as JSON can hold it: numpy scalars as numbers, NaN and infinities as null, paths
    and anything else unknown as text."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [plain(v) for v in value]
    if hasattr(value, "item") and callable(value.item) and not isinstance(value, str | bytes):
        try:
            value = value.item()  # a numpy scalar
        except (TypeError, ValueError):
            return str(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, bool | int | str):
        return value
    return str(value)


_MARKUP = re.compile(r"\[/?[a-z#][^\]]*\]|\[/\]")


def _unmarked(text: str) -> str:
    """A rich cell without its markup (`[bold]x[/]` -> `x`)."""
    try:
        from rich.text import Text
    except ImportError:
        return _MARKUP.sub("", text)
    return Text.from_markup(text).plain


class Table:
    """One table of a `Report`. Markdown tables print their header at once and each row as it
    comes; rich tables print when `show` is called (or when the report closes)."""

    def __init__(
        self,
        report: Report,
        columns: Sequence[str],
        title: str | None,
        style: str,
        justify: Sequence[str] | None,
        width: int | None,
    ) -> None:
        if style not in ("markdown", "rich"):
            raise ValueError(f"style: markdown or rich, not {style!r}")
        self.report = report
        self.columns = [str(c) for c in columns]
        self.title = title
        self.style = style
        self.justify = list(justify) if justify else ["left"] * len(self.columns)
        self.width = width
        self.cells: list[list[str]] = []
        self.values: list[dict[str, Any] | None] = []
        self.shown = False
        if style == "markdown":
            print(_markdown_row(self.columns))
            print("|" + "---|" * len(self.columns), flush=True)

    def row(self, cells: Iterable[Any], values: dict[str, Any] | None = None) -> None:
        """Add (and for markdown print) one row: its cells as printed (`str` of each) and,
        optionally, its unformatted measurements for the JSON."""
        row = [str(c) for c in cells]
        if len(row) != len(self.columns):
            raise ValueError(f"{len(row)} cells for {len(self.columns)} columns")
        self.cells.append(row)
        self.values.append(values)
        if self.style == "markdown":
            print(_markdown_row(row), flush=True)
        self.report.write()

    def rows(self, rows: Iterable[Iterable[Any]]) -> None:
        for cells in rows:
            self.row(cells)

    def show(self) -> None:
        """Print a rich table (a plain one where rich is not installed); once."""
        if self.style != "rich" or self.shown:
            return
        self.shown = True
        try:
            from rich.console import Console
            from rich.table import Table as RichTable
        except ImportError:
            lines = [self.columns, *self.cells]
            widths = [max(len(r[k]) for r in lines) for k in range(len(self.columns))]
            for r in lines:
                print("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)))
            return
        table = RichTable(title=self.title)
        for name, side in zip(self.columns, self.justify, strict=True):
            table.add_column(name, justify=side)
        for r in self.cells:
            table.add_row(*r)
        Console(width=self.width).print(table)

    def as_json(self) -> dict[str, Any]:
        text = _unmarked if self.style == "rich" else str
        doc: dict[str, Any] = {
            "title": self.title,
            "columns": self.columns,
            "rows": [
                {c: text(v) for c, v in zip(self.columns, r, strict=True)} for r in self.cells
            ],
        }
        if any(v is not None for v in self.values):
            doc["values"] = [plain(v) if v is not None else None for v in self.values]
        return doc


class Report:
    """A benchmark's tables and notes, printed as they come and written to `path` as JSON.

    Use as a context manager: on leaving it, rich tables not yet shown are shown and the JSON is
    written with its finishing time (or, after an exception, the error and no finishing time).
    """

    def __init__(self, name: str, path: Path, options: dict[str, Any] | None = None) -> None:
        self.name = name
        self.path = Path(path)
        self.options = dict(options or {})
        self.started = _now()
        self.finished: str | None = None
        self.error: str | None = None
        self.notes: list[str] = []
        self.tables: list[Table] = []

    @classmethod
    def from_args(cls, name: str, args: argparse.Namespace) -> Report:
        """The report of a script whose parser has `add_json_option`."""
        options = {k: v for k, v in vars(args).items() if k != "json"}
        return cls(name, args.json, options)

    def say(self, text: str = "") -> None:
        """Print a line (as `print` does) and keep it among the notes."""
        print(text, flush=True)
        self.note(text)

    def note(self, text: str) -> None:
        """Keep a line among the notes without printing it."""
        if text.strip():
            self.notes.append(text.strip("\n"))

    def table(
        self,
        columns: Sequence[str],
        rows: Iterable[Iterable[Any]] = (),
        *,
        title: str | None = None,
        style: str = "markdown",
        justify: Sequence[str] | None = None,
        width: int | None = None,
    ) -> Table:
        """A new table (markdown: its header printed now); `rows`, if any, added at once."""
        table = Table(self, columns, title, style, justify, width)
        self.tables.append(table)
        table.rows(rows)
        return table

    def as_json(self) -> dict[str, Any]:
        return {
            "benchmark": self.name,
            "command": [Path(sys.executable).name, *sys.argv],
            "options": plain(self.options),
            "host": {
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "platform": platform.platform(),
            },
            "started": self.started,
            "finished": self.finished,
            **({"error": self.error} if self.error else {}),
            "notes": self.notes,
            "tables": [t.as_json() for t in self.tables],
        }

    def write(self) -> None:
        """Write the JSON atomically (a temporary file beside it, then renamed over it)."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(self.as_json(), indent=2, ensure_ascii=False, allow_nan=False)
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", dir=self.path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text + "\n")
            os.replace(tmp, self.path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    def __enter__(self) -> Report:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        _tb: TracebackType | None,
    ) -> None:
        if error is None:
            for table in self.tables:
                table.show()
            self.finished = _now()
        else:
            self.error = f"{kind.__name__}: {error}" if kind else str(error)
        self.write()
        if error is None:
            print(f"\n(rows written to {self.path})", file=sys.stderr)


def _markdown_row(cells: Sequence[str]) -> str:
    """`| a | b |`, an empty cell as `| |`."""
    return "|" + "|".join(f" {c} " if c else " " for c in cells) + "|"


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
