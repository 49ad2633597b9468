"""The ways a detector scores a track, each declared once (`Score`): its name, its unit, the pass
that computes it, what the track is compared with, what its profile shows at each report, what it
measures and how its threshold is calibrated. `--score`, the model card, report.json, the tables,
the figures and the maps read them from `SCORES`; nothing else spells a score's properties.

Every score is calibrated the same way, on the training tracks' own scores: a threshold is their
(1 - contamination) quantile (`aisdati.detectors.base.Detector.threshold`); a cross-fitted model
scores each training track with the member that did not fit it, and a `member_wise` score is then
also judged member by member, as its threshold was made.

This module imports nothing heavy, so that the command line can name the scores quickly.
"""

from __future__ import annotations

from dataclasses import dataclass

STEP_ERRORS = "one-step prediction error (m)"
"""What the step scores' profiles measure at each report."""


@dataclass(frozen=True)
class Score:
    """One way of scoring a track; see the module docstring."""

    name: str
    unit: str
    """"m" (metres) or the unit of a ratio ("x spread")."""
    source: str
    """The pass that computes it: "rollouts" (free rollouts of the policy), "steps" (its
    teacher-forced one-step draws) or "tracks" (the training tracks themselves: nearest)."""
    evidence: str
    """What the track is compared with, for legends and the GeoJSON."""
    profile: str
    """What its profile (profiles.parquet, the evidence figures' lower panel) measures."""
    definition: str
    """report.json's `score_definition`."""
    member_wise: bool = False
    """On a cross-fitted model, scored member by member and averaged, as calibrated."""

    @property
    def digits(self) -> int:
        """Decimals its calibration scores keep in the card: centimetres, or 4 for a ratio."""
        return 2 if self.unit == "m" else 4

    def readable(self, value: float) -> float:
        """A raw value as a person reads it: metres in km, a ratio as it is."""
        return value / 1000 if self.unit == "m" else value

    @property
    def readable_unit(self) -> str:
        return "km" if self.unit == "m" else self.unit

    def text(self, value: float) -> str:
        """`12.34 km` or `1.23 x spread`."""
        return f"{self.readable(value):,.2f} {self.readable_unit}"


TAIL = "mean of the largest 10% of"
SCORES: dict[str, Score] = {
    s.name: s
    for s in (
        Score(
            "rollout", "m", "rollouts", "best rollout", "distance to the best rollout (m)",
            "best of K free rollouts: great-circle DTW / warping-path length (m); the paper's",
        ),
        Score(
            "lane", "m", "rollouts", "best rollout", "distance to the lane (m)",
            f"{TAIL} each report's distance to the nearest point of the free rollouts of twice "
            "the track's steps and of one rollout from each training track's start (nearest: of "
            "the training tracks starting within near_km), sqrt(d^2 + (lane_course_km "
            "sin(dcourse / 2))^2) for great-circle distance d and course difference dcourse (m)",
        ),
        Score(
            "step", "m", "steps", "one-step predictions", STEP_ERRORS,
            f"teacher-forced: {TAIL} the best-of-K one-step prediction errors (m); where the "
            "model reads the reported motion, each draw's error is the larger of its distances "
            "to the next report and to where the report's SOG and COG put the vessel",
        ),
        Score(
            "stepspread", "x spread", "steps", "one-step predictions", STEP_ERRORS,
            f"teacher-forced: {TAIL} the best-of-K one-step prediction errors, each over the K "
            "draws' spread (root mean square distance from their centroid) plus 10 m "
            "(multiples of the spread)",
            member_wise=True,
        ),
    )
}  # fmt: skip
"""The scores a policy (dati, bc) judges by, the paper's first: what `--score` offers."""
NEAREST = Score(
    "nearest", "m", "tracks", "nearest training track",
    "distance to the nearest training track (m)",
    "great-circle DTW / warping-path length (m) to the nearest training track starting within "
    "near_km",
)  # fmt: skip
"""The nearest baseline's own score (it also scores `lane`, against its training tracks)."""
REMOVED_SCORES = ("steprate", "steptraffic", "steplane", "stepod", "both", "area")
"""Scores of earlier releases, measured and not adopted (docs/results/tried.md): a card that
judges by one is refused, naming the last release that reads it
(`aisdati.ais.LAST_RELEASE_WITH_EXPERIMENTS`)."""


def score(name: str) -> Score:
    """The `Score` called `name` (`SCORES`, or nearest's)."""
    return NEAREST if name == NEAREST.name else SCORES[name]


def scores_from(source: str) -> tuple[str, ...]:
    """The names of the policy scores one pass computes together (`Score.source`)."""
    return tuple(s.name for s in SCORES.values() if s.source == source)
