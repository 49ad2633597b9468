"""The two-transmitter rule (`aisdati.preprocess.transmitters`) inside ingest's cleaning, on
real Kitimat reports: two vessels under one MMSI are kept as two (none dropped as an outlier);
one vessel with a wrong fix, or with its own reports relayed again late (a receiver's clock
off), stays one vessel and the implied-speed check judges it as before. On the US coast day
(positions only), an MMSI heard from two places 19 km apart all day is two transmitters, and
vessels with a stale or mistimed report, or with their own track at shifted times, are one."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from aisdati.preprocess.clean import clean_vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.report import CODE
from aisdati.preprocess.settings import IngestSettings
from aisdati.tracks.schema import TRANSMITTER_STEP, mmsi_of
from tests.helpers.live import ROOT

KITIMAT = ROOT / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz"
FIRST, SECOND = 100000496, 100000692
COAST = ROOT / "tests" / "data" / "US_coastal_2020_06_30_points.csv.gz"
SHARED = 368134280
"""Heard from two places 19 km apart on the Illinois waterway from 11:00 to 19:30, each of its
two transmitters within 3 minutes of the other's reports some 200 times."""
ONE_VESSEL = {
    367639990: "a stale report at the berth it left, its own track there again 7 hours later",
    367199310: "a ferry: one report 35 minutes early, then its 28-kn track with times jittered",
    368102110: "its own track along one lane again at times shifted by 5-12 minutes",
}
"""US coast MMSIs whose reports alternate out of reach at 50 kn but are one vessel's (docs/
results/identity.md): the other 'transmitter' is never heard at once for long."""


@pytest.fixture(scope="module")
def rows() -> pd.DataFrame:
    frame = pd.read_csv(KITIMAT, usecols=["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG"])
    frame = frame[frame["MMSI"].isin([FIRST, SECOND])]
    return pd.DataFrame({
        "mmsi": frame["MMSI"].astype("int64"),
        "time": pd.to_datetime(frame["BaseDateTime"], utc=True),
        "lon": frame["LON"], "lat": frame["LAT"], "sog": frame["SOG"], "cog": frame["COG"],
        "heading": np.float32(np.nan), "status": None, "src": 0,
    })  # fmt: skip


@pytest.fixture(scope="module")
def coast() -> pd.DataFrame:
    frame = pd.read_csv(COAST, usecols=["MMSI", "BaseDateTime", "LAT", "LON"])
    frame = frame[frame["MMSI"].isin([SHARED, *ONE_VESSEL])]
    return pd.DataFrame({
        "mmsi": frame["MMSI"].astype("int64"),
        "time": pd.to_datetime(frame["BaseDateTime"], utc=True),
        "lon": frame["LON"], "lat": frame["LAT"], "sog": np.nan, "cog": np.nan,
        "heading": np.float32(np.nan), "status": None, "src": 0,
    })  # fmt: skip


def cleaned(frame: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
    table = pa.Table.from_pandas(frame, PARTITION_SCHEMA, preserve_index=False)
    table, codes = clean_vessels(table, IngestSettings())
    return table.to_pandas(), codes


def test_two_vessels_under_one_mmsi_are_kept_as_two(rows):
    merged = rows.assign(mmsi=FIRST)
    alone, alone_codes = cleaned(rows)
    table, codes = cleaned(merged)
    assert (codes == CODE["implied_speed"]).sum() == (alone_codes == CODE["implied_speed"]).sum()
    second = table[table["mmsi"] == FIRST + TRANSMITTER_STEP]
    assert mmsi_of(FIRST + TRANSMITTER_STEP) == FIRST
    # each id holds one vessel's reports while both sail (which is first: who spoke first)
    span = (second["time"].min(), second["time"].max())
    first = table[(table["mmsi"] == FIRST) & table["time"].between(*span)]
    whose = alone.set_index(["time", "lon", "lat"])["mmsi"]
    second_is = whose[pd.MultiIndex.from_frame(second[["time", "lon", "lat"]])]
    first_is = whose[pd.MultiIndex.from_frame(first[["time", "lon", "lat"]])]
    assert len(second) > 200 and len(first) > 200
    assert second_is.value_counts(normalize=True).iloc[0] > 0.95
    assert first_is.value_counts(normalize=True).iloc[0] > 0.95
    assert second_is.mode()[0] != first_is.mode()[0]


def test_one_wrong_fix_is_an_outlier_not_a_transmitter(rows):
    one = rows[rows["mmsi"] == FIRST].sort_values("time").reset_index(drop=True)
    one.loc[500, "lat"] += 0.3  # 33 km off, once
    table, codes = cleaned(one)
    assert set(table["mmsi"]) == {FIRST}
    assert (codes == CODE["implied_speed"]).sum() >= 1


def test_its_own_reports_relayed_late_are_no_second_transmitter(rows):
    one = rows[rows["mmsi"] == FIRST].sort_values("time")
    late = one.iloc[::3].assign(time=lambda f: f["time"] + pd.Timedelta(minutes=17))
    table, _ = cleaned(pd.concat([one, late]))
    assert set(table["mmsi"]) == {FIRST}


def test_two_places_heard_at_once_all_day_are_two_transmitters(coast):
    table, _ = cleaned(coast[coast["mmsi"] == SHARED])
    assert set(table["mmsi"]) == {SHARED, SHARED + TRANSMITTER_STEP}
    lat = table.groupby("mmsi")["lat"]
    assert lat.count().min() > 200
    assert lat.max()[SHARED] < lat.min()[SHARED + TRANSMITTER_STEP]  # two places, never mixed


@pytest.mark.parametrize("mmsi", ONE_VESSEL)
def test_one_vessel_never_heard_at_once_from_two_places_stays_one(coast, mmsi):
    table, _ = cleaned(coast[coast["mmsi"] == mmsi])
    assert set(table["mmsi"]) == {mmsi}
