"""Interference over an area on real traffic (the New York Harbor hour, with its reported
motion): a block of vessels displaced each way a spoofer or jammer displaces them (by one
shift, onto one point, onto one circle) is one event naming them and saying how; the vessels'
own glitches at the same minutes are not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from aisdati.detection.events import model_free_events
from aisdati.evaluation.constructed import found
from aisdati.evaluation.interference_case import WAYS, displaced_block
from aisdati.events.fleet import Fleet
from aisdati.events.interference import areas, fleet_jumps, gnss_interference
from aisdati.events.reports import vessels
from aisdati.events.rules import EventRules
from aisdati.tracks.reports import read_reports, read_vessels

SAID = {"shifted": "shifted", "point": "onto one point", "circle": "onto a circle"}


@pytest.fixture(scope="module")
def hour(processed) -> tuple[pd.DataFrame, pd.DataFrame]:
    return read_reports(processed), read_vessels(processed)


@pytest.mark.parametrize("way", WAYS)
def test_a_block_displaced_each_way_is_one_event_that_says_how(hour, way):
    reports, identity = hour
    for seed in range(20):
        built = displaced_block(reports, identity, np.random.default_rng(seed), way)
        if built is not None:
            break
    assert built is not None
    written, known, case = built
    events = model_free_events(written, known)
    assert found(case, events)
    area = events[events["kind"] == "gnss-interference"]
    assert len(area) == 1 and SAID[way] in area["evidence"].iloc[0]
    assert len(area["lons"].iloc[0]) >= 4 and area["lons"].iloc[0][0] == area["lons"].iloc[0][-1]


def test_vessels_displaced_apart_are_no_interference(hour):
    """Three vessels of the hour each jumped kilometres at the same minute, each its own way
    (as glitches do): no interference."""
    reports, _ = hour
    fleet = Fleet({v.mmsi: v for v in vessels(reports)})
    moving = [v for v in fleet.vessels.values() if len(v) > 40 and np.median(v.sog) > 5][:3]
    assert len(moving) == 3
    for k, v in enumerate(moving):
        i = int(np.searchsorted(v.time_s, v.time_s[0] + 1800.0))
        bearing = np.radians(120.0 * k)
        lon, lat = v.lon.copy(), v.lat.copy()
        lon[i : i + 5] += 0.03 * (k + 1) * np.sin(bearing)
        lat[i : i + 5] += 0.02 * (k + 1) * np.cos(bearing)
        fleet.vessels[v.mmsi] = replace(v, lon=lon, lat=lat)
    s = EventRules().settings
    assert areas(fleet_jumps(fleet, s), s)  # displaced at once, in one area
    assert gnss_interference(fleet, EventRules()) == []  # but not alike
