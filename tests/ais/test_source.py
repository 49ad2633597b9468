"""The reference source of DATI on real AIS tracks (`aisdati.ais.source`): a perfect policy
reproduces real New York Harbor tracks."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.ais.source import build_source, make_env, track_reference
from aisdati.tracks.store import load_tracks, read_track_table


def test_perfect_policy_reproduces_real_tracks(processed):
    ids = read_track_table(processed)["track_id"].tolist()[:4]
    tracks = load_tracks(processed, ids)
    env = make_env(build_source(tracks))
    for track in tracks:
        env.reset(seed=0, options={"reference": track_reference(track)})
        rewards = []
        for action in env.perfect_actions:
            _, reward, terminated, _, info = env.step(action)
            rewards.append(reward)
        assert terminated
        assert info["dtw"] == pytest.approx(0.0, abs=1e-6)
        np.testing.assert_allclose(env.position, track.positions[-1], atol=1e-9)
        assert set(rewards) == {1.0}
