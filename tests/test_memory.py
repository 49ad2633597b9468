"""Handing freed memory back before a peak (aisdati.memory), as route clustering does."""

from __future__ import annotations

import platform
from pathlib import Path

import numpy as np
import pytest

from aisdati.memory import hand_back

STATM = Path("/proc/self/statm")


def _resident_mib() -> float:
    return int(STATM.read_text().split()[1]) * 4096 / 2**20


@pytest.mark.skipif(
    not STATM.exists() or platform.libc_ver()[0] != "glibc", reason="glibc's heap on Linux"
)
def test_freed_heap_memory_goes_back_to_the_system():
    """300 MB of small arrays freed but for one in a thousand, which pins the heap's top: the
    process keeps them resident until `hand_back`."""
    arrays = [np.ones(128) for _ in range(300_000)]
    kept = arrays[::1000]
    del arrays
    held = _resident_mib()
    hand_back()
    assert held - _resident_mib() > 150
    assert all(float(a.sum()) == 128.0 for a in kept)  # what is still used stays whole
