"""Eight bytes at a time: the compiled bit tricks the CSV scans share (`fastcsv`, `lineguard`).

A block's bytes are read as little-endian 64-bit words; a *mask* has the high bit of each byte
that matched and no other bit, so masks combine with `&`, `|` and shifts by whole bytes, and a
scan passes over eight bytes with a few integer operations instead of eight branches."""

from __future__ import annotations

import numba
import numpy as np

LOW7 = np.uint64(0x7F7F7F7F7F7F7F7F)
HIGH = np.uint64(0x8080808080808080)
ONES = np.uint64(0x0101010101010101)


def each(byte: int) -> np.uint64:
    """A word of eight copies of `byte`, for `equal`."""
    return np.uint64(0x0101010101010101 * byte)


@numba.njit(nogil=True, cache=True, inline="always")
def equal(word, copies):  # pragma: no cover - compiled
    """The mask of the bytes of `word` equal to the byte of `copies` (`each`). Exact: no borrow
    runs from one byte into the next, as in the shorter test for *any* equal byte."""
    y = word ^ copies
    return ~(((y & LOW7) + LOW7) | y | LOW7)


@numba.njit(nogil=True, cache=True, inline="always")
def count(mask):  # pragma: no cover - compiled
    """How many bytes a mask has set."""
    return np.int64(((mask >> np.uint64(7)) * ONES) >> np.uint64(56))


@numba.njit(nogil=True, cache=True, inline="always")
def below_first(mask):  # pragma: no cover - compiled
    """The bits below the lowest set one of `mask` (all 64 where it is 0): `count` of it with
    `HIGH` is how many bytes come before the first match (8 where there is none)."""
    return (mask & (~mask + np.uint64(1))) - np.uint64(1)


@numba.njit(nogil=True, cache=True, inline="always")
def word_at(words, i):  # pragma: no cover - compiled
    """The eight bytes at offset `i` as one word, from the two aligned `words` they span (for
    `i` a multiple of 8 the second shifts out whole); `words[i // 8 + 1]` must exist."""
    shift = np.uint64(8 * (i % 8))
    low = words[i // 8] >> shift
    return low | ((words[i // 8 + 1] << np.uint64(1)) << (np.uint64(63) - shift))
