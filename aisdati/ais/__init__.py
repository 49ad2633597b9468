"""DATI on AIS tracks: the agent's view and moves (space), the navigable corridor, the learnt
policy, training and the model card.

`DEFAULT_PRESET` and the scores' names live here, free of imports, so that the command line can
name them without loading numpy, and the model card can check its score."""

DEFAULT_PRESET = "lanes"
"""The lane preset used when none is given (`aisdati.ais.space.PRESETS`)."""
AREA_PRESET = "area"
"""The lane preset of a model of a whole area (`--cluster all`) when none is given: calibrated
by cross-fitting."""
SCORES = ("rollout", "step", "lane", "both", "steplane", "steptraffic", "area")
"""The ways a detector scores a track (`aisdati.detectors.scoring.ScoreSettings.score`)."""
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

LANE_SCORES = ("lane", "steplane", "steptraffic", "area")
"""Scores whose calibration rests on the lane settings (`ScoreSettings.calibrated_with`)."""
