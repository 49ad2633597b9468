"""DATI on AIS tracks: the agent's view and moves (space), the navigable corridor, the learnt
policy, training and the model card.

`DEFAULT_PRESET` and `SCORES` live here, free of imports, so that the command line can name
them without loading numpy, and the model card can check its score."""

DEFAULT_PRESET = "lanes"
"""The lane preset used when none is given (`aisdati.ais.space.PRESETS`)."""
AREA_PRESET = "area"
"""The lane preset of a model of a whole area (`--cluster all`) when none is given: calibrated
by cross-fitting."""
SCORES = ("rollout", "step", "lane", "both", "area")
"""The ways a detector scores a track (`aisdati.detectors.scoring.ScoreSettings.score`)."""
