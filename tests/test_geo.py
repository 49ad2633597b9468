"""Geodesy (`aisdati.geo`): the spherical step against the haversine distance, and the
indexed lane distance (a k-d tree, kept between calls) against comparing every point, on real
Kitimat tracks and random ones."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.geo import courses_deg, haversine_m, lane_distances, spherical_step
from aisdati.tracks.store import load_tracks, read_track_table
from tests.helpers.tracks import random_tracks


@pytest.mark.parametrize("lat", [0.0, 25.0, 40.7, 60.0])
def test_spherical_rule_one_step_error_below_0_1_percent(lat):
    rng = np.random.default_rng(1)
    sog = rng.uniform(0.5, 30.0, 200)
    cog = rng.uniform(0.0, 360.0, 200)
    dist_m = rng.uniform(10.0, 5000.0, 200)
    dt = dist_m / 1852.0 / sog
    lon, lat2 = spherical_step(-74.0, lat, sog, cog, dt)
    true = haversine_m(-74.0, lat, lon, lat2)
    assert np.max(np.abs(true - dist_m) / dist_m) < 1e-3


NM_M = 1852.0


@pytest.mark.parametrize("lat", [-60.0, -20.0, 0.0, 25.3, 45.0, 60.0])
def test_spherical_step_distance_matches_haversine(lat):
    """One step of SOG x dt nautical miles travels that far on the sphere, within 0.1 %."""
    dists_m = np.array([50.0, 500.0, 2000.0, 4999.0])
    dt_h = 0.1
    for cog in np.arange(0.0, 360.0, 22.5):
        sog = dists_m / NM_M / dt_h
        lon2, lat2 = spherical_step(np.full(4, -80.0), np.full(4, lat), sog, cog, dt_h)
        travelled = haversine_m(-80.0, lat, lon2, lat2)
        rel = np.abs(travelled - dists_m) / dists_m
        assert rel.max() < 1e-3, (lat, cog, rel)


def brute_lane(track: np.ndarray, lane: list[np.ndarray], course_m: float) -> np.ndarray:
    """Every report against every lane point, as `lane_distances` defines the distance."""
    cloud = np.concatenate(lane)
    d = haversine_m(track[:, None, 0], track[:, None, 1], cloud[None, :, 0], cloud[None, :, 1])
    if course_m > 0:

        def course(p: np.ndarray) -> np.ndarray:
            theta = np.radians(courses_deg(p))
            prv, nxt = np.r_[0, np.arange(len(p) - 1)], np.r_[np.arange(1, len(p)), len(p) - 1]
            moves = np.any(p[nxt] != p[prv], axis=1)
            return np.column_stack([np.cos(theta), np.sin(theta)]) * moves[:, None]

        c = np.concatenate([course(p) for p in lane])
        turn = np.linalg.norm(course(track)[:, None] - c[None], axis=2)
        d = np.hypot(d, course_m / 2 * turn)
    return d.min(axis=1)


@pytest.mark.parametrize("course_m", [0.0, 2000.0])
def test_lane_distances_equal_the_brute_force_on_real_and_random_tracks(real, course_m):
    rand = random_tracks(1, 30)
    for k in range(6):
        lane = [t for j, t in enumerate(real) if j != k and j % 3 != k % 3]
        for track, pool in ((real[k], lane), (rand[k], rand[6:]), (real[k], rand[6:] + lane)):
            got = lane_distances(track, pool, course_m)
            np.testing.assert_allclose(got, brute_lane(track, pool, course_m), rtol=0, atol=1e-6)


def test_the_kept_index_serves_subsets_and_notices_changed_tracks(real):
    lane = [t.copy() for t in real[1:]]
    whole = lane_distances(real[0], lane, 2000.0)  # builds the index
    most = [*lane[:-3], real[0][::2].copy()]  # most of it, plus a polyline it does not hold
    assert np.max(lane_distances(real[0][::2], most, 2000.0)) == 0.0  # its own points
    np.testing.assert_allclose(
        lane_distances(real[0], most, 2000.0), brute_lane(real[0], most, 2000.0), atol=1e-6
    )
    assert np.all(lane_distances(real[0], lane, 2000.0) == whole)
    lane[5] += 0.05  # moved in place: the index's copy is stale and must not be used
    np.testing.assert_allclose(
        lane_distances(real[0], lane, 2000.0), brute_lane(real[0], lane, 2000.0), atol=1e-6
    )


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_lane_distances_equal_the_brute_force_nearest_great_circle_distance(tracks):
    from aisdati.geo import haversine_m, lane_distances

    track, lane = tracks[0].positions, np.concatenate([t.positions for t in tracks[1:4]])
    brute = haversine_m(
        track[:, None, 0], track[:, None, 1], lane[None, :, 0], lane[None, :, 1]
    ).min(axis=1)
    np.testing.assert_allclose(lane_distances(track, [lane]), brute, rtol=1e-6, atol=1e-3)


def test_the_course_weighted_lane_distance_is_the_brute_force_minimum(tracks):
    from aisdati.geo import courses_deg, haversine_m, lane_distances

    track, lane = tracks[0].positions, [t.positions for t in tracks[1:4]]
    cloud = np.concatenate(lane)
    courses = np.concatenate([courses_deg(p) for p in lane])
    dtheta = np.radians(courses_deg(track)[:, None] - courses[None, :])
    gc = haversine_m(track[:, None, 0], track[:, None, 1], cloud[None, :, 0], cloud[None, :, 1])
    brute = np.hypot(gc, 3000.0 * np.sin(dtheta / 2)).min(axis=1)
    np.testing.assert_allclose(lane_distances(track, lane, 3000.0), brute, rtol=1e-6, atol=1e-3)


def test_sailing_a_lane_backwards_costs_the_course_weight(tracks):
    from aisdati.geo import lane_distances

    track = tracks[0].positions
    np.testing.assert_allclose(lane_distances(track, [track], 3000.0), 0.0, atol=1e-6)
    backwards = lane_distances(track[::-1], [track], 3000.0)
    assert np.all(backwards <= 3000.0 + 1e-6)
    assert np.median(backwards) > 2500.0  # the same places, the opposite way
    np.testing.assert_allclose(lane_distances(track[::-1], [track]), 0.0, atol=1e-6)
