"""The synthetic trajectory families (`aisdati.selftest.families`): the paper's geometry,
diameters, families registered by name or given as objects."""

from __future__ import annotations

from dataclasses import replace

import gymnasium
import numpy as np
import pytest

from aisdati.dtw import dtw
from aisdati.errors import UserError
from aisdati.model.env import (
    ENV_ID,
    TrajectoryImitationEnv,
)
from aisdati.selftest.families import FAMILIES, Family, get_family, register_family
from aisdati.selftest.sources import FamilySource, make_family_env

PAPER = ("fixedstart", "ushaped", "circles", "ribbons")


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
