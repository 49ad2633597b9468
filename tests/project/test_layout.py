"""The package's shape, checked: no module reads another's private names, imports flow one way
(the method in `aisdati.model` knows nothing of AIS, the self-test or the tool around it; the
numeric kernels know nothing of anything above them), and no function outside the command
line's option declarations is longer than a reader can hold (issue 25)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "aisdati"
MAX_FUNCTION_LINES = 80
KERNELS = {
    "aisdati.geo",
    "aisdati.dtw",
    "aisdati.coastline",
    "aisdati.inland_water",
    "aisdati.errors",
}
ABOVE_MODEL = (
    "aisdati.ais",
    "aisdati.selftest",
    "aisdati.detectors",
    "aisdati.detection",
    "aisdati.evaluation",
    "aisdati.commands",
    "aisdati.preprocess",
    "aisdati.cli",
)


def modules() -> dict[str, ast.Module]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = ast.parse(path.read_text(), filename=str(path))
    return out


def aisdati_imports(tree: ast.Module) -> list[tuple[str, list[str], int]]:
    """(module, imported names, line) of every `from aisdati... import` and `import aisdati...`,
    lazy ones inside functions included."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("aisdati"):
            found.append((node.module, [a.name for a in node.names], node.lineno))
        elif isinstance(node, ast.Import):
            found += [(a.name, [], node.lineno) for a in node.names if a.name.startswith("aisdati")]
    return found


def test_no_module_imports_another_modules_private_names():
    bad = [
        f"{mod}:{line} imports {name} from {src}"
        for mod, tree in modules().items()
        for src, names, line in aisdati_imports(tree)
        for name in names
        if name.startswith("_") and not name.startswith("__") and src != mod
    ]
    assert bad == []


def test_no_module_reads_a_private_attribute_of_an_imported_module():
    """`from aisdati import dtw; dtw._kernel(...)` is the same trespass by another door."""
    bad = []
    for mod, tree in modules().items():
        aliases = {
            (a.asname or a.name).split(".")[0]
            for node in ast.walk(tree)
            if isinstance(node, ast.Import | ast.ImportFrom)
            for a in node.names
            if (getattr(node, "module", None) or a.name).startswith("aisdati")
        }
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in aliases
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                bad.append(f"{mod}:{node.lineno} reads {node.value.id}.{node.attr}")
    assert bad == []


def test_the_method_is_domain_free_and_the_kernels_stand_alone():
    bad = []
    for mod, tree in modules().items():
        for src, _, line in aisdati_imports(tree):
            if mod.startswith("aisdati.model") and src.startswith(ABOVE_MODEL):
                bad.append(f"{mod}:{line} (the method) imports {src}")
            if mod in KERNELS and src not in KERNELS:
                bad.append(f"{mod}:{line} (a kernel) imports {src}")
    assert bad == []


def test_functions_are_short():
    long = []
    for mod, tree in modules().items():
        if mod == "aisdati.cli":  # Typer commands: option declarations and one call
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{mod}.{node.name}: {lines} lines")
    assert long == []
