"""`import aisdati` registers the Gymnasium environment, with a string entry point, and stays
light (no torch, no numba)."""

from __future__ import annotations

import subprocess
import sys

import gymnasium

import aisdati


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )


def test_make_after_import_aisdati_alone():
    res = _python(
        "import aisdati, gymnasium\n"
        "env = gymnasium.make('aisdati/TrajectoryImitation-v0')\n"
        "obs, _ = env.reset(seed=0)\n"
        "assert env.unwrapped.source.family.name == 'circles', env.unwrapped.source\n"
        "env = gymnasium.make('aisdati/TrajectoryImitation-v0', family='ushaped')\n"
        "assert env.unwrapped.source.family.name == 'ushaped'\n"
    )
    assert res.returncode == 0, res.stderr


def test_import_aisdati_is_light():
    res = _python(
        "import sys, aisdati\n"
        "heavy = [m for m in ('torch', 'numba', 'aisdati.model.env') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    assert res.returncode == 0, res.stderr


def test_registered_once_with_a_string_entry_point():
    spec = gymnasium.spec(aisdati.ENV_ID)
    assert spec.entry_point == "aisdati.selftest.sources:make_family_env"
    from aisdati.model import env

    assert env.ENV_ID == aisdati.ENV_ID
    assert gymnasium.spec(aisdati.ENV_ID) is spec  # importing env.py did not register again
