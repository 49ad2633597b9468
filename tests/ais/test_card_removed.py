"""What was measured and not adopted left the package (issue 58): a model card or saved
configuration that names a removed score or lever is refused in one line that names the last
release that reads it; the same setting at its "off" value (every card of that release records
every lever) still loads."""

from __future__ import annotations

import json
import shutil

import pytest

from aisdati.ais import LAST_RELEASE_WITH_EXPERIMENTS
from aisdati.ais.space import REMOVED_LEVERS
from aisdati.ais.training import TrainSettings
from aisdati.detectors import load_detector
from aisdati.detectors.nearest import NearestDetector
from aisdati.errors import UserError
from aisdati.model.dati import DATIConfig
from aisdati.scores import REMOVED_SCORES, SCORES
from aisdati.tracks.store import load_tracks, read_track_table


@pytest.fixture(scope="module")
def saved(kitimat, tmp_path_factory):
    table = read_track_table(kitimat)
    ids = [int(i) for i in table.loc[table["route"] == "route-1", "track_id"]][:6]
    folder = tmp_path_factory.mktemp("model")
    det = NearestDetector(TrainSettings(cluster="route-1")).fit(load_tracks(kitimat, ids))
    det.save(folder / det.name)
    return folder / det.name


def edited(saved, tmp_path, edit):
    stem = tmp_path / saved.name
    for f in saved.parent.glob(f"{saved.name}.*"):
        shutil.copy(f, tmp_path / f.name)
    card = json.loads(stem.with_suffix(".json").read_text())
    edit(card)
    stem.with_suffix(".json").write_text(json.dumps(card))
    return stem


@pytest.mark.parametrize("score", REMOVED_SCORES)
def test_a_card_judging_by_a_removed_score_is_refused_naming_the_release(saved, tmp_path, score):
    stem = edited(saved, tmp_path, lambda card: card.update(score=score))
    with pytest.raises(UserError, match=rf"score '{score}' was removed after aisdati "
                       rf"{LAST_RELEASE_WITH_EXPERIMENTS}.*use that release"):  # fmt: skip
        load_detector(stem)
    assert score not in SCORES


@pytest.mark.parametrize("lever", sorted(REMOVED_LEVERS))
def test_a_removed_lever_loads_when_off_and_is_refused_when_on(saved, tmp_path, lever):
    off = REMOVED_LEVERS[lever]
    on = {"time": "progress", "critic": "state", "average": 0.9, "variety": 4, "goal": True,
          "fold_by": "time"}[lever]  # fmt: skip
    stem = edited(saved, tmp_path, lambda card: card["lane_config"].update({lever: off}))
    assert load_detector(stem).card.lane_config == load_detector(saved).card.lane_config
    stem = edited(saved, tmp_path, lambda card: card["lane_config"].update({lever: on}))
    with pytest.raises(UserError, match=rf"lane lever '{lever}' was removed after aisdati "
                       rf"{LAST_RELEASE_WITH_EXPERIMENTS}"):  # fmt: skip
        load_detector(stem)


def test_removed_network_settings_load_when_off_and_are_refused_when_on():
    base = DATIConfig().to_dict()
    old = {**base, "pretrain_variety": 1, "actor_average": 0.0,
           "network": {**base["network"], "conditional_critic": False}}  # fmt: skip
    assert DATIConfig.from_dict(old) == DATIConfig()
    for key, value in (("pretrain_variety", 4), ("actor_average", 0.5)):
        with pytest.raises(ValueError, match=f"{key} was removed"):
            DATIConfig.from_dict({**base, key: value})
