"""How the AIS agent sees and moves (`aisdati.ais.space`) on real Kitimat tracks: the paper's
state, the enlarged and Fourier states, the lane presets and their overrides."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from aisdati.ais.source import build_source, make_env, track_reference
from aisdati.ais.space import PRESETS, LaneConfig, lane_config
from aisdati.errors import UserError
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def tracks(kitimat):
    ids = read_track_table(kitimat)["track_id"].tolist()[:30]
    return load_tracks(kitimat, ids)


def test_enlarged_state_shape_scaling_and_env_checker(tracks):
    from gymnasium.utils.env_checker import check_env

    source = build_source(tracks[:8], LaneConfig(state="motion"))
    env = make_env(source)
    assert env.observation_space.shape == (6,)
    check_env(env, skip_render_check=True)
    ref = track_reference(tracks[0])
    obs, _ = env.reset(seed=0, options={"reference": ref})
    assert np.all(obs[2:5] == 0) and obs[5] == 0  # no motion yet, step 0
    for k, action in enumerate(env.perfect_actions[:20]):
        obs, *_ = env.step(action)
        sog, cog, _ = source.rule.perfect_decisions(ref.positions, ref.dts)[k]
        assert obs[2] == pytest.approx(np.sin(np.radians(cog)), abs=1e-4)
        assert obs[3] == pytest.approx(np.cos(np.radians(cog)), abs=1e-4)
        assert obs[4] == pytest.approx(sog / source.rule.max_sog, abs=1e-4)
        assert obs[5] == k + 1  # the step index, the paper's time input
        assert env.observation_space.contains(obs)


def test_fourier_state_encodes_the_position_at_each_octave(tracks):
    from gymnasium.utils.env_checker import check_env

    plain = build_source(tracks[:8], LaneConfig(state="motion")).space
    source = build_source(tracks[:8], LaneConfig(state="motion", fourier=3))
    space = source.space
    assert space.state_dim == 5 + 12
    env = make_env(source)
    assert env.observation_space.shape == (18,)
    check_env(env, skip_render_check=True)
    pos, prev, dts = tracks[0].positions[1:], tracks[0].positions[:-1], tracks[0].dts
    got, base = space.features(pos, prev, dts), plain.features(pos, prev, dts)
    np.testing.assert_array_equal(got[:, :5], base)  # the paper's view comes first, unchanged
    for coord in range(2):  # lon's 3 sines and 3 cosines, then lat's
        for octave in range(3):
            angle = np.pi * 2**octave * base[:, coord]
            np.testing.assert_allclose(got[:, 5 + 6 * coord + octave], np.sin(angle))
            np.testing.assert_allclose(got[:, 8 + 6 * coord + octave], np.cos(angle))
    lo, hi = space.state_bounds
    assert np.all(got >= lo - 1e-12) and np.all(got <= hi + 1e-12)
    with pytest.raises(UserError, match="fourier"):
        LaneConfig(fourier=-1)


def test_lane_presets_and_overrides():
    from aisdati.errors import UserError

    assert lane_config("paper") == LaneConfig()
    cfg = lane_config("paper", ["validation=true", "region=corridor", "corridor_km=3"])
    assert cfg.validation and cfg.region == "corridor" and cfg.corridor_km == 3.0
    assert lane_config("lanes") == PRESETS["lanes"]
    for bad in (["validation=maybe"], ["nope=1"], ["corridor_km=-1"], ["time=hours"]):
        with pytest.raises(UserError):
            lane_config("paper", bad)
    with pytest.raises(UserError):
        lane_config("fancy")


def test_gym_space_of_the_paper_state_is_unchanged(tracks):
    env = make_env(build_source(tracks[:4], LaneConfig()))
    assert env.observation_space.shape == (3,)
    assert isinstance(env.action_space, gym.spaces.Box)
