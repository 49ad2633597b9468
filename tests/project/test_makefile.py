"""The Makefile says what it installs system-wide before it installs it (issue 69, item 6)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("target, package", [("browser", "chromium"), ("postgres", "postgresql")])
def test_a_system_wide_install_is_announced_first(target, package):
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    recipe = subprocess.run(
        ["make", "-n", target], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout
    said = recipe.find(f"installing Debian's {package} system-wide")
    assert 0 <= said < recipe.find(f"apt-get install -y -qq {package}"), recipe
