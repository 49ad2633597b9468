"""The fleet finders look one by one only at the vessels a screen over all reports at once
keeps (`aisdati.events.fleet.Joined`); on real Kitimat traffic, what they find is what looking
at every vessel one by one finds: the screens drop no vessel that gives something."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from aisdati.events.anchorages import learned_from
from aisdati.events.encounters import slow_samples
from aisdati.events.fleet import Fleet
from aisdati.events.interference import fleet_jumps
from aisdati.events.port_visits import port_visits, stays, visit_row
from aisdati.events.reports import vessels
from aisdati.events.rules import EventRules
from aisdati.events.settings import EventSettings


@pytest.fixture(scope="module")
def fleet(kitimat):
    reports = pd.read_parquet(kitimat / "reports.parquet")
    return Fleet({v.mmsi: v for v in vessels(reports)}), learned_from(reports)


def test_port_visits_are_those_of_every_vessel_looked_at(fleet):
    fleet, ports = fleet
    s = EventSettings()
    one_by_one = [
        visit_row(fleet, v, stay, ports, s.port_min_s)
        for v in fleet.vessels.values()
        for stay in stays(v, ports.nearest(v.lon, v.lat)[0], s)
    ]
    found = port_visits(fleet, EventRules(ports=ports))
    assert len(found) > 100
    assert pd.DataFrame(found).equals(pd.DataFrame(one_by_one))


def test_the_slow_step_screen_keeps_every_vessel_with_a_slow_sample(fleet):
    fleet, ports = fleet
    s, every = EventSettings(), fleet.joined
    kept = every.any_step(every.reports.implied_kn < s.encounter_kn)
    sampled = np.array([len(slow_samples(v, s, ports.subset(np.zeros(len(ports), bool)))) > 0
                        for v in fleet.vessels.values()])  # fmt: skip
    assert sampled.sum() > 50 and not (sampled & ~kept).any()
    assert (~kept).sum() > 0  # (the screen leaves some out)


def test_jumps_of_the_fleet_are_each_vessels_own(fleet):
    fleet, _ = fleet
    s = EventSettings()
    found = fleet_jumps(fleet, s)
    alone = [fleet_jumps(Fleet({m: v}), s) for m, v in fleet.vessels.items()]
    mmsi = np.concatenate([j.mmsi for j in alone])
    t1 = np.concatenate([j.t1 for j in alone])
    order = np.argsort(t1, kind="stable")
    assert len(found) > 0
    assert np.array_equal(found.mmsi, mmsi[order]) and np.array_equal(found.t1, t1[order])
    assert np.array_equal(found.metres, np.concatenate([j.metres for j in alone])[order])
