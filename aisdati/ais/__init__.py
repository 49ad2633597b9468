"""DATI on AIS tracks: the agent's view and moves (space), the navigable corridor, the learnt
policy, training and the model card.

`DEFAULT_PRESET` and the scores' names live here, free of imports, so that the command line can
name them without loading numpy, and the model card can check its score."""

DEFAULT_PRESET = "lanes"
"""The lane preset used when none is given (`aisdati.ais.space.PRESETS`)."""
AREA_PRESET = "area"
"""The lane preset of a model of a whole area (`--cluster all`) when none is given: calibrated
by cross-fitting."""
AREA_METHOD = "bc"
"""The detector `train --cluster all` fits when `--method` is not given: cross-fitted BC, judged
by `stepspread`, measured above DATI's one-step score on Kitimat, NY Harbor and Virginia Beach
forward in time by a rule written before (docs/results/forward.md); a cluster or route trains
the paper's DATI (`DEFAULT_METHOD`)."""
DEFAULT_METHOD = "dati"
"""The detector `train` fits for a cluster or route when `--method` is not given."""
SCORES = (
    "rollout",
    "step",
    "steprate",
    "stepspread",
    "stepod",
    "lane",
    "both",
    "steplane",
    "steptraffic",
    "area",
)
"""The ways a detector scores a track (`aisdati.detectors.scoring.ScoreSettings.score`)."""
SCORE_UNITS = {"steprate": "m/s", "stepspread": "x spread", "stepod": "rarity"}
"""The unit of each score not in metres but for `RATIO_SCORES` (multiples of medians):
`steprate` is the one-step errors over their report intervals, `stepspread` over the spread of
the model's own draws, `stepod` the rarer of `stepspread` and the origin-destination term
among the training tracks' own (-log10 of a share, `aisdati.detectors.rarity`)."""
RATIO_SCORES: dict[str, tuple[str, str]] = {
    "both": ("rollout", "step"),
    "steplane": ("step", "lane"),
    "steptraffic": ("step", "traffic"),
}
"""Scores that add two others, each divided by the median of the training tracks' own scores of
its kind, so that neither dominates by its unit of scale (a track as typical as the median
training track scores 2). `steplane` joins what the one-step score sees (a move the traffic
would not make: a jump) to what the lane sees (a place the traffic does not go: a detour);
`steptraffic` joins it to the distance to the training tracks themselves (`traffic`: where the
area's vessels went, not where the policy sails)."""
STEP_SCORES = ("step", "steprate", "stepspread")
"""Scores of the teacher-forced one-step errors: computed together from the same K draws."""
LANE_SCORES = ("lane", "steplane", "steptraffic", "area")
"""Scores whose calibration rests on the lane settings (`ScoreSettings.calibrated_with`)."""


def score_unit(score: str) -> str:
    """The unit of a score's raw values: metres, `SCORE_UNITS`'s, or (a sum of ratios,
    `RATIO_SCORES`) multiples of the training tracks' medians."""
    return "x median" if score in RATIO_SCORES else SCORE_UNITS.get(score, "m")


def readable_value(value: float, unit: str) -> float:
    """A raw value of `unit` as a person reads it: metres in km, any other unit as it is."""
    return value / 1000 if unit == "m" else value


def score_text(value: float, score: str) -> str:
    """A raw score for a person: km for metres, else the value and its unit."""
    unit = score_unit(score)
    return f"{readable_value(value, unit):,.2f} {'km' if unit == 'm' else unit}"
