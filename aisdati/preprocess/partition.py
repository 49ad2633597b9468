"""On-disk partitions by vessel: the bridge between streaming row-wise stages and per-vessel ones.

Cleaning and segmentation need all of a vessel's reports in time order, but a month of AIS does
not fit in memory. Rows that survive the row-wise filters are spilled to `n` Arrow IPC files by a
hash of their MMSI, so each file holds whole vessels and can be processed on its own (by this
process today, by a distributed engine mapping the same functions tomorrow).

One vessel can still send more rows than memory holds (a zip bomb of one MMSI). A partition of
more than `max_rows` rows is therefore split again, in passes over its file that each hold one
record batch (plus a few numbers per vessel, and a time histogram per large vessel: one pass to
count the vessels, one per 16 large ones to place their cuts, one to spill the pieces), into
pieces of at most a quarter of that (`PIECES_PER_BOUND`: a flood that overflows its partition
then costs well under the memory of a full one), given in (MMSI, time) order: whole vessels by
MMSI, and the history of a vessel with more rows than a piece holds cut at times. The per-vessel
stages see a vessel's reports on both sides of a gap longer than `gap_s` independently (its
track ends there, the outlier test and the derived speeds start anew, a stop cannot span it), so
where such gaps allow, the pieces give exactly the results of the whole partition. A vessel
reporting without such a gap for more than a piece's rows is cut anyway, at a time: its track
is split there. Reports at one and the same time are never split up; but a vessel cannot be at
two places at one time, and the cleaner keeps only the first of its reports at one time, so of a
flood at one time (a bin of more rows than a piece holds) only the first piece's worth is kept:
the rest are handed to the caller's `dropped` (counted as `same_time_flood`), and memory stays
bounded whatever the input.

Several writers may spill one partition (each input source its own `VesselPartitions`, in its
own task): `partition_tables` reads partition i from all their files, in the writers' order, as
if one writer had written them all.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
PIECES_PER_BOUND = 4
MAX_BINS = 1 << 18
"""Time bins of the histogram in which a large vessel's cuts are sought (2 MiB of counts; for two
months of reports, bins of 20 seconds)."""
HISTOGRAMS_PER_PASS = 16
"""Large vessels whose histograms one pass over a partition file builds (32 MiB at most)."""
Dropped = Callable[[pa.Table], None]
"""Where a large partition's reports beyond a piece's worth at one (MMSI, time) go."""


def partition_of(mmsi: np.ndarray, n: int) -> np.ndarray:
    """Partition index of each MMSI: a multiplicative hash, so neighbouring MMSIs (fleets are
    often numbered in sequence) spread over the partitions."""
    mixed = (mmsi.astype(np.uint64) * _GOLDEN) >> np.uint64(32)
    return (mixed % np.uint64(n)).astype(np.int64)


class VesselPartitions:
    """`n` spill files under `folder` (named `prefix-0000.arrow`, ...); `write` splits a table
    between them, iterating reads each back as one table (and deletes it), splitting those of
    more than `max_rows` rows into pieces in (MMSI, time) order (see the module docstring)."""

    def __init__(
        self,
        folder: Path,
        n: int,
        schema: pa.Schema,
        max_rows: int | None = None,
        gap_s: float = math.inf,
        prefix: str = "part",
    ) -> None:
        self.paths = [folder / f"{prefix}-{i:04d}.arrow" for i in range(n)]
        self.schema = schema
        self.max_rows = max_rows
        self.gap_s = gap_s
        self._writers: dict[int, pa.ipc.RecordBatchStreamWriter] = {}
        self._rows = np.zeros(n, dtype=np.int64)
        self.flooded = 0
        """Reports dropped by iterating: beyond a piece's worth of one vessel at one time."""

    def __len__(self) -> int:
        return len(self.paths)

    def write(self, table: pa.Table) -> None:
        if table.num_rows == 0:
            return
        part = partition_of(table.column("mmsi").to_numpy(), len(self.paths))
        for i, chunk in split_rows(table, part, len(self.paths)):
            self.append(i, chunk)

    def append(self, i: int, chunk: pa.Table) -> None:
        """Rows of partition `i` (`partition_of` their MMSIs), written after those before."""
        self._writer(i).write_table(chunk)
        self._rows[i] += chunk.num_rows

    def _writer(self, i: int) -> pa.ipc.RecordBatchStreamWriter:
        if i not in self._writers:
            self._writers[i] = pa.ipc.new_stream(str(self.paths[i]), self.schema)
        return self._writers[i]

    def close(self) -> None:
        for writer in self._writers.values():
            writer.close()

    @property
    def rows(self) -> np.ndarray:
        """Rows written to each partition."""
        return self._rows.copy()

    def __iter__(self) -> Iterator[pa.Table]:
        """Each partition as one table (or, when large, as pieces in (MMSI, time) order), in a
        fixed order (empty ones as empty tables); each file is deleted once read."""
        for i, path in enumerate(self.paths):
            paths = [path] if i in self._writers else []
            yield from partition_tables(
                paths, self.schema, int(self._rows[i]), self.max_rows, self.gap_s, self._flood
            )
            path.unlink(missing_ok=True)

    def _flood(self, rows: pa.Table) -> None:
        self.flooded += rows.num_rows


def partition_tables(
    paths: Sequence[Path],
    schema: pa.Schema,
    rows: int,
    max_rows: int | None = None,
    gap_s: float = math.inf,
    dropped: Dropped | None = None,
    pieces_as: str = "piece",
) -> Iterator[pa.Table]:
    """One partition, spilled to `paths` (in writing order; `rows` in all): as one table, or,
    holding more than `max_rows`, as pieces in (MMSI, time) order (see the module docstring),
    the reports of a flood at one time beyond a piece's worth handed to `dropped`, the pieces
    spilled as `<first path>-<pieces_as>-00000.arrow`, ... (two readers of one partition at
    once name them apart). The files are left in place, so that a task run again can read
    them again."""
    if not paths:
        yield schema.empty_table()
    elif max_rows is not None and rows > max_rows:
        gap_us = math.ceil(gap_s * 1e6) if math.isfinite(gap_s) else None
        piece_rows = max(max_rows // PIECES_PER_BOUND, 1)
        drop = dropped or (lambda _: None)
        yield from _pieces(paths, schema, piece_rows, gap_us, drop, pieces_as)
    else:
        tables = []
        for path in paths:
            with pa.OSFile(str(path)) as f:
                tables.append(pa.ipc.open_stream(f).read_all())
        joined = [pa.concat_tables(tables)]
        del tables  # (the caller alone holds the rows: it may free them before the next)
        yield joined.pop()


def _pieces(
    paths: Sequence[Path],
    schema: pa.Schema,
    piece_rows: int,
    gap_us: int | None,
    dropped: Dropped,
    pieces_as: str,
) -> Iterator[pa.Table]:
    """A large partition's pieces, spilled beside its first file, each read whole (and
    deleted) in turn; the reports of a flood at one time beyond a piece's worth to `dropped`."""
    plan = plan_pieces(paths, piece_rows, gap_us)
    first = paths[0]
    pieces = [first.with_name(f"{first.stem}-{pieces_as}-{k:05d}.arrow") for k in range(plan.count)]
    writers: dict[int, pa.ipc.RecordBatchStreamWriter] = {}
    cap = FloodCap(plan, piece_rows)
    for batch in _batches(paths):
        table = pa.Table.from_batches([batch])
        over = cap.over(table)
        if over.any():
            dropped(table.filter(pa.array(over)))
            table = table.filter(pa.array(~over))
        for k, chunk in split_rows(table, plan.piece_of(table), plan.count):
            if k not in writers:
                writers[k] = pa.ipc.new_stream(str(pieces[k]), schema)
            writers[k].write_table(chunk)
    for writer in writers.values():
        writer.close()
    for k in sorted(writers):
        with pa.OSFile(str(pieces[k])) as f:
            table = pa.ipc.open_stream(f).read_all()
        pieces[k].unlink()
        yield table


def write_split(table: pa.Table, which: np.ndarray, spills: Sequence[VesselPartitions]) -> None:
    """Each row of `table` into the partitions `spills[which[row]]` (-1: none of them), as
    `write` of each one's rows would put them, with one sort and one `take` for all: the read
    stage spills its moving and its slow reports (most of the rows) at once."""
    kept = np.flatnonzero(which >= 0)
    if not len(kept):
        return
    n = len(spills[0])
    key = which[kept] * n + partition_of(table.column("mmsi").to_numpy()[kept], n)
    sizes = np.bincount(key, minlength=n * len(spills))
    rows = table.take(pa.array(kept[_stable_order(key, n * len(spills))]))
    bounds = np.r_[0, np.cumsum(sizes)]
    for k in np.flatnonzero(sizes):
        spills[k // n].append(k % n, rows.slice(bounds[k], sizes[k]))


def _stable_order(part: np.ndarray, n: int) -> np.ndarray:
    """The stable order of part numbers 0 .. n - 1: for 16-bit ones a radix sort, linear."""
    return np.argsort(part.astype(np.int16) if n <= 1 << 15 else part, kind="stable")


def split_rows(table: pa.Table, part: np.ndarray, n: int) -> Iterator[tuple[int, pa.Table]]:
    """The rows of `table` by their part number (0 .. n - 1), each part in the table's order."""
    sizes = np.bincount(part, minlength=n)
    if len(part) and sizes.max() == len(part):  # one part (a small input's only one): as is
        yield int(part[0]), table
        return
    order = _stable_order(part, n)
    bounds = np.r_[0, np.cumsum(sizes)]
    table = table.take(pa.array(order))
    for i in np.flatnonzero(np.diff(bounds)):
        yield int(i), table.slice(bounds[i], bounds[i + 1] - bounds[i])


def _batches(paths: Sequence[Path]) -> Iterator[pa.RecordBatch]:
    """The record batches of a partition's files, in order."""
    for path in paths:
        with pa.OSFile(str(path)) as f:
            yield from pa.ipc.open_stream(f)


def _keys(batch: pa.RecordBatch | pa.Table) -> tuple[np.ndarray, np.ndarray]:
    """The MMSIs and times (microseconds) of a batch's rows."""
    mmsi = batch.column("mmsi").to_numpy()
    return mmsi, batch.column("time").to_numpy().view(np.int64)


@dataclass(frozen=True)
class PiecePlan:
    """Where a partition's rows go: `first_piece[v]` is the piece of the v-th of the sorted
    `mmsi`, and of a vessel with time cuts (`cuts[v]`, sorted) its first piece. `crowded[v]`:
    the vessel's time bins of more rows than a piece holds, where a flood at one time may be."""

    mmsi: np.ndarray
    first_piece: np.ndarray
    cuts: dict[int, np.ndarray]
    count: int
    crowded: dict[int, Crowded] = field(default_factory=dict)

    def piece_of(self, batch: pa.RecordBatch | pa.Table) -> np.ndarray:
        mmsi, time_us = _keys(batch)
        vessel = np.searchsorted(self.mmsi, mmsi)
        piece = self.first_piece[vessel]
        for v, cuts in self.cuts.items():
            rows = np.flatnonzero(vessel == v)
            piece[rows] += np.searchsorted(cuts, time_us[rows], side="right")
        return piece


def plan_pieces(paths: Sequence[Path], max_rows: int, gap_us: int | None) -> PiecePlan:
    """Pieces of at most about `max_rows` rows: vessels packed whole in MMSI order, and a vessel
    of more rows cut at times (`vessel_cuts`)."""
    mmsi, counts, first, last = _vessel_spans(paths)
    large = np.flatnonzero(counts > max_rows)
    cuts, crowded = time_cuts(paths, mmsi, first, last, large, max_rows, gap_us)
    first_piece = np.zeros(len(mmsi), dtype=np.int64)
    piece, rows = 0, 0
    for v in range(len(mmsi)):
        if rows and (v in cuts or rows + counts[v] > max_rows):
            piece, rows = piece + 1, 0
        first_piece[v] = piece
        if v in cuts:
            piece += len(cuts[v]) + 1
        else:
            rows += int(counts[v])
    return PiecePlan(mmsi, first_piece, cuts, piece + 1 if rows else piece, crowded)


def time_cuts(
    paths: Sequence[Path],
    mmsi: np.ndarray,
    first: np.ndarray,
    last: np.ndarray,
    large: np.ndarray,
    max_rows: int,
    gap_us: int | None,
) -> tuple[dict[int, np.ndarray], dict[int, Crowded]]:
    """The cut times (`vessel_cuts`) of each of the `large` vessels (indices into the sorted
    `mmsi`), from histograms of their times built `HISTOGRAMS_PER_PASS` at a time; and of those
    with bins of more than `max_rows` rows, the bins (`Crowded`)."""
    cuts: dict[int, np.ndarray] = {}
    crowded: dict[int, Crowded] = {}
    for start in range(0, len(large), HISTOGRAMS_PER_PASS):
        bins = {
            int(v): _Bins(int(first[v]), int(last[v]))
            for v in large[start : start + HISTOGRAMS_PER_PASS]
        }
        for batch in _batches(paths):
            ids, time_us = _keys(batch)
            vessel = np.searchsorted(mmsi, ids)
            for v, hist in bins.items():
                hist.add(time_us[vessel == v])
        cuts |= {v: vessel_cuts(hist, max_rows, gap_us) for v, hist in bins.items()}
        crowded |= {v: Crowded.of(hist, max_rows) for v, hist in bins.items()}
    return cuts, {v: c for v, c in crowded.items() if len(c.bins)}


def _vessel_spans(paths: Sequence[Path]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sorted MMSIs of a partition's files, and each one's row count, first and last time."""
    parts = []
    for batch in _batches(paths):
        parts.append(_spans(*_keys(batch), np.ones(batch.num_rows, dtype=np.int64)))
    mmsi, counts, first, last = (np.concatenate(a) for a in zip(*parts, strict=True))
    return _spans(mmsi, first, counts, last)


def _spans(
    mmsi: np.ndarray, first: np.ndarray, counts: np.ndarray, last: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows (or partial spans) grouped by MMSI: (MMSI, count, min first, max last)."""
    last = first if last is None else last
    order = np.argsort(mmsi, kind="stable")
    mmsi, first, last, counts = mmsi[order], first[order], last[order], counts[order]
    starts = np.flatnonzero(np.r_[True, mmsi[1:] != mmsi[:-1]])
    return (
        mmsi[starts],
        np.add.reduceat(counts, starts),
        np.minimum.reduceat(first, starts),
        np.maximum.reduceat(last, starts),
    )


class _Bins:
    """A histogram of one vessel's report times: `MAX_BINS` bins (or one per microsecond)."""

    def __init__(self, first_us: int, last_us: int) -> None:
        self.start = first_us
        self.width = max(1, math.ceil((last_us - first_us + 1) / MAX_BINS))
        self.counts = np.zeros((last_us - first_us) // self.width + 1, dtype=np.int64)

    def add(self, time_us: np.ndarray) -> None:
        self.counts += np.bincount((time_us - self.start) // self.width, minlength=len(self.counts))


@dataclass(frozen=True)
class Crowded:
    """A large vessel's time bins (`_Bins`) of more rows than a piece holds: only there can more
    than a piece's worth of its reports share one time."""

    start: int
    width: int
    bins: np.ndarray

    @classmethod
    def of(cls, hist: _Bins, max_rows: int) -> Crowded:
        return cls(hist.start, hist.width, np.flatnonzero(hist.counts > max_rows))

    def holds(self, time_us: np.ndarray) -> np.ndarray:
        return np.isin((time_us - self.start) // self.width, self.bins)


class FloodCap:
    """Which reports of a large partition, read in order, follow `cap` earlier ones of their
    vessel at their time: the cleaner would keep only the first, and a flood of them would make
    one unbounded piece. Counts are kept for the times in crowded bins only."""

    def __init__(self, plan: PiecePlan, cap: int) -> None:
        self.plan = plan
        self.cap = cap
        self.seen: Counter[tuple[int, int]] = Counter()

    def over(self, table: pa.Table) -> np.ndarray:
        """One flag per row of `table`: beyond the cap."""
        over = np.zeros(table.num_rows, dtype=bool)
        if not self.plan.crowded:
            return over
        mmsi, time_us = _keys(table)
        vessel = np.searchsorted(self.plan.mmsi, mmsi)
        for v, crowd in self.plan.crowded.items():
            rows = np.flatnonzero(vessel == v)
            rows = rows[crowd.holds(time_us[rows])]
            over[rows] = self._beyond(v, time_us[rows])
        return over

    def _beyond(self, v: int, time_us: np.ndarray) -> np.ndarray:
        """Of one vessel's reports (in order), those after `cap` others at their time, counting
        those of earlier batches."""
        times, inverse, counts = np.unique(time_us, return_inverse=True, return_counts=True)
        order = np.argsort(inverse, kind="stable")
        starts = np.r_[0, np.cumsum(counts)[:-1]]
        rank = np.empty(len(time_us), dtype=np.int64)
        rank[order] = np.arange(len(time_us)) - starts[inverse[order]]
        before = np.array([self.seen[(v, int(t))] for t in times], dtype=np.int64)
        for t, n in zip(times, counts, strict=True):
            self.seen[(v, int(t))] += int(n)
        return rank + before[inverse] >= self.cap


def vessel_cuts(bins: _Bins, max_rows: int, gap_us: int | None) -> np.ndarray:
    """Times at which to cut one vessel's history into pieces of at most about `max_rows` rows:
    in a gap longer than `gap_us` where one lies in reach (a bin boundary after enough empty bins
    that the reports on either side are more than `gap_us` apart), else at the last bin boundary
    in reach. A bin of more rows than `max_rows` is a piece of its own."""
    cum = np.r_[0, np.cumsum(bins.counts)]  # rows before each bin boundary
    n = len(bins.counts)
    safe = np.zeros(n + 1, dtype=bool)
    if gap_us is not None:
        need = math.ceil(gap_us / bins.width)  # empty bins before a boundary, for a safe cut
        busy = np.r_[0, np.cumsum(bins.counts > 0)]
        j = np.arange(need, n + 1)
        safe[j] = busy[j] == busy[j - need]
    safe_at = np.flatnonzero(safe)
    cuts, at = [], 0
    while cum[n] - cum[at] > max_rows:
        reach = int(np.searchsorted(cum, cum[at] + max_rows, side="right")) - 1
        k = int(np.searchsorted(safe_at, reach, side="right")) - 1
        cut = int(safe_at[k]) if k >= 0 and safe_at[k] > at else reach
        if cut <= at:  # the next bin alone holds more than max_rows
            cut = at + 1
        cuts.append(cut)
        at = cut
    return bins.start + np.asarray(cuts, dtype=np.int64) * bins.width
