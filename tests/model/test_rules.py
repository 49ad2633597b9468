"""The known update rules (`aisdati.model.rules`): their perfect decisions map each point onto
the next, on a plane and on the sphere, and the course window is centred on the traffic."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.geo import EARTH_RADIUS_M
from aisdati.model.rules import PlanarRule, SphericalRule
from aisdati.selftest.families import get_family

NM_M = 1852.0


# ---------------------------------------------------------------------------- update rules
def test_planar_rule_perfect_decisions_map_each_point_onto_the_next():
    fam = get_family("fixedstart")
    rule = PlanarRule(dt=fam.dt, max_speed=fam.max_speed)
    pos = fam.reference(7.3)
    dec = rule.perfect_decisions(pos, np.full(fam.steps, fam.dt))
    assert dec.shape == (fam.steps, 2)
    np.testing.assert_allclose(rule.step(pos[:-1], dec), pos[1:], atol=1e-12)
    for i in (0, 57, fam.steps - 1):  # one state at a time as well
        np.testing.assert_allclose(rule.step(pos[i], dec[i]), pos[i + 1], atol=1e-12)
    scaled = rule.decision_scaler.scale(dec)
    assert np.all(scaled >= -1) and np.all(scaled <= 1)
    np.testing.assert_allclose(rule.decision_scaler.unscale(scaled), dec, atol=1e-12)


def _destination(lon, lat, course_deg, dist_m):
    """Great-circle destination (exact on the sphere), independent of the update rule."""
    phi, lam, th = np.radians(lat), np.radians(lon), np.radians(course_deg)
    d = dist_m / EARTH_RADIUS_M
    phi2 = np.arcsin(np.sin(phi) * np.cos(d) + np.cos(phi) * np.sin(d) * np.cos(th))
    lam2 = lam + np.arctan2(
        np.sin(th) * np.sin(d) * np.cos(phi), np.cos(d) - np.sin(phi) * np.sin(phi2)
    )
    return np.degrees(lam2), np.degrees(phi2)


@pytest.fixture
def ais_track():
    """A vessel in the Florida Straits: 60 reports, irregular intervals (10 s to 6 min),
    speed 4-18 kn, slowly turning."""
    rng = np.random.default_rng(7)
    n = 60
    dts = rng.uniform(10, 360, n) / 3600.0
    sog = np.clip(11 + np.cumsum(rng.normal(0, 0.8, n)), 4, 18)
    cog = (35 + np.cumsum(rng.normal(0, 4, n))) % 360
    lon, lat = [-80.1], [25.3]
    for k in range(n):
        x, y = _destination(lon[-1], lat[-1], cog[k], sog[k] * dts[k] * NM_M)
        lon.append(float(x))
        lat.append(float(y))
    return np.stack([lon, lat], axis=1), dts, sog, cog


def test_spherical_rule_perfect_decisions_map_each_report_onto_the_next(ais_track):
    pos, dts, sog, cog = ais_track
    rule = SphericalRule(max_sog=30.0, max_dt_h=0.5)
    dec = rule.perfect_decisions(pos, dts)
    assert dec.shape == (len(dts), 3)
    np.testing.assert_allclose(dec[:, 2], dts)
    np.testing.assert_allclose(rule.step(pos[:-1], dec), pos[1:], atol=1e-10, rtol=0)
    # the decisions are the vessel's real speed and course, up to the flat-Earth step
    np.testing.assert_allclose(dec[:, 0], sog, rtol=2e-3)
    course_error = (dec[:, 1] - cog + 180) % 360 - 180
    assert np.abs(course_error).max() < 0.1
    scaled = rule.decision_scaler.scale(dec)
    assert np.all(scaled >= -1) and np.all(scaled <= 1)


def test_cog_window_is_centred_on_the_traffic_and_keeps_the_rule_exact():
    from aisdati.model.rules import SphericalRule, mean_course

    assert mean_course(np.array([350.0, 10.0])) == pytest.approx(0.0, abs=1e-9)
    assert mean_course(np.array([100.0, 140.0])) == pytest.approx(120.0)
    # a north-going track whose courses straddle 0/360
    lat = 40.0 + np.arange(6) * 0.01
    lon = -74.0 + np.array([0.0, 0.001, 0.0, 0.001, 0.0, 0.001])
    positions = np.stack([lon, lat], axis=1)
    dts = np.full(5, 0.05)
    rule = SphericalRule(max_sog=30.0, max_dt_h=0.1, cog_center=0.0)
    decisions = rule.perfect_decisions(positions, dts)
    assert np.all(np.abs(decisions[:, 1]) < 10.0)  # near 0, not split between ~0 and ~360
    scaled = rule.decision_scaler.scale(decisions)
    assert np.all(np.abs(scaled[:, 1]) < 0.1)
    stepped = rule.step(positions[:-1], decisions)
    np.testing.assert_allclose(stepped, positions[1:], atol=1e-9)
