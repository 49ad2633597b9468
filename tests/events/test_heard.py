"""`Heard.near` (who reported near a place during a time: a gap's coverage, an interference's
area) gives the rows a distance to every report would give, on real Kitimat reports: its
latitude band only spares the distances that cannot be within the radius."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.events.heard import Heard
from aisdati.events.reports import vessels
from aisdati.geo import haversine_m
from aisdati.tracks.reports import read_reports


@pytest.mark.parametrize("radius_m", [500.0, 20_000.0, 50_000.0])
def test_near_gives_the_rows_every_distance_gives(kitimat, radius_m):
    heard = Heard.of(vessels(read_reports(kitimat)))
    rng = np.random.default_rng(int(radius_m))
    found = 0
    for i in rng.integers(0, len(heard.time_s), 60):
        spread = rng.normal(0, 0.05, (int(rng.integers(1, 6)), 2))
        places = np.array([heard.lon[i], heard.lat[i]]) + spread
        start, end = heard.time_s[i] - 7200, heard.time_s[i] + 7200
        rows = np.flatnonzero((heard.time_s >= start) & (heard.time_s <= end))
        d = np.min([haversine_m(x, y, heard.lon[rows], heard.lat[rows]) for x, y in places], 0)
        expected = rows[d <= radius_m]
        assert np.array_equal(heard.near(start, end, places, radius_m), expected)
        found += len(expected)
    assert found > 0
