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
SCORES = ("rollout", "step", "stepspread", "lane")
"""The ways a detector scores a track (`aisdati.detectors.scoring.ScoreSettings.score`): the
paper's (`rollout`) and the ones a preset judges by. What was measured and not adopted is listed
in docs/results/tried.md; its code is in git history."""
REMOVED_SCORES = ("steprate", "steptraffic", "steplane", "stepod", "both", "area")
"""Scores of earlier releases, measured and not adopted: a card that judges by one is refused
with `LAST_RELEASE_WITH_EXPERIMENTS` named."""
LAST_RELEASE_WITH_EXPERIMENTS = "0.3.0"
"""The last release that reads cards of the removed scores and lane levers."""
SCORE_UNITS = {"stepspread": "x spread"}
"""The unit of each score not in metres: `stepspread` is the one-step errors over the spread of
the model's own draws."""
STEP_SCORES = ("step", "stepspread")
"""Scores of the teacher-forced one-step errors: computed together from the same K draws."""


def score_unit(score: str) -> str:
    """The unit of a score's raw values: metres, or `SCORE_UNITS`'s."""
    return SCORE_UNITS.get(score, "m")


def readable_value(value: float, unit: str) -> float:
    """A raw value of `unit` as a person reads it: metres in km, any other unit as it is."""
    return value / 1000 if unit == "m" else value


def score_text(value: float, score: str) -> str:
    """A raw score for a person: km for metres, else the value and its unit."""
    unit = score_unit(score)
    return f"{readable_value(value, unit):,.2f} {'km' if unit == 'm' else unit}"
