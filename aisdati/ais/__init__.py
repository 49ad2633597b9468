"""DATI on AIS tracks: the agent's view and moves (space), the navigable corridor, the learnt
policy, training and the model card.

`DEFAULT_PRESET` lives here, free of imports, so that the command line can name the default
lane preset without loading numpy."""

DEFAULT_PRESET = "lanes"
"""The lane preset used when none is given (`aisdati.ais.space.PRESETS`)."""
AREA_PRESET = "area"
"""The lane preset of a model of a whole area (`--cluster all`) when none is given: calibrated
by cross-fitting."""
