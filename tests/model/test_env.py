"""The trajectory-imitation environment, the synthetic families and the update rules."""

from __future__ import annotations

import warnings
from dataclasses import replace

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from aisdati.dtw import dtw
from aisdati.errors import UserError
from aisdati.geo import EARTH_RADIUS_M, haversine_m, spherical_step
from aisdati.model.env import (
    ENV_ID,
    Reference,
    ReferenceSource,
    TrajectoryImitationEnv,
)
from aisdati.model.rules import PlanarRule, SphericalRule
from aisdati.selftest.families import FAMILIES, Family, get_family, register_family
from aisdati.selftest.sources import FamilySource, make_family_env

PAPER = ("fixedstart", "ushaped", "circles", "ribbons")
NM_M = 1852.0


# ---------------------------------------------------------------------------- Gymnasium API
def test_check_env_passes_on_the_unwrapped_env():
    env = make_family_env("circles")
    with warnings.catch_warnings():
        # the only warning: no spec, so alternative render modes are not tested
        warnings.filterwarnings("ignore", message=".*render modes.*")
        check_env(env)


def test_gymnasium_make_by_id():
    env = gymnasium.make(ENV_ID, family="ushaped")
    obs, info = env.reset(seed=0)
    assert env.unwrapped.source.family.name == "ushaped"
    assert env.observation_space.contains(obs)
    assert info["reference"].steps == get_family("ushaped").steps
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert reward in (-1.0, 1.0)
    assert not terminated and not truncated
    env.close()


# ---------------------------------------------------------------------------- determinism
def _episode(env: TrajectoryImitationEnv, seed: int, actions: np.ndarray):
    obs, info = env.reset(seed=seed)
    observations, rewards, dtws = [obs], [], []
    for a in actions:
        obs, reward, terminated, _, info = env.step(a)
        observations.append(obs)
        rewards.append(reward)
        dtws.append(info["dtw"])
        if terminated:
            break
    return env.reference.positions.copy(), np.array(observations), rewards, dtws


def test_same_seed_same_episode_different_seed_different():
    actions = np.random.default_rng(0).uniform(-1, 1, (30, 2)).astype(np.float32)
    ref1, obs1, rew1, dtw1 = _episode(make_family_env("ushaped"), 5, actions)
    ref2, obs2, rew2, dtw2 = _episode(make_family_env("ushaped"), 5, actions)
    np.testing.assert_array_equal(ref1, ref2)
    np.testing.assert_array_equal(obs1, obs2)
    assert rew1 == rew2 and dtw1 == dtw2

    ref3, _, _, dtw3 = _episode(make_family_env("ushaped"), 6, actions)
    assert not np.array_equal(ref1, ref3)
    assert dtw1 != dtw3


def test_reset_without_seed_continues_the_stream():
    env = make_family_env("circles")
    env.reset(seed=1)
    first = env.reference.label["alpha"]
    env.reset()
    assert env.reference.label["alpha"] != first


# ---------------------------------------------------------------------------- perfect policy
@pytest.mark.parametrize("name", PAPER)
def test_perfect_policy_reproduces_the_reference(name):
    """Definition 3.2: feeding the perfect decisions back gives DTW 0 and +1 at every step."""
    env = make_family_env(name)
    env.reset(seed=11)
    ref = env.reference
    perfect = env.perfect_actions.copy()
    assert perfect.shape == (ref.steps, 2)
    assert np.all(np.abs(perfect) <= 1.0)
    path = [env.position.copy()]
    terminated = False
    for t, a in enumerate(perfect):
        assert not terminated
        _, reward, terminated, truncated, info = env.step(a)
        path.append(env.position.copy())
        assert reward == 1.0, f"step {t}"
        assert info["dtw"] <= 1e-9
        assert info["dtw_smoothed"] <= 1e-9
        assert not info["stuck"]
        assert not truncated
        np.testing.assert_array_equal(info["perfect_action"], a.astype(np.float32))
    assert terminated
    np.testing.assert_allclose(np.array(path), ref.positions, atol=1e-9)


# ---------------------------------------------------------------------------- sticking
def test_move_out_of_the_region_sticks():
    env = make_family_env("circles")
    hi = env.source.bounds[1]
    start = np.array([hi[0] - 0.01, 0.0])
    ks = np.arange(env.source.max_steps + 1)
    positions = np.stack([np.full(len(ks), start[0]), 0.01 * ks], axis=1)
    ref = Reference(positions, np.full(len(positions) - 1, env.source.family.dt))
    env.reset(seed=0, options={"reference": ref})
    # max speed, heading 0 (due +x): one step is far more than the 0.01 left to the boundary
    outward = np.array([1.0, 0.0], dtype=np.float32)
    assert env.source.family.max_speed * env.source.family.dt > 0.01
    obs, _, _, _, info = env.step(outward)
    assert info["stuck"]
    np.testing.assert_array_equal(env.position, start)
    assert env.t == 1 and env.observation_space.contains(obs)
    # heading π (unit +1) points back inside: the agent moves
    inward = np.array([1.0, 1.0], dtype=np.float32)
    _, _, _, _, info = env.step(inward)
    assert not info["stuck"]
    assert env.position[0] < start[0]


def test_move_inside_the_region_is_not_stuck():
    env = make_family_env("circles")
    env.reset(seed=0)
    before = env.position.copy()
    _, _, _, _, info = env.step(np.array([0.5, 0.3], dtype=np.float32))
    assert not info["stuck"]
    assert not np.array_equal(env.position, before)


# ---------------------------------------------------------------------------- reward timing
class LineSource(ReferenceSource):
    """A straight reference one unit per step along x; DTW is not normalised."""

    def __init__(self, steps: int = 4):
        self.rule = PlanarRule(dt=1.0, max_speed=2.0)
        self.bounds = (np.array([-10.0, -10.0]), np.array([10.0, 10.0]))
        self.max_steps = steps

    def sample(self, rng):
        xs = np.arange(self.max_steps + 1, dtype=np.float64)
        return Reference(np.stack([xs, np.zeros_like(xs)], axis=1), np.ones(self.max_steps))

    def normalize(self, distance, path_length):
        return distance


def _line_env():
    env = TrajectoryImitationEnv(LineSource(), epsilon=0.5, smoothing=0.9)
    env.reset(seed=0)
    return env


# scaled (speed, heading): speed 1 of max 2 -> 0; heading 0 -> 0
FOLLOW = np.array([0.0, 0.0], dtype=np.float32)
STAY = np.array([-1.0, 0.0], dtype=np.float32)


def test_reward_counts_the_point_just_revealed():
    """Following the reference gives +1 at once: had the newly revealed point been left out,
    the agent's new point would sit 1 unit from the old reference prefix (smoothed 0.9 > ε)."""
    env = _line_env()
    np.testing.assert_allclose(env.perfect_actions[0], FOLLOW, atol=1e-12)
    _, reward, _, _, info = env.step(FOLLOW)
    assert info["dtw"] == pytest.approx(0.0, abs=1e-12)
    assert reward == 1.0


def test_reward_reacts_to_the_move_of_the_same_step():
    """Standing still while the reference moves crosses ε at this very step (no one-step lag:
    with a lag the first reward would still be the +1 of the empty DTW)."""
    env = _line_env()
    _, reward, _, _, info = env.step(STAY)
    assert info["dtw"] == pytest.approx(1.0)
    assert info["dtw_smoothed"] == pytest.approx(0.9)
    assert reward == -1.0

    # after a good step, a bad one is punished in the same step too
    env = _line_env()
    assert env.step(FOLLOW)[1] == 1.0
    _, reward, _, _, info = env.step(STAY)
    assert info["dtw_smoothed"] > env.epsilon
    assert reward == -1.0


def test_step_dtw_equals_whole_pair_dtw_of_the_prefixes():
    env = make_family_env("ushaped", epsilon=0.05)
    env.reset(seed=3)
    rng = np.random.default_rng(1)
    path = [env.position.copy()]
    smoothed = 0.0
    for t in range(1, 25):
        _, reward, _, _, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        path.append(env.position.copy())
        expected = dtw(np.array(path), env.reference.positions[: t + 1])
        assert info["dtw"] == pytest.approx(expected, rel=1e-9, abs=1e-12)
        value = expected / env.source.family.diameter
        assert info["dtw_normalized"] == pytest.approx(value, rel=1e-9, abs=1e-12)
        smoothed = env.smoothing * value + (1 - env.smoothing) * smoothed
        assert info["dtw_smoothed"] == pytest.approx(smoothed, rel=1e-9, abs=1e-12)
        assert reward == (1.0 if smoothed < env.epsilon else -1.0)


def test_step_before_reset_raises():
    with pytest.raises(RuntimeError):
        make_family_env("circles").step(np.zeros(2, dtype=np.float32))


# ---------------------------------------------------------------------------- families
@pytest.mark.parametrize("name", PAPER)
def test_paper_family_geometry(name):
    fam = get_family(name)
    assert fam.diameter > 0 and np.isfinite(fam.diameter)
    assert fam.max_speed > 0
    lo, hi = fam.bounds
    assert np.all(hi > lo)
    for alpha in np.linspace(*fam.alpha_range, 5):
        ref = fam.reference(alpha)
        assert ref.shape == (fam.steps + 1, 2)
        assert np.all(ref >= lo) and np.all(ref <= hi)
        speeds = np.linalg.norm(np.diff(ref, axis=0), axis=1) / fam.dt
        assert speeds.max() <= fam.max_speed


def test_ribbons_diameter_is_twice_the_distance_to_the_median_member():
    fam = get_family("ribbons")
    lo, hi = fam.alpha_range
    assert fam.wraps
    half = dtw(fam.reference(lo), fam.reference((lo + hi) / 2))
    assert fam.diameter == pytest.approx(2 * half, rel=1e-12)
    # the boundary members of a wrapping family coincide
    np.testing.assert_allclose(fam.reference(lo), fam.reference(hi), atol=1e-9)


def test_non_wrapping_diameter_is_the_distance_between_the_boundary_members():
    fam = get_family("circles")
    assert fam.diameter == pytest.approx(dtw(fam.reference(0.5), fam.reference(1.0)))


@pytest.fixture
def spiral():
    fam = Family(
        name="TestSpiral",
        x=lambda t, a: a * t * np.cos(t),
        y=lambda t, a: a * t * np.sin(t),
        alpha_range=(0.5, 1.0),
        omega=0.5,
        steps=30,
    )
    yield register_family(fam)
    FAMILIES.pop("testspiral", None)


def test_registered_family_works_by_name(spiral):
    assert get_family("testspiral") is spiral
    env = make_family_env("TestSpiral")
    assert env.source.family is spiral
    env.reset(seed=2)
    for a in env.perfect_actions.copy():
        _, reward, terminated, _, info = env.step(a)
        assert reward == 1.0 and info["dtw"] <= 1e-9
    assert terminated and env.t == 30
    assert gymnasium.make(ENV_ID, family="testspiral").unwrapped.source.family is spiral


def test_family_object_with_fewer_steps():
    fam = replace(get_family("circles"), steps=12)
    env = TrajectoryImitationEnv(FamilySource(fam))
    env.reset(seed=0)
    assert env.reference.steps == 12 and env.perfect_actions.shape == (12, 2)
    assert env.observation_space.high[2] == 12


def test_unknown_family_is_a_user_error():
    with pytest.raises(UserError, match="unknown family"):
        get_family("nosuchfamily")
    with pytest.raises(UserError, match="unknown family"):
        make_family_env("nosuchfamily")


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
