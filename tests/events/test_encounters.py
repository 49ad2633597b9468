"""Encounters and port visits (`aisdati.events.encounters`, `aisdati.events.port_visits`) on
real Kitimat traffic: two real vessels brought together at sea for hours are one encounter
naming both; the same two passing close under way are none; the time-bucketed grid finds
exactly the pairs that comparing every two vessels finds; ports and anchorages learned from
where vessels stop, or given as GeoJSON."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from aisdati.detection.events import model_free_events
from aisdati.errors import UserError
from aisdati.evaluation.constructed import found, named
from aisdati.events.anchorages import Anchorages, learned_from, read_ports
from aisdati.events.encounters import close_pairs, encounters, slow_samples
from aisdati.events.fleet import Fleet
from aisdati.events.reports import VesselReports, vessels
from aisdati.events.rules import EventRules
from aisdati.events.settings import EventSettings
from aisdati.geo import haversine_m, moved_m
from tests.helpers.meetings import met

NONE = Anchorages(np.empty(0), np.empty(0), np.empty(0, np.int64), (), "none")


@pytest.fixture(scope="module")
def meeting(kitimat):
    reports, identity, case = met(kitimat)
    ports = learned_from(reports)
    events = model_free_events(reports, identity, EventRules(ports=ports))
    return reports, identity, case, ports, events


def test_two_real_vessels_brought_together_at_sea_are_one_encounter_naming_both(meeting):
    _reports, identity, case, ports, events = meeting
    assert found(case, events)
    mine = events[(events["kind"] == "encounter") & events.apply(
        lambda e: set(case.mmsis) <= named(e), axis=1)]  # fmt: skip
    assert len(mine) == 1
    e = mine.iloc[0]
    assert e["class"] == "activity"
    other = json.loads(e["others"])[0]
    assert {int(e["mmsi"]), other["mmsi"]} == set(case.mmsis)
    b = other["mmsi"]
    assert other["name"] == (identity.loc[b, "name"] if pd.notna(identity.loc[b, "name"]) else None)
    assert abs(e["start"] - case.start) <= pd.Timedelta("20min")
    assert abs(e["end"] - case.end) <= pd.Timedelta("20min")
    far, _ = ports.nearest(np.array([e["lon"]]), np.array([e["lat"]]))
    assert far[0] >= EventSettings().encounter_port_m


def test_every_encounter_is_long_and_away_from_the_ports_others_make(meeting):
    """Each encounter lasts 2 h and lies 10 km from every anchorage point that vessels other
    than its two make (two vessels meeting do not make the place a port)."""
    _reports, _, _, ports, events = meeting
    s = EventSettings()
    for e in events[events["kind"] == "encounter"].itertuples():
        assert e.duration_s >= s.encounter_min_s
        two = named(pd.Series(e._asdict()))
        others = np.array([len(w - two) >= s.anchorage_min_vessels for w in ports.stoppers])
        far, _ = ports.subset(others).nearest(np.array([e.lon]), np.array([e.lat]))
        assert far[0] >= s.encounter_port_m - s.encounter_m


def _alongside(v: VesselReports, rows: np.ndarray, mmsi: int) -> VesselReports:
    """A second vessel 150 m from `v` at each of its reports `rows`."""
    lon, lat = moved_m(v.lon[rows], v.lat[rows], 90.0, 150.0)
    return VesselReports(
        mmsi, v.time_s[rows] + 5.0, lon, lat, v.sog[rows], v.cog[rows], v.heading[rows],
        v.status[rows], np.full(len(rows), -1.0),
    )  # fmt: skip


def test_a_close_pass_under_way_is_no_encounter(meeting):
    """A real vessel's hours under way with a second vessel 150 m abeam all along (a convoy,
    closer and longer than any pass): not slow, so no encounter; the same pair slow is one."""
    reports, *_ = meeting
    own = max(vessels(reports), key=lambda v: int((v.sog > 5).sum()))
    fast = np.flatnonzero(own.sog > 5)
    pair = Fleet({own.mmsi: own, 1: _alongside(own, fast, 1)})
    short = VesselReports(own.mmsi, *(x[fast] for x in (own.time_s, own.lon, own.lat, own.sog,
                          own.cog, own.heading, own.status, own.track_id)))  # fmt: skip
    assert (short.time_s[-1] - short.time_s[0]) > 2 * 3600
    pair = Fleet({own.mmsi: short, 1: _alongside(own, fast, 1)})
    assert encounters(pair, EventRules(ports=NONE)) == []


def test_the_grid_finds_exactly_the_pairs_every_two_vessels_compared_find(meeting):
    reports, *_ = meeting
    s = EventSettings()
    samples = pd.concat([slow_samples(v, s, NONE) for v in vessels(reports)], ignore_index=True)
    assert samples["mmsi"].nunique() >= 10
    grid = close_pairs(samples, s)
    every = samples.merge(samples, on="step", suffixes=("_a", "_b"))
    every = every[every["mmsi_a"] < every["mmsi_b"]]
    metres = haversine_m(every["lon_a"], every["lat_a"], every["lon_b"], every["lat_b"])
    every = every[np.asarray(metres) <= s.encounter_m]
    assert len(grid) > 0
    got = set(zip(grid["a"], grid["b"], grid["step"], strict=True))
    assert got == set(zip(every["mmsi_a"], every["mmsi_b"], every["step"], strict=True))


def test_anchorages_are_where_enough_distinct_vessels_stopped(meeting):
    reports, *_ = meeting
    s = EventSettings()
    ports = learned_from(reports)
    assert len(ports) > 0
    stopped = reports[reports["sog"] < s.stopped_kn]
    half_diagonal = s.anchorage_cell_m / np.sqrt(2) + 1.0
    for k in range(len(ports)):
        near = haversine_m(stopped["lon"], stopped["lat"], ports.lon[k], ports.lat[k])
        assert stopped["mmsi"][np.asarray(near) <= half_diagonal].nunique() >= ports.vessels[k]
        assert ports.vessels[k] >= s.anchorage_min_vessels


def test_a_port_given_as_geojson_names_its_visits(meeting, tmp_path):
    reports, identity, _, _ports, events = meeting
    visits = events[events["kind"] == "port-visit"]
    assert len(visits)
    assert (visits["duration_s"] >= EventSettings().port_min_s).all()
    v = visits.iloc[0]
    d = 0.01
    square = [[v["lon"] - d, v["lat"] - d], [v["lon"] + d, v["lat"] - d],
              [v["lon"] + d, v["lat"] + d], [v["lon"] - d, v["lat"] + d]]  # fmt: skip
    doc = {"type": "FeatureCollection", "features": [{"type": "Feature",
           "properties": {"name": "TEST HARBOUR"},
           "geometry": {"type": "Polygon", "coordinates": [[*square, square[0]]]}}]}  # fmt: skip
    path = tmp_path / "ports.geojson"
    path.write_text(json.dumps(doc))
    given = model_free_events(reports, identity, EventRules(ports=read_ports(path)))
    mine = given[(given["kind"] == "port-visit") & (given["mmsi"] == v["mmsi"])]
    assert (mine["start"] <= v["end"]).any() and (mine["end"] >= v["start"]).any()
    assert mine["evidence"].str.contains("TEST HARBOUR").all()
    path.write_text(json.dumps({"type": "LineString", "coordinates": [[0, 0], [1, 1]]}))
    with pytest.raises(UserError, match="Points or Polygons"):
        read_ports(path)
