"""On-disk partitions by vessel: the bridge between streaming row-wise stages and per-vessel ones.

Cleaning and segmentation need all of a vessel's reports in time order, but a month of AIS does
not fit in memory. Rows that survive the row-wise filters are spilled to `n` Arrow IPC files by a
hash of their MMSI, so each file holds whole vessels and can be processed on its own (by this
process today, by a distributed engine mapping the same functions tomorrow).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def partition_of(mmsi: np.ndarray, n: int) -> np.ndarray:
    """Partition index of each MMSI: a multiplicative hash, so neighbouring MMSIs (fleets are
    often numbered in sequence) spread over the partitions."""
    mixed = (mmsi.astype(np.uint64) * _GOLDEN) >> np.uint64(32)
    return (mixed % np.uint64(n)).astype(np.int64)


class VesselPartitions:
    """`n` spill files under `folder`; `write` splits a table between them, iterating reads each
    back as one table (and deletes it)."""

    def __init__(self, folder: Path, n: int, schema: pa.Schema) -> None:
        self.paths = [folder / f"part-{i:04d}.arrow" for i in range(n)]
        self.schema = schema
        self._writers: dict[int, pa.ipc.RecordBatchStreamWriter] = {}

    def __len__(self) -> int:
        return len(self.paths)

    def write(self, table: pa.Table) -> None:
        if table.num_rows == 0:
            return
        part = partition_of(table.column("mmsi").to_numpy(), len(self.paths))
        order = np.argsort(part, kind="stable")
        bounds = np.r_[0, np.cumsum(np.bincount(part, minlength=len(self.paths)))]
        table = table.take(pa.array(order))
        for i in np.flatnonzero(np.diff(bounds)):
            chunk = table.slice(bounds[i], bounds[i + 1] - bounds[i])
            self._writer(int(i)).write_table(chunk)

    def _writer(self, i: int) -> pa.ipc.RecordBatchStreamWriter:
        if i not in self._writers:
            self._writers[i] = pa.ipc.new_stream(str(self.paths[i]), self.schema)
        return self._writers[i]

    def close(self) -> None:
        for writer in self._writers.values():
            writer.close()

    def __iter__(self) -> Iterator[pa.Table]:
        """Each partition as one table, in a fixed order (empty ones as empty tables)."""
        for i, path in enumerate(self.paths):
            if i not in self._writers:
                yield self.schema.empty_table()
                continue
            with pa.OSFile(str(path)) as f:
                table = pa.ipc.open_stream(f).read_all()
            path.unlink()
            yield table
