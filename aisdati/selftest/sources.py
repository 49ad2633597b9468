"""The synthetic families as a `ReferenceSource` of the imitation game, and the Gymnasium entry
point of `aisdati.ENV_ID` (so the domain-free env never imports the self-test)."""

from __future__ import annotations

from typing import Any

import numpy as np

from aisdati.model.env import Reference, ReferenceSource, TrajectoryImitationEnv
from aisdati.model.rules import PlanarRule
from aisdati.selftest.families import Family, get_family


class FamilySource(ReferenceSource):
    """References drawn from a synthetic family, α uniform in its interval per episode."""

    def __init__(self, family: Family) -> None:
        self.family = family
        low, high = family.speed_range
        self.rule = PlanarRule(dt=family.dt, max_speed=high, min_speed=low)
        self.bounds = family.bounds
        self.max_steps = family.steps

    def reference(self, alpha: float) -> Reference:
        dts = np.full(self.family.steps, self.family.dt)
        return Reference(self.family.reference(alpha), dts, {"alpha": alpha})

    def sample(self, rng: np.random.Generator) -> Reference:
        return self.reference(self.family.sample_alpha(rng))

    def normalize(self, distance: float, path_length: int) -> float:
        return distance / self.family.diameter


def make_family_env(family: str | Family = "circles", **kwargs: Any) -> TrajectoryImitationEnv:
    """Environment over a synthetic family, by name or object (the entry point of `ENV_ID`)."""
    fam = get_family(family) if isinstance(family, str) else family
    return TrajectoryImitationEnv(FamilySource(fam), **kwargs)
