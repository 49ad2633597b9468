"""Cleaning: sentinels, ranges, COG normalisation, duplicates, implied-speed outliers, derived
SOG/COG."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.preprocess.clean import (
    check_values,
    clean_vessels,
    derive_sog_cog,
    filter_area_speed,
    filter_period,
)
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.report import CODE
from aisdati.preprocess.roi import florida_straits
from aisdati.preprocess.settings import IngestSettings

T0 = 1_600_000_000_000_000  # microseconds


def _table(mmsi, t_s, lon, lat, sog=None, cog=None):
    n = len(mmsi)
    sog = np.full(n, 10.0) if sog is None else np.asarray(sog, float)
    cog = np.full(n, 0.0) if cog is None else np.asarray(cog, float)
    time = pa.array(T0 + np.asarray(t_s, np.int64) * 1_000_000).view(pa.timestamp("us", tz="UTC"))
    return pa.table(
        [
            np.asarray(mmsi, np.int64),
            time,
            np.asarray(lon, float),
            np.asarray(lat, float),
            sog,
            cog,
            np.full(n, np.nan, np.float32),
            pa.nulls(n, pa.int16()),
            np.zeros(n, np.int32),
        ],
        schema=PARTITION_SCHEMA,
    )


def test_sentinels_ranges_and_cog_normalisation():
    t = _table(
        [1] * 7,
        range(7),
        [-80, 181, -80, -80, -80, -80, -80],
        [91, 25, 25, 25, 25, 95, 25],
        sog=[10, 10, 102.3, 10, 10, 10, 10],
        cog=[10, 10, 10, 360, -60.6, 10, 720],
    )
    codes = np.zeros(7, np.uint8)
    t = check_values(t, codes)
    assert list(codes) == [
        CODE["sentinel_lat"],
        CODE["sentinel_lon"],
        CODE["sentinel_sog"],
        CODE["sentinel_cog"],
        0,
        CODE["out_of_range"],
        CODE["out_of_range"],
    ]
    assert abs(t.column("cog")[4].as_py() - 299.4) < 1e-9


def test_roi_and_speed_filter():
    t = _table([1, 1, 1], [0, 1, 2], [-81.5, -81.5, -70.0], [24.0, 24.0, 40.0], sog=[10, 3, 10])
    codes = np.zeros(3, np.uint8)
    filter_area_speed(t, codes, florida_straits(), IngestSettings())
    assert list(codes) == [0, CODE["slow"], CODE["outside_roi"]]


def test_duplicates_repeated_timestamps_and_outliers():
    # vessel 7 sails north at ~10 kn (0.0028 deg lat per minute); report 3 jumps 1 degree away.
    lat = [25.0, 25.0028, 25.0028, 26.0, 25.0056, 25.0084, 25.0084]
    t = _table([7] * 7, [0, 60, 60, 90, 120, 180, 180], [-80.0] * 7, lat, cog=[0, 0, 0, 0, 0, 0, 5])
    shuffled = t.take(pa.array([6, 3, 0, 5, 1, 4, 2]))
    out, codes = clean_vessels(shuffled, IngestSettings())
    assert out.column("lat").to_pylist()[0] == 25.0  # sorted by time again
    assert list(codes) == [
        0,
        0,
        CODE["duplicate"],
        CODE["implied_speed"],
        0,
        0,
        CODE["repeated_timestamp"],
    ]


def test_outlier_does_not_become_the_reference():
    lat = [25.0, 25.0028, 27.0, 25.0056, 25.0084]
    _, codes = clean_vessels(
        _table([1] * 5, [0, 60, 120, 180, 240], [-80.0] * 5, lat), IngestSettings()
    )
    assert list(codes) == [0, 0, CODE["implied_speed"], 0, 0]


def test_derived_sog_and_cog_known_answer():
    # one minute north along a meridian by 1/60 deg = 1 nautical mile: 60 kn, course 0;
    # then one minute east.
    lat = np.array([25.0, 25.0 + 1 / 60, 25.0 + 1 / 60])
    lon = np.array([-80.0, -80.0, -80.0 + (1 / 60) / np.cos(np.radians(25 + 1 / 60))])
    time_us = np.array([0, 60, 120]) * 1_000_000
    sog, cog = derive_sog_cog(np.ones(3, np.int64), time_us, lon, lat, IngestSettings())
    assert np.allclose(sog, [60.0, 60.0, 60.0], rtol=2e-3)
    assert np.allclose(cog[:2], [0.0, 0.0], atol=0.01) and abs(cog[2] - 90) < 0.1


def test_positions_only_rows_get_sog_and_cog_then_the_speed_filter():
    lat = [25.0, 25.0028, 25.0056, 25.0056]
    t = _table([3] * 4, [0, 60, 120, 180], [-80.0] * 4, lat, sog=[np.nan] * 4, cog=[np.nan] * 4)
    out, codes = clean_vessels(t, IngestSettings())
    assert list(codes) == [0, 0, 0, CODE["slow"]]  # the last report did not move
    assert np.allclose(out.column("sog").to_numpy()[:3], 10.08, atol=0.05)


def test_bad_first_report_does_not_reject_the_rest_of_the_track():
    # the first report is 2 degrees off; the following ones agree with each other
    lat = [27.0, 25.0, 25.0028, 25.0056, 25.0084, 25.0112]
    _, codes = clean_vessels(
        _table([1] * 6, [0, 60, 120, 180, 240, 300], [-80.0] * 6, lat), IngestSettings()
    )
    assert list(codes) == [CODE["implied_speed"], 0, 0, 0, 0, 0]


def test_two_consecutive_outliers_stay_rejected():
    lat = [25.0, 25.0028, 27.0, 27.0001, 25.0084, 25.0112]
    _, codes = clean_vessels(
        _table([1] * 6, [0, 60, 120, 180, 240, 300], [-80.0] * 6, lat), IngestSettings()
    )
    assert list(codes) == [0, 0, CODE["implied_speed"], CODE["implied_speed"], 0, 0]


def test_a_confirmed_reference_stays_when_the_track_jumps_for_good():
    lat = [25.0, 25.0028, 27.0, 27.0028, 27.0056]
    _, codes = clean_vessels(
        _table([1] * 5, [0, 60, 120, 180, 240], [-80.0] * 5, lat), IngestSettings()
    )
    assert list(codes) == [0, 0, 0, 0, 0]


def test_period_filter_takes_since_inclusive_until_exclusive():
    """`--since` keeps a report at its instant, `--until` drops one at its own (issue 69)."""
    t = _table([1] * 4, [0, 60, 120, 180], [-81.5] * 4, [24.0] * 4)
    codes = np.zeros(4, np.uint8)
    codes[3] = CODE["bad_time"]  # a row already rejected keeps its first reason
    since = pd.Timestamp(T0 + 60_000_000, unit="us", tz="UTC").isoformat()
    until = pd.Timestamp(T0 + 120_000_000, unit="us", tz="UTC").isoformat()
    filter_period(t, codes, IngestSettings(since=since, until=until))
    assert list(codes) == [CODE["outside_period"], 0, CODE["outside_period"], CODE["bad_time"]]
