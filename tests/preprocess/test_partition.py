"""Partitions by vessel (`aisdati.preprocess.partition`) on the real Kitimat reports: a large
partition split by time gives the same outputs, a vessel without gaps is cut into bounded
pieces in time order, many vessels pack into pieces in MMSI order (issue 27, item 18)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import aisdati.preprocess.partition as partition
import aisdati.preprocess.pipeline as pipeline
from aisdati.preprocess.convert import PARTITION_SCHEMA, to_canonical
from aisdati.preprocess.inputs import Source
from aisdati.preprocess.read import open_reader
from aisdati.preprocess.settings import IngestSettings

KITIMAT = "AIS_2018_07-08_Kitimat.csv.gz"


# ----------------------------------------- 18: one vessel's partition split by time, bounded
def test_a_large_partition_split_by_time_gives_the_same_outputs(data, tmp_path, monkeypatch):
    """Kitimat in one partition, read whole and split into pieces of 3,000 rows (one vessel
    cut at a time, in a gap): the points, tracks, reports and counts are the same."""
    monkeypatch.setattr(pipeline, "MAX_PARTITIONS", 1)
    plans, plan_pieces = [], partition.plan_pieces

    def spy(*args):
        plans.append(plan_pieces(*args))
        return plans[-1]

    monkeypatch.setattr(partition, "plan_pieces", spy)
    outs = {}
    for rows in (2_000_000, 12_000):  # split: pieces of 3,000
        out = tmp_path / f"rows-{rows}"
        settings = IngestSettings(min_points=100, rows_per_bucket=rows)
        result = pipeline.ingest([data / KITIMAT], out, settings, None, "none")
        outs[rows] = (out, result.counts.as_dict())
    (whole, counts), (split, split_counts) = outs.values()
    assert len(plans) == 2  # the tracks' (moving reports) and reports.parquet's (all reports)
    # vessels packed into pieces, and one cut at times
    assert all(plan.count > 10 for plan in plans) and any(plan.cuts for plan in plans)
    assert split_counts == counts
    for name in ("points.parquet", "tracks.parquet", "reports.parquet"):
        got, want = (pq.read_table(out / name).to_pandas() for out in (split, whole))
        assert got.equals(want), name  # (pandas: a NaN heading equals NaN)


def _kitimat_rows(data: Path) -> pa.Table:
    reader = open_reader(Source(data / KITIMAT))
    tables = [to_canonical(b, reader.columns, 0, reader.time_format)[0] for b in reader.batches()]
    return pa.concat_tables(tables)


def test_a_vessel_without_gaps_is_cut_into_bounded_time_ordered_pieces(data, tmp_path):
    """The busiest Kitimat vessel's reports, with every gap closed up to a minute: no safe cut
    anywhere, so the pieces are cut at times; each is bounded, and together, in order, they
    are the vessel's reports sorted by time (reports at one time never split up)."""
    rows = _kitimat_rows(data)
    mmsi = rows.column("mmsi").to_numpy()
    busiest = np.bincount(mmsi - mmsi.min()).argmax() + mmsi.min()
    vessel = rows.filter(pa.array(mmsi == busiest))
    time_us = np.sort(vessel.column("time").to_numpy().view(np.int64))
    steps = np.minimum(np.diff(time_us), 60_000_000)
    closed = time_us[0] + np.r_[0, np.cumsum(steps)]
    shuffled = np.random.default_rng(27).permutation(len(closed))  # spilled out of order
    at = PARTITION_SCHEMA.get_field_index("time")
    vessel = vessel.set_column(
        at, "time", pa.array(closed[shuffled]).view(PARTITION_SCHEMA.field("time").type)
    )
    bound = len(vessel) // 2  # pieces of a quarter of that: about 8
    parts = partition.VesselPartitions(tmp_path, 1, PARTITION_SCHEMA, bound, 3600.0)
    for chunk in vessel.to_batches(max_chunksize=500):
        parts.write(pa.Table.from_batches([chunk]))
    parts.close()
    pieces = list(parts)
    piece_rows = bound // partition.PIECES_PER_BOUND
    assert len(vessel) / piece_rows <= len(pieces) <= len(vessel) / piece_rows + 2
    assert all(p.num_rows <= piece_rows for p in pieces)
    times = [np.sort(p.column("time").to_numpy().view(np.int64)) for p in pieces]
    assert all(a[-1] < b[0] for a, b in itertools.pairwise(times))
    assert np.array_equal(np.concatenate(times), np.sort(closed))
    assert list(tmp_path.iterdir()) == []  # every spill file deleted


def test_many_vessels_pack_into_pieces_in_mmsi_order(data, tmp_path):
    rows = _kitimat_rows(data)
    parts = partition.VesselPartitions(tmp_path, 2, PARTITION_SCHEMA, 5_000, math.inf)
    parts.write(rows)
    parts.close()
    pieces = [p for p in parts if p.num_rows]
    assert len(pieces) > 2 and sum(p.num_rows for p in pieces) == rows.num_rows
    for a, b in itertools.pairwise(pieces):
        # pieces of one partition follow in MMSI order (a piece starts a new partition or goes on)
        ma, mb = a.column("mmsi").to_numpy(), b.column("mmsi").to_numpy()
        same_part = partition.partition_of(ma[:1], 2) == partition.partition_of(mb[:1], 2)
        assert not same_part[0] or ma.max() <= mb.min()
