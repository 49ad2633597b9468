"""aisdati: maritime AIS anomaly detection with domain-adaptive trajectory imitation (DATI)."""

from aisdati.startup import guard_startup

guard_startup()  # first: a Ctrl-C while the CLI imports exits 130 without a traceback

__version__ = "0.3.0"

ENV_ID = "aisdati/TrajectoryImitation-v0"
"""Gymnasium id of the trajectory-imitation environment over a synthetic family:
`gymnasium.make(ENV_ID, family="circles")` once `aisdati` is imported."""


def _register_envs() -> None:
    """Register ENV_ID with a string entry point, so that importing aisdati stays light (the
    environment module, numba and torch load only when gymnasium.make builds one). The only
    place where aisdati registers with Gymnasium."""
    try:
        import gymnasium
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="aisdati.selftest.sources:make_family_env")


_register_envs()
