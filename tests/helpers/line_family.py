"""A tiny synthetic family shared by the baseline tests (not a test module itself)."""

from __future__ import annotations

import numpy as np

from aisdati.selftest.families import Family

LINE = Family(
    name="line",
    x=lambda t, a: t,
    y=lambda t, a: a * (1 + t),
    alpha_range=(0.5, 1.0),
    omega=2 * np.pi,
    steps=20,
)
"""Straight lines from (0, α) with slope α: heading and speed depend on α, which the state shows."""
