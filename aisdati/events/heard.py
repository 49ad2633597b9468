"""Who was heard where and when: every report of the vessels judged together, in time order,
so that a fleet kind can ask which vessels reported near a place during a time
(`aisdati.events.fleet`: a gap's coverage; `aisdati.events.interference`: the vessels of an
area)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from aisdati.events.reports import VesselReports
from aisdati.geo import EARTH_RADIUS_M, haversine_m


@dataclass(frozen=True)
class Heard:
    """Reports of many vessels sorted by time (arrays of equal length)."""

    time_s: np.ndarray
    mmsi: np.ndarray
    lon: np.ndarray
    lat: np.ndarray

    @classmethod
    def of(cls, vessels: Iterable[VesselReports]) -> Heard:
        vs = list(vessels)
        if not vs:
            return cls(*[np.zeros(0)] * 4)
        time = np.concatenate([v.time_s for v in vs])
        order = np.argsort(time, kind="stable")
        mmsi = np.concatenate([np.full(len(v), v.mmsi, np.int64) for v in vs])
        lon, lat = np.concatenate([v.lon for v in vs]), np.concatenate([v.lat for v in vs])
        return cls(time[order], mmsi[order], lon[order], lat[order])

    def near(self, start_s: float, end_s: float, places: np.ndarray, radius_m: float) -> np.ndarray:
        """[k] the rows reported from `start_s` to `end_s` within `radius_m` of any of
        `places` ([m, 2] lon/lat); the distance reckoned only for rows within `radius_m` in
        latitude alone (a great circle is never shorter), the same rows at a coast's scale
        in a fraction of the time."""
        a = np.searchsorted(self.time_s, start_s, side="left")
        b = np.searchsorted(self.time_s, end_s, side="right")
        rows = np.arange(a, b)
        lons, lats = self.lon[rows], self.lat[rows]
        band = np.degrees(radius_m / EARTH_RADIUS_M) * (1 + 1e-9) + 1e-9
        close = np.zeros(len(rows), bool)
        for lon, lat in np.reshape(places, (-1, 2)):
            may = np.flatnonzero(np.abs(lats - lat) <= band)  # (never nearer than in latitude)
            close[may] |= haversine_m(lon, lat, lons[may], lats[may]) <= radius_m
        return rows[close]
