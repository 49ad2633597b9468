"""DATI on AIS tracks: the agent's view and moves (space), the navigable corridor, the learnt
policy, training and the model card.

`DEFAULT_PRESET` and the default methods live here, free of imports, so that the command line can
name them without loading numpy."""

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
LAST_RELEASE_WITH_EXPERIMENTS = "0.3.0"
"""The last release that reads cards of the removed scores and lane levers
(`aisdati.scores.REMOVED_SCORES`, `aisdati.ais.space.REMOVED_LEVERS`)."""
