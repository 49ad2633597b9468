"""From per-report evidence to stretches: runs of reports that meet a condition, and the
stretches where evidence accumulates (a one-sided CUSUM, Page 1954), so that many moderately
surprising reports in a row stand out where no single one does."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np


@dataclass(frozen=True)
class Found:
    """An event of one vessel before it is placed: its kind, its reports [start, end] (indices
    into the vessel's reports, inclusive), the report where it is strongest, how strongly it
    exceeds its threshold (1 = at it) and its evidence in words."""

    kind: str
    start: int
    end: int
    peak: int
    strength: float
    evidence: str


def merged(found: list[Found]) -> list[Found]:
    """One kind's events of one vessel with the overlapping ones merged into one: its reports
    the union, its peak, strength and evidence the strongest's (one event per thing). Two that
    share only an end report (a gap and the next) do not overlap in time."""
    out: list[Found] = []
    for e in sorted(found, key=lambda e: (e.start, e.end)):
        if out and e.start < out[-1].end:
            last = out[-1]
            strong = e if e.strength > last.strength else last
            out[-1] = Found(
                e.kind, last.start, max(last.end, e.end), strong.peak, strong.strength,
                strong.evidence,
            )  # fmt: skip
        else:
            out.append(e)
    return out


def deviation_stretch(profile: np.ndarray) -> tuple[int, int]:
    """The contiguous stretch around a profile's peak where it stays above half the peak: where
    the track strays most, as an index range [start, end)."""
    k = int(np.argmax(profile))
    above = profile >= profile[k] / 2
    a = k
    while a > 0 and above[a - 1]:
        a -= 1
    b = k + 1
    while b < len(profile) and above[b]:
        b += 1
    return a, b


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """The [start, end] (inclusive) of each run of True in `mask`."""
    m = np.asarray(mask, dtype=np.int8)
    edges = np.diff(np.concatenate([[0], m, [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))


def cusum_stretches(x: np.ndarray, drift: float, limit: float) -> list[tuple[int, int, float]]:
    """Stretches where the CUSUM S_i = max(0, S_{i-1} + x_i - drift) exceeds `limit`: each from
    where S last left zero to its peak, with the peak value; S starts again after each."""
    starts, ends, peaks = _cusum(np.asarray(x, np.float64), float(drift), float(limit))
    return list(zip(starts.tolist(), ends.tolist(), peaks.tolist(), strict=True))


@numba.njit(cache=True)
def _cusum(x, drift, limit):  # pragma: no cover - compiled
    n = x.shape[0]
    starts = np.empty(n, np.int64)
    ends = np.empty(n, np.int64)
    peaks = np.empty(n, np.float64)
    found = 0
    s = 0.0
    start = 0
    best = 0.0
    best_at = -1
    for i in range(n):
        if s == 0.0:
            start = i
        s = max(0.0, s + x[i] - drift)
        if s > best:
            best = s
            best_at = i
        if s == 0.0 or i == n - 1:
            if best > limit:
                starts[found] = start
                ends[found] = best_at
                peaks[found] = best
                found += 1
            best = 0.0
            best_at = -1
    return starts[:found], ends[:found], peaks[:found]
