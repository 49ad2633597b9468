"""The trajectory-imitation environment (`aisdati.model.env`): the Gymnasium API (and
Stable-Baselines3's checker), determinism, the perfect policy, sticking at the region's edge and
the reward's timing."""

from __future__ import annotations

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from aisdati.dtw import dtw
from aisdati.model.env import (
    ENV_ID,
    Reference,
    ReferenceSource,
    TrajectoryImitationEnv,
)
from aisdati.model.rules import PlanarRule
from aisdati.selftest.families import get_family
from aisdati.selftest.sources import make_family_env
from tests.helpers.line_family import LINE

PAPER = ("fixedstart", "ushaped", "circles", "ribbons")


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


def test_environment_passes_sb3_check_env():
    from stable_baselines3.common.env_checker import check_env

    check_env(make_family_env(LINE), warn=False)
    check_env(make_family_env("circles"), warn=False)
