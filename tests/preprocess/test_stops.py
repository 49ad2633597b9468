"""Stops by dwell: the splitters on hand-built reports, and a real ferry's week in NY Harbor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from aisdati.geo import haversine_m
from aisdati.preprocess.pipeline import ingest
from aisdati.preprocess.report import CODE
from aisdati.preprocess.segment import segment
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.stops import (
    DwellGapSplitter,
    GapSplitter,
    Reports,
    StopSplitter,
    dwell_rules,
    split_reports,
)
from aisdati.tracks.schema import KNOT_MPS

MIN = 60_000_000  # one minute in microseconds
M_PER_DEG = 111_195.0


def sailing(minutes, speeds_kn, lat0=40.0):
    """Positions of a vessel sailing north at the given speeds, one report per minute mark."""
    minutes = np.asarray(minutes, dtype=float)
    speeds = np.asarray(speeds_kn, dtype=float)
    north_m = np.r_[0.0, np.cumsum(np.diff(minutes) * 60 * speeds[1:] * KNOT_MPS)]
    return np.full(len(minutes), -74.0), lat0 + north_m / M_PER_DEG


def test_gap_splitter_is_the_papers_rule():
    r = Reports(np.ones(4, np.int64), np.array([0, 10, 80, 90]) * MIN)
    assert list(GapSplitter(3600).split(r).starts) == [False, False, True, False]


def test_dwell_gap_splits_a_stop_but_not_a_reporting_gap_under_way():
    # 0-10 min under way at 10 kn, then 12 min at a pier (reports filtered out), then on again
    minutes = [0, 5, 10, 22, 27]
    speeds = [10, 10, 4, 4, 10]
    lon, lat = sailing(minutes, [10, 10, 10, 0, 10])
    lat[3:] = lat[2] + 200 / M_PER_DEG + (lat[3:] - lat[3])  # 200 m on from the last report
    r = Reports(np.ones(5, np.int64), np.array(minutes) * MIN, lon, lat, np.array(speeds, float))
    assert list(DwellGapSplitter(500, 300).split(r).starts) == [False] * 3 + [True, False]
    # the same 12-minute gap while sailing on at 10 kn is a reporting gap, not a stop
    lon, lat = sailing(minutes, [10] * 5)
    r = Reports(np.ones(5, np.int64), np.array(minutes) * MIN, lon, lat, np.full(5, 10.0))
    assert not DwellGapSplitter(500, 300).split(r).starts.any()
    # slow steaming: 2.5 km in 25 min is not "within 500 m", though below 3 kn on average
    lon, lat = sailing([0, 25], [5, 5])
    lat[1] = lat[0] + 2500 / M_PER_DEG
    r = Reports(np.ones(2, np.int64), np.array([0, 25]) * MIN, lon, lat, np.array([5.0, 5.0]))
    assert not DwellGapSplitter(500, 300).split(r).starts.any()


def test_stop_splitter_drops_the_dwell_and_splits_there():
    # under way, 8 reports within 30 m over 7 minutes, under way again
    minutes = np.arange(20)
    speeds = np.r_[np.full(6, 10.0), np.zeros(8), np.full(6, 10.0)]
    lon, lat = sailing(minutes, speeds)
    r = Reports(np.ones(20, np.int64), minutes * MIN, lon, lat, speeds)
    out = StopSplitter(radius_m=100, min_duration_s=300).split(r)
    assert out.drop.sum() >= 8 and not out.drop[:5].any() and not out.drop[15:].any()
    track, codes, n_short = segment(
        r.mmsi, r.time_us, 3600, 3, [StopSplitter(100, 300)], lon, lat, speeds
    )
    assert set(track[codes == CODE["dwell"]]) == {-1}
    assert len(set(track[track >= 0])) == 2 and n_short == 0
    # too short a dwell: nothing happens
    assert not StopSplitter(radius_m=100, min_duration_s=600).split(r).drop.any()


def test_split_reports_restarts_at_every_vessel_and_after_dropped_reports():
    mmsi = np.array([1, 1, 1, 2, 2, 2])
    minutes = np.array([0, 1, 2, 0, 1, 2])
    r = Reports(mmsi, minutes * MIN, np.zeros(6), np.zeros(6), np.zeros(6))

    class DropSecond:
        def split(self, sub):
            from aisdati.preprocess.stops import Splits

            drop = np.zeros(len(sub), bool)
            drop[1] = True
            return Splits(np.zeros(len(sub), bool), drop)

    out = split_reports(r, [DropSecond()])
    assert list(out.drop) == [False, True, False, False, False, False]
    assert list(out.starts) == [True, False, True, True, False, False]


def test_dwell_time_zero_is_the_papers_segmentation():
    assert dwell_rules(500, 0, 3.0) == []
    mmsi = np.ones(5, np.int64)
    t = np.array([0, 1, 2, 20, 21]) * MIN
    lon, lat = np.full(5, -74.0), np.full(5, 40.0)  # a 18-minute dwell on the spot
    old = segment(mmsi, t, 3600, 2)
    new = segment(mmsi, t, 3600, 2, dwell_rules(500, 0, 3.0), lon, lat, np.full(5, 5.0))
    assert all(np.array_equal(a, b) for a, b in zip(old[:2], new[:2], strict=True))
    split = segment(mmsi, t, 3600, 2, dwell_rules(500, 300, 3.0), lon, lat, np.full(5, 5.0))
    assert list(split[0]) == [0, 0, 0, 1, 1]


# ----------------------------------------------------------------- a real ferry, a real week
STATEN_ISLAND_FERRY = 366952790
WHITEHALL = (-74.0130, 40.7010)
ST_GEORGE = (-74.0718, 40.6440)


@pytest.fixture(scope="module")
def ferry_week(tmp_path_factory):
    """The Staten Island Ferry's tracks in the NY Harbor week, with and without dwell stops."""
    src = Path(__file__).parents[1] / "data" / "NYHarbor_2020_12_first_week_points.csv.gz"
    out = {}
    for name, dwell in (("dwell", 300.0), ("paper", 0.0)):
        folder = tmp_path_factory.mktemp(name)
        settings = IngestSettings(min_points=2, dwell_time_s=dwell, clusters="direction")
        ingest([src], folder, settings, None, "none")
        tracks = pq.read_table(folder / "tracks.parquet").to_pandas()
        points = pq.read_table(folder / "points.parquet").to_pandas()
        ids = tracks.loc[tracks["mmsi"] == STATEN_ISLAND_FERRY, "track_id"]
        out[name] = points[points["track_id"].isin(ids)]
    return out


def _ends(points):
    g = points.sort_values("time").groupby("track_id")
    return g.first(), g.last(), g.size()


def _near(rows, pier, km=1.5):
    return haversine_m(rows["lon"], rows["lat"], *pier) < km * 1000


def test_a_real_ferry_week_splits_into_its_crossings(ferry_week):
    first, last, size = _ends(ferry_week["dwell"])
    first, last = first[size >= 5], last[size >= 5]
    to_st_george = _near(first, WHITEHALL) & _near(last, ST_GEORGE)
    to_whitehall = _near(first, ST_GEORGE) & _near(last, WHITEHALL)
    # five days of a ferry that crosses about 20 times a day: each crossing is its own track
    assert len(first) >= 100
    assert (to_st_george | to_whitehall).mean() >= 0.9
    assert min(to_st_george.sum(), to_whitehall.sum()) >= 40
    # the paper's rule (gaps over an hour) keeps runs of many crossings in one track
    first, last, size = _ends(ferry_week["paper"])
    assert (size >= 5).sum() <= 15 and size.max() > 200
