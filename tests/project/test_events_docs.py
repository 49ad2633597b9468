"""docs/detectors.md defines every event kind as the code does (`aisdati.events.kinds`)."""

from __future__ import annotations

from pathlib import Path

from aisdati.events.kinds import KINDS

DETECTORS = Path(__file__).resolve().parents[2] / "docs" / "detectors.md"


def test_every_kind_is_defined_in_the_docs_as_in_the_code():
    text = DETECTORS.read_text()
    for kind in KINDS.values():
        assert f"| `{kind.name}` |" in text
        assert kind.definition in text, kind.name
