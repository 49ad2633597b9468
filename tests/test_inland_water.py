"""Inland water (`aisdati.inland_water`): real vessels of the shipped US day (MarineCadastre
2022-01-03) sailing the Mississippi at New Orleans, the Columbia at Portland, Lake Michigan and
the Ohio at Cincinnati report ashore on the coastline alone, and raise no ashore event with
the lakes and rivers; land away from any mapped river stays land, and a position far inland
is still ashore."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from aisdati import coastline
from aisdati.events.behaviour import ashore
from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports
from aisdati.inland_water import water
from aisdati.tracks.ashore import AshoreCheck

US_DAY = Path(__file__).parent / "data" / "AIS_2022_01_03_head.zip"
UNDER_WAY = {
    319120100: "Mississippi, New Orleans (STOLT LOYALTY, tanker, 9.7 kn)",
    368121820: "Mississippi, New Orleans (MICHAEL S, tug, 12.7 kn)",
    367513140: "Columbia, Portland (CLEARWATER, tug, 7.3 kn)",
    367082230: "Lake Michigan (JOSEPH L BLOCK, cargo, 12.1 kn)",
    367434580: "Ohio, Cincinnati (KENTUCKY, 8.8 kn)",
}


@pytest.fixture(scope="module")
def river_vessels() -> dict[int, VesselReports]:
    with zipfile.ZipFile(US_DAY) as z:
        frame = pd.read_csv(z.open(z.namelist()[0]))
    frame = frame[frame["MMSI"].isin(UNDER_WAY)].rename(
        columns={"MMSI": "mmsi", "BaseDateTime": "time", "LON": "lon", "LAT": "lat",
                 "SOG": "sog", "COG": "cog"}
    )  # fmt: skip
    return {int(m): VesselReports.of(g) for m, g in frame.groupby("mmsi")}


def test_river_and_lake_traffic_is_ashore_on_the_coastline_alone_and_not_with_inland_water(
    river_vessels,
):
    assert set(river_vessels) == set(UNDER_WAY)
    for mmsi, v in river_vessels.items():
        before = AshoreCheck(inland_water=False).reports(v.positions())
        assert before.all() and len(v) >= 8, UNDER_WAY[mmsi]
        assert ashore(v, before), UNDER_WAY[mmsi]  # an event on the coastline alone
        assert not AshoreCheck().reports(v.positions()).any(), UNDER_WAY[mmsi]
        assert [e for e in find_events(v) if e.kind == "ashore"] == [], UNDER_WAY[mmsi]


def test_land_away_from_rivers_stays_land_and_far_inland_is_ashore():
    # Kansas farmland 15 km from the Kansas River; the middle of Lake Michigan; the Mississippi
    # at New Orleans' French Quarter, where the coastline alone puts it on land.
    lon, lat = np.array([-96.0, -87.0, -90.06]), np.array([39.3, 43.5, 29.955])
    assert coastline.on_land(lon, lat).tolist() == [True, False, False]
    assert coastline.on_land(lon, lat, inland_water=False).tolist() == [True, True, True]
    assert AshoreCheck().reports(np.array([[-96.0, 39.3], [-96.0, 39.31]])).all()


def test_water_is_clipped_to_its_box_and_rivers_are_widened():
    box = (-91.0, 29.0, -90.0, 30.0)  # New Orleans' tile: the Mississippi's bends
    w = water(box)
    assert not w.is_empty and w.is_valid
    x0, y0, x1, y1 = w.bounds
    assert x0 >= box[0] and y0 >= box[1] and x1 <= box[2] and y1 <= box[3]
    assert water((-40.0, 30.0, -39.0, 31.0)).is_empty  # mid-Atlantic: no inland water
