"""How the AIS agent sees and moves, shared by training (`AISTrackSource`) and scoring
(`AISPolicy`), with the levers that make DATI follow real lanes as one configuration.

`LaneConfig()` is the paper's reading (preset `paper`): the state is the position scaled by a
lon/lat box around the training tracks (10 % margin), the time input is the step index, decision
ranges come from the largest perfect decisions, the kept actor is the one of the episode with the
lowest total loss, latent noise is Gaussian. Each lever departs from it in one documented way:

- `validation`: keep the actor whose rollouts from the first points of `validation_tracks`
  training tracks (best of `validation_rollouts`) are closest in mean great-circle DTW to those
  tracks, and stop early on that score: the WGAN loss is ~99 % critic offset and says nothing
  about how good the rollouts are.
- `region="corridor"`: the training tracks buffered by `corridor_km`, minus land where a
  coastline is available; moves that would leave it slide along its edge (`Corridor`).
- `state="motion"`: the state adds the agent's current course (sin, cos) and speed (scaled by the
  SOG range), from its last move, so the policy can continue a course ("the state space of DATI
  may easily be enlarged", section 7).
- `ranges="quantile"`: SOG and dt ranges from the 99th percentile of the perfect decisions
  (x 1.1) instead of the maxima: one 1-hour gap made the typical 3-minute dt sit at -0.91 on the
  tanh axis, where an error of 0.02 is 40 s.
- `noise="ou"`: Ornstein-Uhlenbeck latent noise at the data's median dt (hours), as the authors'
  code does for most of its families.
- `members=M`: M seeds of the same lane trained as one batched ensemble (each with its own
  validation and early stopping) and saved as one model; scoring draws its K rollouts (and K
  one-step draws) across the members in turn, so one seed's blind spot is covered by another's.
- `fourier=F`: the state adds sin and cos of the scaled position at F octaves (π, 2π, ...,
  2^(F-1) π), Fourier features (Tancik et al. 2020). The paper's actor sees the position through
  16 tanh units of a linear map; a lane that winds through a box needs a policy that changes
  course within a few hundred metres of a box tens of km wide, which such a small network
  cannot resolve: its rollouts turn at the wrong places, run into the corridor's edge and stop.
- `pretrain=N`: before the adversarial training, N passes of the forward actor's L1 pull over
  the training tracks as demonstrated (each report's state and perfect decision): behaviour
  cloning as a warm start, as GAIL is often started. From the first episode the agent then stays
  near its reference, so the pull pairs the reference's decisions with states near the
  reference's own. The paper starts from random actors. With validation the pretrained actor is
  a candidate for the kept one (episode 0), which an episode's actor must beat.
- `validate_by="step"`: validation scores an actor by its mean one-step error on the
  validation tracks (teacher-forced, as the `step` score) instead of its rollouts' DTW: the
  actor kept is the one best at what a model judging by one-step errors is used for.
- `crossfit=true`: member m of an M-member lane trains on every fold of the training tracks but
  fold m (folds by vessel), validates on fold m, and calibrates the threshold on it, so the
  threshold comes from tracks the member did not fit (`aisdati.detectors.dati`).

What was measured and not adopted (time by progress, a state-aware critic, a moving-average
actor, the variety loss, a goal in the state, folds by time) is in docs/results/tried.md; a card
that names one is refused (`REMOVED_LEVERS`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from aisdati.ais import AREA_PRESET, DEFAULT_PRESET, LAST_RELEASE_WITH_EXPERIMENTS
from aisdati.ais.corridor import Corridor
from aisdati.errors import UserError
from aisdati.geo import spherical_decision
from aisdati.model.rules import SphericalRule, mean_course

BOX_MARGIN = 0.1
"""The region box is the training tracks' box widened by this fraction of its span."""
MIN_MARGIN_DEG = 0.01
DECISION_HEADROOM = 1.1
RANGE_QUANTILE = 0.99
MAX_MEMBERS = 16
MAX_PRETRAIN = 1000
MAX_FOURIER = 12
REMOVED_LEVERS = {
    "time": "step",
    "critic": "decision",
    "average": 0.0,
    "variety": 1,
    "goal": False,
    "fold_by": "vessel",
}
"""Levers of earlier releases, measured and not adopted, with the value that meant "off": a card
that records one at that value reads as before; at another, it is refused."""


@dataclass(frozen=True)
class LaneConfig:
    """The AIS set-up of DATI; the defaults are the paper's (preset `paper`)."""

    validation: bool = False
    validation_tracks: int = 8
    validation_rollouts: int = 3
    region: str = "box"
    corridor_km: float = 2.0
    state: str = "position"
    ranges: str = "max"
    noise: str = "gaussian"
    members: int = 1
    pretrain: int = 0
    fourier: int = 0
    validate_by: str = "rollout"
    crossfit: bool = False

    def __post_init__(self) -> None:
        choices = {
            "region": ("box", "corridor"),
            "state": ("position", "motion"),
            "ranges": ("max", "quantile"),
            "noise": ("gaussian", "ou"),
            "validate_by": ("rollout", "step"),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise UserError(f"{name} must be one of {', '.join(allowed)}")
        if not (np.isfinite(self.corridor_km) and self.corridor_km > 0):
            raise UserError(f"corridor_km must be positive, got {self.corridor_km}")
        if not 0 <= self.fourier <= MAX_FOURIER:
            raise UserError(f"fourier must be in [0, {MAX_FOURIER}] octaves, got {self.fourier}")
        if not 0 <= self.pretrain <= MAX_PRETRAIN:
            raise UserError(f"pretrain must be in [0, {MAX_PRETRAIN}] epochs, got {self.pretrain}")
        if not 1 <= self.members <= MAX_MEMBERS:
            raise UserError(f"members must be in [1, {MAX_MEMBERS}], got {self.members}")
        if self.crossfit and self.members < 2:
            raise UserError("crossfit needs at least 2 members (one fold held out by each)")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> LaneConfig:
        """A recorded configuration; a removed lever at its "off" value is dropped, at another
        value refused in one line (`REMOVED_LEVERS`)."""
        data = dict(data or {})
        for key, off in REMOVED_LEVERS.items():
            if key in data and data.pop(key) != off:
                raise UserError(
                    f"lane lever {key!r} was removed after aisdati {LAST_RELEASE_WITH_EXPERIMENTS}"
                    f" (measured, not adopted): use that release to read this model, or retrain"
                )
        return cls(**data)


LANES = LaneConfig(
    validation=True,
    region="corridor",
    ranges="quantile",
    noise="ou",
    fourier=6,
    pretrain=50,
    members=3,
)
PRESETS: dict[str, LaneConfig] = {
    "paper": LaneConfig(),
    DEFAULT_PRESET: LANES,
    AREA_PRESET: replace(LANES, crossfit=True, state="motion", validate_by="step"),
}
"""Named configurations: `paper` reproduces the paper's set-up; `lanes` is the default, the
combination that measured best with `aisdati evaluate` on one route (docs/results); `area` is
`lanes` with cross-fitted calibration and the agent's last move in its state, the model of a
whole area (`--cluster all`, which trains it unless told otherwise): an area's lanes run both
ways, and at a point of a two-way lane a policy that sees only the position cannot tell which
way its vessel sails (its one-step errors on Kitimat fell from 2.4 km to 0.65 km with the
motion state), and validation by the one-step errors it judges with (`validate_by="step"`:
forward in time at sea, three trainings x three injection seeds, the one-step AUC rose on all
three areas measured, Kitimat 0.702 -> 0.770, NY Harbor 0.803 -> 0.823, Virginia Beach
0.836 -> 0.864; it mostly keeps the behaviour-cloned warm start, which the adversarial episodes
do not improve on for one-step predictions of a whole area). Their names are
`aisdati.ais.DEFAULT_PRESET` and `AREA_PRESET`."""
PRESET_SCORES: dict[tuple[str, str], str] = {
    (AREA_PRESET, "dati"): "step",
    (AREA_PRESET, "bc"): "stepspread",
}
"""The score a policy of a preset and method judges by unless `--score` says otherwise
(`ModelCard.score`; every other preset, and `nearest`: lane). The area preset's one-step
predictions ranked the anomalies a vessel could sail better than its lane on both areas,
forward in time (Kitimat 0.737 against 0.597, NY Harbor 0.786 against 0.674;
docs/results/forward.md): one model of a whole area predicts the next report far better than it
generates a whole track. BC's draws come from its Gaussian, wide where it learnt a report is
uncertain, so its errors over their spread (`stepspread`) ranked and flagged best of every
score measured on three areas (the same page)."""


READS_REPORTED_MOTION = {(AREA_PRESET, "bc")}
"""The presets and methods whose step scores also judge where each report's own SOG and COG
put the vessel (`ScoreSettings.reported_motion`): the area's default model, where it raised the
ROC AUC of shifted stretches and noised reported course and speed on Kitimat by 0.070 (95 %:
0.044-0.091) and changed detours, jumps and loiters by -0.002 (docs/results/
reported-motion.md). The paper's presets judge positions, as the paper does."""


def reads_reported_motion(preset: str | None, method: str) -> bool:
    """Whether a card's preset (with its overrides, "area + members=5") and method calibrate
    their step scores with the reported motion (`READS_REPORTED_MOTION`)."""
    return ((preset or "").split(" + ")[0], method) in READS_REPORTED_MOTION


def preset_score(preset: str | None, method: str) -> str:
    """`PRESET_SCORES`' score of a card's preset name, which carries its overrides ("area +
    members=5"): the preset's own, whatever was overridden."""
    base = (preset or "").split(" + ")[0]
    return PRESET_SCORES.get((base, method), "lane")


def lane_config(preset: str, overrides: Sequence[str] = ()) -> LaneConfig:
    """A preset with `KEY=VALUE` overrides (`validation=true`, `region=corridor`, ...); any
    mistake is a one-line `UserError`."""
    if preset not in PRESETS:
        raise UserError(f"unknown preset {preset!r}; choose from {', '.join(PRESETS)}")
    values = PRESETS[preset].to_dict()
    for item in overrides:
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in values:
            known = ", ".join(values)
            raise UserError(f"--lane {item!r}: expected KEY=VALUE with KEY one of {known}")
        kind = type(values[key])
        try:
            if kind is bool:
                if value.strip().lower() not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(value)
                values[key] = value.strip().lower() in ("true", "1", "yes")
            else:
                values[key] = kind(value.strip())
        except ValueError:
            raise UserError(f"--lane {item!r}: {value!r} is not a {kind.__name__}") from None
    return LaneConfig(**values)


def state_width(state: str, fourier: int) -> int:
    """Width of the agent's state: the position (2) or position and motion (5), plus sin and
    cos of both coordinates at each Fourier octave (the layout of `AISSpace.features`)."""
    return (5 if state == "motion" else 2) + 4 * fourier


def region_box(positions: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    allpos = np.concatenate(positions)
    lo, hi = allpos.min(axis=0), allpos.max(axis=0)
    margin = np.maximum((hi - lo) * BOX_MARGIN, MIN_MARGIN_DEG)
    return lo - margin, hi + margin


def fit_rule(
    positions: Sequence[np.ndarray], dts: Sequence[np.ndarray], ranges: str = "max"
) -> SphericalRule:
    """The spherical rule with decision ranges covering the training tracks' perfect decisions
    (all of them, or all but the top 1 %), its COG window centred on the tracks'
    distance-weighted mean course."""
    base = SphericalRule(max_sog=1.0, max_dt_h=1.0)
    decisions = np.concatenate(
        [base.perfect_decisions(p, d) for p, d in zip(positions, dts, strict=True)]
    )
    pick = np.max if ranges == "max" else lambda x: np.quantile(x, RANGE_QUANTILE)
    max_sog = float(pick(decisions[:, 0])) * DECISION_HEADROOM
    max_dt = float(pick(decisions[:, 2])) * DECISION_HEADROOM
    center = mean_course(decisions[:, 1], weights=decisions[:, 0] * decisions[:, 2])
    return SphericalRule(max_sog=max(max_sog, 1.0), max_dt_h=max(max_dt, 1e-3), cog_center=center)


@dataclass
class AISSpace:
    """The agent's region, decision rule and view of itself."""

    bounds: tuple[np.ndarray, np.ndarray]
    rule: SphericalRule
    config: LaneConfig
    corridor: Corridor | None = None

    @classmethod
    def fit(
        cls, positions: Sequence[np.ndarray], dts: Sequence[np.ndarray], config: LaneConfig
    ) -> AISSpace:
        corridor = None
        if config.region == "corridor":
            corridor = Corridor.from_tracks(positions, config.corridor_km, on_land=_on_land())
        return cls(region_box(positions), fit_rule(positions, dts, config.ranges), config, corridor)

    @property
    def state_dim(self) -> int:
        return state_width(self.config.state, self.config.fourier)

    @property
    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.config.state == "motion":
            lo, hi = np.array([0.0, 0.0, -1.0, -1.0, 0.0]), np.array([1.0, 1.0, 1.0, 1.0, 2.0])
        else:
            lo, hi = np.zeros(2), np.ones(2)
        waves = 4 * self.config.fourier
        return np.r_[lo, -np.ones(waves)], np.r_[hi, np.ones(waves)]

    def contains(self, points: np.ndarray) -> np.ndarray:
        inside = self.in_box(points)
        if self.corridor is not None:
            inside &= self.corridor.allowed(np.asarray(points, np.float64))
        return inside

    def in_box(self, points: np.ndarray) -> np.ndarray:
        """Whether each point is finite and inside the region's box (whatever the corridor)."""
        points = np.asarray(points, np.float64)
        lo, hi = self.bounds
        return np.all(np.isfinite(points), axis=-1) & np.all(
            (points >= lo) & (points <= hi), axis=-1
        )

    def resolve(self, position: np.ndarray, proposed: np.ndarray) -> np.ndarray:
        """Rows [N, 2] (or one point): where each move ends (sticking or sliding). The corridor
        keeps an agent in, it does not hold one out: an agent outside it (a track that starts
        off the training tracks' lanes) takes moves, turned if need be, that take it no farther
        from the corridor, so it finds its way in (`Corridor.slide`)."""
        single = np.ndim(proposed) == 1
        pos, prop = np.atleast_2d(position), np.atleast_2d(proposed)
        if self.corridor is not None:
            prop = self.corridor.slide(pos, prop)
        out = np.where(self.in_box(prop)[:, None], prop, pos)
        return out[0] if single else out

    def features(self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """The state of agents at `positions` (previously at `previous`, `dts` hours before)."""
        positions = np.asarray(positions, np.float64)
        scaled = self._scaled(positions)
        parts = [scaled]
        if self.config.state == "motion":
            parts.append(self._motion(positions, previous, dts))
        parts.append(self._waves(scaled))
        return np.concatenate(parts, axis=-1)

    def _scaled(self, positions: np.ndarray) -> np.ndarray:
        lo, hi = self.bounds
        return np.clip((positions - lo) / (hi - lo), 0.0, 1.0)

    def _waves(self, scaled: np.ndarray) -> np.ndarray:
        """sin and cos of the scaled coordinates at each Fourier octave ([..., 0] without)."""
        angles = scaled[..., None] * (np.pi * 2.0 ** np.arange(self.config.fourier))
        waves = np.concatenate([np.sin(angles), np.cos(angles)], axis=-1)
        return waves.reshape((*scaled.shape[:-1], -1))

    def _motion(self, positions: np.ndarray, previous: np.ndarray, dts: np.ndarray) -> np.ndarray:
        """The agent's current course (sin, cos) and speed (scaled by the SOG range), from its
        last move; zeros before it has moved."""
        previous = np.asarray(previous, np.float64)
        dts = np.asarray(dts, np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            sog, cog = spherical_decision(
                previous[..., 0], previous[..., 1], positions[..., 0], positions[..., 1], dts
            )
        moving = (dts > 0) & (sog > 0) & np.isfinite(sog)
        rad = np.radians(cog)
        return np.stack(
            [
                np.where(moving, np.sin(rad), 0.0),
                np.where(moving, np.cos(rad), 0.0),
                np.where(moving, np.clip(sog / self.rule.max_sog, 0.0, 2.0), 0.0),
            ],
            axis=-1,
        )


def _on_land():
    """The coastline's land test, where the package that ships one is installed."""
    try:
        from aisdati.coastline import on_land
    except ImportError:
        return None
    return on_land
