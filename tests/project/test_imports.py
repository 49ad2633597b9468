"""No two packages of aisdati import each other, directly or through others: each concept sits in
one place and the layers read one way (the detection <-> evaluation cycle is gone: their shared
metrics are `aisdati.metrics`, the events they share are `aisdati.detection.events`)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "aisdati"


def package_imports() -> dict[str, set[str]]:
    """Subpackage -> the other subpackages its modules import (at any depth of the module)."""
    graph: dict[str, set[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).parts
        if len(parts) < 2:
            continue
        mine = parts[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("aisdati."):
                other = node.module.split(".")[1]
                if other != mine and (PACKAGE / other).is_dir():
                    graph.setdefault(mine, set()).add(other)
    return graph


def cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of `graph`, or None."""
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt] if nxt in path else [node, nxt]
            if nxt not in state and (found := visit(nxt, [*path, nxt])):
                return found
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start, [start])):
            return found
    return None


def test_no_package_imports_itself_through_others():
    assert cycle(package_imports()) is None, " -> ".join(cycle(package_imports()) or [])


def test_the_cycle_check_finds_one():
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle({"a": {"b"}, "b": set()}) is None
