"""Handing freed memory back to the system before a command's peak.

A process's resident memory does not fall when it frees arrays: Arrow's allocator (mimalloc)
keeps what it freed for its next allocation, and so does glibc's heap, where numpy's arrays go
when they are smaller than glibc's mmap threshold (a threshold that rises, up to 32 MB, each time
a larger array is freed). Route clustering at 100 M rows came after stages that had freed
hundreds of MB this way, and its endpoint clustering freed 190 MB more before its unit vectors
were made: `hand_back` between them keeps that out of the command's peak."""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable

import pyarrow as pa


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's malloc_trim, or None where the C library is another (macOS, musl, Windows)."""
    try:
        return getattr(ctypes.CDLL(None), "malloc_trim", None)
    except (OSError, TypeError):
        return None


def hand_back() -> None:
    """Give the memory this process has freed back to the system: Arrow's pool, then glibc's
    heap (where there is glibc)."""
    pa.default_memory_pool().release_unused()
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
