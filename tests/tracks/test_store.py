"""Reading ingest's tracks back (`aisdati.tracks.store`): each track's reports in time order
whatever the order of the points file."""

from __future__ import annotations

import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aisdati.errors import UserError
from aisdati.tracks.store import load_tracks, read_track_table


def test_tracks_load_in_time_order_from_points_in_any_order(processed, tmp_path):
    """The ingest's points written back as one file with their rows shuffled: each track's
    positions and time steps are those of its own reports sorted by time (pandas, per track),
    in the order the ids are asked for."""
    points = pq.read_table(processed / "points.parquet").to_pandas()
    shuffled = points.sample(frac=1.0, random_state=0).reset_index(drop=True)
    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(processed / "tracks.parquet", data / "tracks.parquet")
    pq.write_table(pa.Table.from_pandas(shuffled, preserve_index=False), data / "points.parquet")
    ids = read_track_table(processed)["track_id"].tolist()[::-1]
    for tid, track in zip(ids, load_tracks(data, ids), strict=True):
        mine = points[points["track_id"] == tid].sort_values("time")
        hours = mine["time"].diff().dt.total_seconds().to_numpy()[1:] / 3600.0
        assert track.track_id == tid
        np.testing.assert_array_equal(track.positions, mine[["lon", "lat"]].to_numpy())
        np.testing.assert_allclose(track.dts, hours, rtol=1e-12)
    shuffled["time"] = shuffled["time"].astype(str)
    pq.write_table(pa.Table.from_pandas(shuffled, preserve_index=False), data / "points.parquet")
    with pytest.raises(UserError, match="not a timestamp"):
        load_tracks(data, ids)


def test_tracks_carry_the_reported_motion_where_the_points_have_it(processed, tmp_path):
    """Issue 59, item 3: each track's reported SOG and COG, report by report, as the step
    scores read them; points without them (an older ingest) give None."""
    points = pq.read_table(processed / "points.parquet").to_pandas()
    ids = read_track_table(processed)["track_id"].tolist()[:3]
    for tid, track in zip(ids, load_tracks(processed, ids), strict=True):
        mine = points[points["track_id"] == tid].sort_values("time")
        np.testing.assert_allclose(track.sog, mine["sog"].to_numpy(np.float64))
        np.testing.assert_allclose(track.cog, mine["cog"].to_numpy(np.float64))
    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(processed / "tracks.parquet", data / "tracks.parquet")
    bare = pa.Table.from_pandas(points.drop(columns=["sog", "cog"]), preserve_index=False)
    pq.write_table(bare, data / "points.parquet")
    assert all(t.sog is None and t.cog is None for t in load_tracks(data, ids))
