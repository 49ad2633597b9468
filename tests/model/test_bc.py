"""The self-test's BC baseline (`aisdati.model.bc`): it learns a straight-line family, each
seed of an ensemble trains as if alone, and its policy has the paper's shape."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from aisdati.model.bc import BCConfig, BCTrainer, bc_act
from aisdati.model.rollout import rollout_policy
from aisdati.selftest.protocol import evaluation_references
from aisdati.selftest.sources import make_family_env
from tests.helpers.line_family import LINE


def _bc_scores(trainer: BCTrainer, refs: int = 5) -> np.ndarray:
    references = evaluation_references(LINE, refs, 1)
    act = bc_act(trainer.policy, refs, seed=1)
    grid = [[make_family_env(LINE) for _ in references] for _ in trainer.seeds]
    return rollout_policy(act, grid, [references] * len(trainer.seeds))[1]


def test_bc_learns_a_straight_line_family_in_a_few_hundred_updates():
    torch.set_num_threads(1)
    untrained = _bc_scores(BCTrainer([make_family_env(LINE)], [0], BCConfig(episodes=0)))
    trainer = BCTrainer([make_family_env(LINE)], [0], BCConfig(episodes=30))
    trainer.train()  # 30 episodes x 20 pairs, one update of 64 per pair: 600 updates
    scores = _bc_scores(trainer)
    assert untrained.min() > 0.3
    assert scores.max() < 0.03, scores  # stochastic rollouts on their own predictions
    assert trainer.losses[-1][0] < trainer.losses[0][0]


def test_bc_ensemble_trains_each_seed_as_if_alone():
    cfg = BCConfig(episodes=2, updates_per_episode=5)
    pair = BCTrainer([make_family_env(LINE) for _ in range(2)], [3, 4], cfg)
    alone = BCTrainer([make_family_env(LINE)], [4], cfg)
    pair.train(), alone.train()
    for a, b in zip(pair.losses, alone.losses, strict=True):
        assert a[1] == pytest.approx(b[0], rel=1e-5, abs=1e-6)


def test_bc_policy_has_the_papers_shape():
    policy = BCTrainer([make_family_env(LINE)], [0]).policy
    assert policy.feature_width == 156
    widths = [w.shape[1] for w in policy.hidden.first.weights]
    assert widths == [80, 1, 75]  # 80 state features + Time2Vec(76)
    hidden = [m for m in policy.hidden.rest if hasattr(m, "weight")]
    assert len(hidden) == 3 and all(m.weight.shape[1:] == (32, 32) for m in hidden)
