"""Reported against observed motion on real Kitimat tracks: a stretch altered the way the
evaluation's kinds alter it is found where it was altered; the untouched tracks raise none."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.events.find import find_events
from aisdati.events.reports import VesselReports, vessels
from aisdati.geo import moved_m
from aisdati.tracks.reports import read_reports

LONGEST = 12


@pytest.fixture(scope="module")
def long_tracks(kitimat) -> list[VesselReports]:
    """Kitimat's longest tracks (MarineCadastre 2018: SOG and COG as reported, once a minute),
    each as one vessel's reports."""
    reports = read_reports(kitimat)
    sizes = reports.groupby("track_id").size().sort_values(ascending=False)
    chosen = reports[reports["track_id"].isin(sizes.index[:LONGEST])]
    return [VesselReports.of(g) for _, g in chosen.groupby("track_id")]


def _altered(v: VesselReports, **changed: np.ndarray) -> VesselReports:
    fields = {k: getattr(v, k) for k in VesselReports.__dataclass_fields__}
    return VesselReports(**(fields | changed))


def _stretch(v: VesselReports) -> tuple[int, int]:
    """A stretch of 15 % of the reports in the middle third, at most an hour: a minority of the
    hours around it, whose reports give the vessel's own spread (`scale_window_s`)."""
    a = len(v) // 3
    b = a + max(5, int(0.15 * len(v)))
    return a, min(b, int(np.searchsorted(v.time_s, v.time_s[a] + 3600.0)))


def _overlaps(v: VesselReports, kind: str, a: int, b: int) -> bool:
    return any(e.kind == kind and e.start < b and e.end >= a for e in find_events(v))


def test_untouched_tracks_raise_no_consistency_event(long_tracks):
    kinds = {"position-jump", "speed-inconsistent", "course-inconsistent"}
    raised = [e.kind for v in long_tracks for e in find_events(v) if e.kind in kinds]
    assert len(raised) <= 1, raised


def test_a_shifted_stretch_is_a_position_jump(long_tracks):
    found = 0
    for v in long_tracks:
        a, b = _stretch(v)
        lon, lat = v.lon.copy(), v.lat.copy()
        lon[a:b], lat[a:b] = moved_m(lon[a:b], lat[a:b], 70.0, 1500.0)
        found += _overlaps(_altered(v, lon=lon, lat=lat), "position-jump", a, b)
    assert found >= 0.8 * len(long_tracks)


@pytest.mark.parametrize(
    ("field", "kind", "sigma"),
    [("sog", "speed-inconsistent", 3.0), ("cog", "course-inconsistent", 40.0)],
)
def test_noise_on_the_reported_motion_is_found(long_tracks, field, kind, sigma):
    rng = np.random.default_rng(7)
    found = 0
    for v in long_tracks:
        a, b = _stretch(v)
        values = getattr(v, field).copy()
        values[a:b] += rng.normal(0.0, sigma, b - a)
        values = np.maximum(values, 0.0) if field == "sog" else values % 360.0
        found += _overlaps(_altered(v, **{field: values}), kind, a, b)
    assert found >= 2 / 3 * len(long_tracks)  # Kitimat's own course varies 3-14 deg


def test_vessels_splits_a_table_by_mmsi(kitimat):
    reports = read_reports(kitimat)
    got = vessels(reports.head(5000))
    assert sorted(v.mmsi for v in got) == sorted(reports.head(5000)["mmsi"].unique())
    assert all(np.all(np.diff(v.time_s) >= 0) for v in got)
