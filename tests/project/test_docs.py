"""The documentation: the site builds without a warning or a broken link, and the README stays a
short manual whose links all lead somewhere."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
README_MAX_LINES = 200
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
"""An inline markdown link or image: [text](target) or ![alt](target "title")."""


def relative_links(markdown: str) -> list[str]:
    """The targets of the inline links that point into the repository (no URL, no bare anchor),
    without their #fragment."""
    targets = [m.group(1) for m in LINK.finditer(markdown)]
    return [
        t.split("#", 1)[0]
        for t in targets
        if not re.match(r"^[a-z][a-z0-9+.-]*:", t, re.IGNORECASE) and not t.startswith("#")
    ]


def test_site_builds_strict(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs", reason="mkdocs is not installed: pip install -e '.[dev]'")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    site = tmp_path / "site"
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)]
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    log = done.stdout + done.stderr
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{log}"
    assert "WARNING" not in log, log
    assert (site / "index.html").is_file()
    assert (site / "api" / "index.html").is_file()


def test_readme_is_short() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines"


def test_readme_links_resolve() -> None:
    links = relative_links(README.read_text(encoding="utf-8"))
    assert links, "README.md links to nothing in the repository"
    missing = [t for t in links if not (ROOT / t).is_file()]
    assert not missing, f"README.md links to files that do not exist: {missing}"


def test_relative_links_ignores_urls_and_anchors() -> None:
    text = "[a](docs/x.md#part) ![b](docs/p.png) [c](https://x.org) [d](#top) [e](mailto:a@b)"
    assert relative_links(text) == ["docs/x.md", "docs/p.png"]
