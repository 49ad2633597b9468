"""The model card: read and checked as a whole (every bad field one line naming it), written
back as the same JSON, and the training tracks it names found again by vessel and time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from aisdati.ais.card import ModelCard, card_warnings, training_mask
from aisdati.errors import UserError


def _card() -> dict:
    return {
        "format": "aisdati-dati/1", "kind": "ais", "state_dim": 2, "decision_dim": 3,
        "seeds": [0], "cluster": "up", "seed": 0, "epsilon_m": 500.0,
        "config": {"noise": "gaussian", "noise_sigma": 0.3, "ou_theta": 0.15, "ou_dt": 0.01,
                   "network": {"latent_dim": 64}},
        "rule": {"max_sog_kn": 20.0, "max_dt_h": 0.1, "cog_center_deg": 10.0},
        "region": {"lon": [-80.0, -79.0], "lat": [25.0, 26.0]},
        "data": {"track_ids": [4, 7], "points": 900, "start_points": [[-79.5, 25.5], [-79.6, 25.4]],
                 "track_keys": [[366000001, "2015-01-01T00:00:00+00:00",
                                 "2015-01-01T05:00:00+00:00"],
                                [366000002, "2015-01-02T00:00:00+00:00",
                                 "2015-01-02T04:00:00+00:00"]]},
        "training": {"finished": True, "episodes_run": 3},
    }  # fmt: skip


def test_a_valid_card_passes_and_keys_match_by_vessel_and_overlap():
    import pandas as pd

    card = ModelCard.from_dict(_card(), Path("up.json"))
    tracks = pd.DataFrame(
        {
            "track_id": [0, 1, 2, 3],
            "mmsi": [366000001, 366000001, 366000002, 366000003],
            "start": pd.to_datetime(
                ["2015-01-01T00:10", "2015-01-01T06:00", "2015-01-01T23:00", "2015-01-02T01:00"],
                utc=True,
            ),
            "end": pd.to_datetime(
                ["2015-01-01T04:50", "2015-01-01T09:00", "2015-01-02T02:00", "2015-01-02T03:00"],
                utc=True,
            ),
        }
    )
    # ids 4 and 7 are nowhere; by vessel and time: track 0 (inside the first training track's
    # span) and track 2 (overlaps the second's); not the later voyage 1, nor another vessel's 3
    assert list(training_mask(card, tracks)) == [True, False, True, False]
    card.data.track_keys = None  # a card from before the keys: by track id
    tracks["track_id"] = [4, 5, 6, 7]
    assert list(training_mask(card, tracks)) == [True, False, False, True]


def test_the_state_width_must_match_the_lane_configuration():
    card = _card()
    card["lane_config"] = {"state": "motion", "fourier": 3}
    with pytest.raises(UserError, match="state_dim must be one of 17, got 2"):
        ModelCard.from_dict(json.loads(json.dumps(card)), Path("up.json"))
    card["state_dim"] = 17
    ModelCard.from_dict(json.loads(json.dumps(card)), Path("up.json"))
    card["lane_config"]["fourier"] = 2.5
    with pytest.raises(UserError, match=r"lane_config\.fourier must be an integer"):
        ModelCard.from_dict(json.loads(json.dumps(card)), Path("up.json"))


@pytest.mark.parametrize(
    "path, value, message",
    [
        (
            ("rule", "max_sog_kn"),
            -3,
            "rule.max_sog_kn must be a finite number in (0, 1000], got -3",
        ),
        (("rule", "max_dt_h"), True, "rule.max_dt_h must be a finite number"),
        (("seeds",), [0, 1], "seeds must be a list of 1, got 2 items"),
        (("kind",), "synthetic", "is not an AIS model card"),
        (
            ("data", "track_keys"),
            [[366000001, "2015-01-01T00:00:00Z"], [366000002, "2015-01-02T00:00:00Z", "noon"]],
            "data.track_keys[1][2] must be an ISO 8601 time, got 'noon'",
        ),
        (
            ("data", "track_keys"),
            [[366000001, 20150101], [366000002, "2015-01-02T00:00:00Z"]],
            "data.track_keys[0][1] must be an ISO 8601 time, got 20150101",
        ),
        (
            ("data", "track_keys"),
            [[366000001, "2015-01-01T00:00:00Z"], [366000002, "2015-01-02T05:00", "2015-01-02"]],
            "data.track_keys[1] must be a start before its end",
        ),
    ],
)
def test_card_errors_name_the_field(path, value, message):
    card = _card()
    node = card
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(UserError) as err:
        ModelCard.from_dict(json.loads(json.dumps(card)), Path("models/up.json"))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_card_reads_back_from_the_json_it_writes():
    doc = json.loads(json.dumps({**_card(), "calibration": {"rollout": [1.0, 2.5]}}))
    card = ModelCard.from_dict(doc, Path("up.json"))
    assert card.method == "dati" and card.rule.cog_center_deg == 10.0
    assert card.region.bounds[1].tolist() == [-79.0, 26.0]
    written = card.to_dict()
    assert ModelCard.from_dict(json.loads(json.dumps(written)), Path("up.json")) == card
    # every field it held is written back as it was; it adds its method, the lane
    # configuration and the score it lacked (the paper's, the lane) and the rule's description
    rule = {"name": "spherical (eq. 5)", "decisions": ["sog_kn", "cog_deg", "dt_h"], **doc["rule"]}
    assert {k: written[k] for k in doc} == {**doc, "rule": rule}
    assert set(written) - set(doc) == {"method", "lane_config", "score"}
    assert written["score"] == "lane"


def test_an_unfinished_card_warns_and_a_bad_lane_configuration_is_one_line():
    doc = _card()
    doc["training"]["finished"] = False
    card = ModelCard.from_dict(doc, Path("up.json"))
    (warning,) = card_warnings(card, "up")
    assert "stopped after 3 of None episodes" in warning
    doc["lane_config"] = {"region": "sea"}
    with pytest.raises(UserError, match=r"up\.json: lane_config: region must be one of box"):
        ModelCard.from_dict(doc, Path("up.json"))
    doc["lane_config"] = {"fancy": 1}
    with pytest.raises(UserError, match=r"lane_config must be an object of validation, .*"):
        ModelCard.from_dict(doc, Path("up.json"))
