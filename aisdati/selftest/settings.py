"""The self-test's settings: its methods, the presets that name the set-up choices the paper
leaves to its code, and `SelftestSettings` (the whole protocol's knobs).

Methods: `dati`, `bc`, `bc-paper`, `ddpg-ti` (Table 1) and the ablated DATI variants
`dati-no-time-embedding`, `dati-no-reward-input` (Table 2, with `dati`: `ABLATION`).

Presets (`SELFTEST_PRESETS`):
- `paper` (the default): the authors' code (DLR-MI/dati) as far as it can be read: 100 episodes
  and the final actor (its running-sum early stopping never fires once the losses turn
  negative); Time2Vec frozen under the actors' adversarial loss (critic.trainable = False when
  the GAN is compiled); Ornstein-Uhlenbeck noise at the family's own dt for FixedStart, UShaped
  and Circles and Gaussian for Ribbons (its results script takes Ribbons from the Gaussian run);
  the exact bounding box and speeds in [s_min, s_max]; each seed scored on its own references
  (100 distinct ones). It is the default because its DATI median was lower than `ours`' on 3 of
  4 families over 10 seeds x 3 repeats (README, "the paper preset").
- `ours`: early stopping (patience 10) keeping the lowest-loss actor; the shared Time2Vec also
  learns from the actors' adversarial loss; Gaussian latent noise; the region is the family's box
  plus 10 % and speeds decode in [0, 1.25 x s_max]; every seed is scored on the same references.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from aisdati.errors import UserError
from aisdati.model.bc import BC_PAPER, BCConfig
from aisdati.model.dati import DATIConfig
from aisdati.model.ddpg_ti import DDPGTIConfig
from aisdati.model.noise import NoiseProcess
from aisdati.options import parse_names
from aisdati.selftest.families import Family, get_family
from aisdati.selftest.paper import PAPER_FAMILIES

METHODS = {
    "dati": "DATI",
    "bc": "BC",
    "bc-paper": "BC (paper's: no time input)",
    "ddpg-ti": "DDPG-TI",
    "dati-no-time-embedding": "DATI, no time embedding",
    "dati-no-reward-input": "DATI, no reward input",
}
"""Method names accepted by `--methods`, with their display labels."""

ABLATION = ("dati", "dati-no-time-embedding", "dati-no-reward-input")
TABLE2 = "table2"
"""`--methods table2`: the methods of the paper's ablation (`ABLATION`), reported as Table 2."""


def parse_methods(text: str | Sequence[str]) -> tuple[str, ...]:
    """'dati,bc' -> ('dati', 'bc'); an unknown name is a one-line `UserError`."""
    return parse_names(text, METHODS, "method")


NOISES = ("gaussian", "ou", "family")
"""Latent noise of the self-test's DATI: Gaussian, OU at `DATIConfig.ou_dt` for every family, or
"family": the authors' choice per family (`PAPER_NOISE`)."""

PAPER_NOISE = {"ribbons": "gaussian"}
"""The authors' latent noise per family where it is not OU at the family's dt."""


@dataclass(frozen=True)
class SelftestPreset:
    """The set-up choices that the paper leaves to its code (see the module docstring)."""

    keep: str = "best"
    """The actor a DATI seed ends with: "best" (lowest episode loss) or "final"."""
    patience: int = 10
    adversarial_time2vec: bool = True
    noise: str = "gaussian"
    exact_region: bool = False
    """The family's exact box and [s_min, s_max] speeds (`Family.exact`)."""
    distinct_references: bool = False
    """Each seed scored on references of its own instead of the family's shared ones."""


SELFTEST_PRESETS = {
    "paper": SelftestPreset(
        keep="final",
        patience=0,
        adversarial_time2vec=False,
        noise="family",
        exact_region=True,
        distinct_references=True,
    ),
    "ours": SelftestPreset(),
}
"""`aisdati selftest --preset`; the first is the default."""
DEFAULT_SELFTEST_PRESET = next(iter(SELFTEST_PRESETS))
_DEFAULT = SELFTEST_PRESETS[DEFAULT_SELFTEST_PRESET]


def get_preset(name: str) -> SelftestPreset:
    try:
        return SELFTEST_PRESETS[name]
    except KeyError:
        raise UserError(
            f"unknown self-test preset {name!r}; choose from {', '.join(SELFTEST_PRESETS)}"
        ) from None


@dataclass(frozen=True)
class SelftestSettings:
    """The protocol; defaults are the paper's (10 seeds, 10 unseen references, τ = 200) under
    the default preset; `preset_settings` builds them for any preset."""

    families: tuple[str, ...] = PAPER_FAMILIES
    seeds: int = 10
    references: int = 10
    steps: int | None = None
    """Steps per episode τ; None keeps each family's own (200 for the paper's)."""
    workers: int = 1
    """Local Dask processes the tasks run on (1: this process); see `aisdati.execution`."""
    scheduler: str | None = None
    """An existing Dask cluster's address to run the tasks on instead."""
    device: str = "cpu"
    """Where DATI's networks train and roll out (`aisdati.execution.device`); the baselines
    stay on the CPU."""
    eval_seed: int = 2024
    config: DATIConfig = field(default_factory=lambda: preset_config(_DEFAULT))
    methods: tuple[str, ...] = ("dati",)
    bc: BCConfig = field(default_factory=BCConfig)
    bc_paper: BCConfig = BC_PAPER
    ddpg: DDPGTIConfig = field(default_factory=DDPGTIConfig)
    preset: str = DEFAULT_SELFTEST_PRESET
    noise: str = _DEFAULT.noise
    """One of `NOISES`: DATI's latent noise per family (`noise_process`); `config.noise` only
    mirrors it."""
    exact_region: bool = _DEFAULT.exact_region
    distinct_references: bool = _DEFAULT.distinct_references
    repeats: int = 1
    """Runs of the whole protocol, repeat r on seeds r·seeds .. (r+1)·seeds − 1."""

    def dati_config(self, method: str) -> DATIConfig:
        """DATI's configuration for a DATI method name (the ablations switch one input off)."""
        if method == "dati-no-time-embedding":
            return self.config.with_network(time_embedding=False)
        if method == "dati-no-reward-input":
            return self.config.with_network(reward_input=False)
        return self.config

    def noise_process(self, fam: Family) -> NoiseProcess:
        """DATI's latent noise process for a family."""
        if self.noise == "family":
            kind = PAPER_NOISE.get(fam.name, "ou")
            return NoiseProcess(kind, fam.dt)
        return NoiseProcess(self.noise, self.config.ou_dt)


def preset_config(p: SelftestPreset, episodes: int = 100, noise: str | None = None) -> DATIConfig:
    """DATI's configuration under a preset (`noise` overrides the preset's)."""
    noise = noise or p.noise
    return DATIConfig(
        episodes=episodes,
        patience=p.patience,
        keep=p.keep,
        adversarial_time2vec=p.adversarial_time2vec,
        noise="ou" if noise == "family" else noise,  # the family's dt: `noise_process`
    )


def preset_settings(
    preset: str = DEFAULT_SELFTEST_PRESET,
    episodes: int = 100,
    noise: str | None = None,
    **fields: Any,
) -> SelftestSettings:
    """The settings of a named preset with every method's episode budget; `noise` overrides the
    preset's, `fields` set the rest of `SelftestSettings` (a `config` given there is kept)."""
    p = get_preset(preset)
    noise = noise or p.noise
    if noise not in NOISES:
        raise UserError(f"--noise must be one of {', '.join(NOISES)}, got {noise!r}")
    config = fields.pop("config", preset_config(p, episodes, noise))
    return SelftestSettings(
        config=config,
        bc=replace(BCConfig(), episodes=episodes),
        bc_paper=replace(BC_PAPER, episodes=episodes),
        ddpg=replace(DDPGTIConfig(), episodes=episodes),
        preset=preset,
        noise=noise,
        exact_region=p.exact_region,
        distinct_references=p.distinct_references,
        **fields,
    )


QUICK = {"seeds": 2, "references": 3, "steps": 40, "episodes": 3}
"""`--quick`: a smoke check of a fresh install in well under two minutes on two cores."""


def family_for(name: str, steps: int | None, exact: bool = False) -> Family:
    """A registered family with τ = `steps` (None: its own) and, if `exact`, the exact region."""
    fam = get_family(name)
    changes: dict[str, Any] = {}
    if steps is not None and steps != fam.steps:
        changes["steps"] = steps
    if exact != fam.exact:
        changes["exact"] = exact
    return replace(fam, **changes) if changes else fam


def settings_family(settings: SelftestSettings, name: str) -> Family:
    return family_for(name, settings.steps, settings.exact_region)
