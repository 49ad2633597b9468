"""The model card (`aisdati.ais.card`): read and checked as a whole (every bad field one line
naming it), written back as the same JSON, and the training tracks it names found again by vessel
and time, after a re-ingest renumbers them. On real models of the New York Harbor hour: cards
edited into nonsense are refused naming the field, counts have upper bounds (issue 13, items 1,
2 and 7; issue 27, item 12)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from aisdati.ais.card import ModelCard, card_warnings, training_mask
from aisdati.errors import UserError
from tests.helpers.cli import one_line_error, run
from tests.helpers.models import card_edit, card_of, card_text, copy_of, detect_dati, detect_with


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


def test_a_card_records_whether_its_step_scores_read_the_reported_motion():
    """Issue 59, item 3: `calibrated_with.reported_motion` reads back; a card from before it
    judged positions only; anything but true or false is one line."""
    doc = {**_card(), "calibrated_with": {"lane_course_km": 2.0}}
    assert ModelCard.from_dict(doc, Path("up.json")).calibrated_with.reported_motion is False
    doc["calibrated_with"]["reported_motion"] = True
    card = ModelCard.from_dict(json.loads(json.dumps(doc)), Path("up.json"))
    assert card.calibrated_with.reported_motion is True
    assert card.to_dict()["calibrated_with"]["reported_motion"] is True
    doc["calibrated_with"]["reported_motion"] = "max"
    with pytest.raises(UserError, match=r"calibrated_with\.reported_motion must be true or false"):
        ModelCard.from_dict(doc, Path("up.json"))


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


NY_HOUR = Path(__file__).parents[1] / "data" / "NYHarbor_2020_06_30_first_hour.csv"


def edited_models(ny_dati, tmp_path: Path, edit) -> Path:
    """A copy of the model folder whose card went through `edit(card)`."""
    models = tmp_path / "models"
    shutil.copytree(ny_dati["models"], models)
    card = card_of(models)
    edit(card)
    (models / "down.json").write_text(json.dumps(card))  # NaN and Infinity as Python writes them
    return models


def training_keys(ny_dati) -> set[tuple[int, pd.Timestamp]]:
    """(mmsi, start) of the model's training tracks, read from the data it was trained on."""
    ids = card_of(ny_dati["models"])["data"]["track_ids"]
    tracks = pq.read_table(ny_dati["proc"] / "tracks.parquet").to_pandas()
    rows = tracks[tracks["track_id"].isin(ids)]
    return set(zip(rows["mmsi"], rows["start"], strict=True))


def test_the_card_stores_stable_track_keys(ny_dati):
    card = card_of(ny_dati["models"])
    keys = {(m, pd.Timestamp(s)) for m, s, _ in card["data"]["track_keys"]}
    assert keys == training_keys(ny_dati) and len(keys) == 3
    assert card["training"]["finished"] is True


CARD_DAMAGE = [
    ("rule.max_sog_kn", -3, "rule.max_sog_kn must be a finite number in \\(0, 1000\\], got -3"),
    ("rule.max_sog_kn", math.nan, "rule.max_sog_kn must be a finite number .*got nan"),
    ("rule.max_sog_kn", "12", "rule.max_sog_kn must be a finite number .*got '12'"),
    ("rule.max_dt_h", 0, "rule.max_dt_h must be a finite number in \\(0, .*got 0"),
    ("rule.max_dt_h", math.inf, "rule.max_dt_h must be a finite number .*got inf"),
    ("rule.cog_center_deg", math.nan, "rule.cog_center_deg must be a finite number"),
    ("region.lat", [41.0, 40.0], "region.lat must be \\[low, high\\] with low < high"),
    ("region.lon", [-74.5, math.nan], "region.lon\\[1\\] must be a finite number"),
    ("epsilon_m", -500, "epsilon_m must be a finite number > 0"),
    ("config.noise_sigma", math.nan, "config.noise_sigma must be a finite number"),
    ("config.noise", "pink", "config.noise must be one of 'gaussian', 'ou'"),
    ("data.start_points", [[math.nan, 40.6]] * 3, "data.start_points\\[0\\]\\[0\\] must be"),
    ("data.start_points", [[-74.0, 40.6]], "data.start_points must be a list of 3, got 1 items"),
    (
        "data.track_ids",
        [1, -2, 10],
        r"data.track_ids\[1\] must be an integer in \[0, [^]]*\], got -2",
    ),
    ("data.points", 2, "data.points must be an integer (>= 3|in \\[3, [^]]*\\]), got 2"),
    ("data.track_keys", [[1, "yesterday"]] * 3, "data.track_keys\\[0\\]\\[1\\] must be an ISO"),
    ("training.finished", "no", "training.finished must be true or false"),
]


@pytest.mark.parametrize("field, value, needle", CARD_DAMAGE, ids=[c[0] for c in CARD_DAMAGE])
def test_a_damaged_card_is_refused_naming_the_field(ny_dati, tmp_path, field, value, needle):
    models = edited_models(ny_dati, tmp_path, card_edit(field, value))
    result = detect_dati(ny_dati, models, tmp_path / "report")
    one_line_error(result, "model card .*down.json: " + needle)
    assert not (tmp_path / "report" / "scores.parquet").exists()


# ---------------------------------------------------------------------------------- item 2
def test_training_tracks_are_found_after_a_reingest_renumbers_them(ny_dati, tmp_path):
    again = tmp_path / "again"  # the same data, other settings: more tracks, other numbers
    r = run("ingest", "--input", NY_HOUR, "--roi", "none", "--min-points", 15, "--out", again)
    assert r.exit_code == 0, r.output
    tracks = pq.read_table(again / "tracks.parquet").to_pandas()
    keys = training_keys(ny_dati)
    moved = tracks[[(m, s) in keys for m, s in zip(tracks["mmsi"], tracks["start"], strict=True)]]
    ids = set(card_of(ny_dati["models"])["data"]["track_ids"])
    assert len(moved) == 3 and set(moved["track_id"]) != ids  # renumbered
    result = detect_dati(ny_dati, ny_dati["models"], tmp_path / "r", "--cluster", "all", data=again)
    assert result.exit_code == 0, result.output
    scored = pq.read_table(tmp_path / "r" / "scores.parquet").to_pandas()
    assert not set(scored["track_id"]) & set(moved["track_id"])  # the real training tracks
    assert set(scored["track_id"]) & (ids - set(moved["track_id"]))  # their old numbers: tested


def test_a_card_without_track_keys_falls_back_to_track_ids(ny_dati, tmp_path):
    models = edited_models(ny_dati, tmp_path, lambda card: card["data"].pop("track_keys"))
    result = detect_dati(ny_dati, models, tmp_path / "r", "--cluster", "all")
    assert result.exit_code == 0, result.output
    assert "warning" not in result.stderr
    scored = pq.read_table(tmp_path / "r" / "scores.parquet").to_pandas()
    ids = set(card_of(ny_dati["models"])["data"]["track_ids"])
    assert len(scored) > 0 and not set(scored["track_id"]) & ids


# ---------------------------------------------------------------------------------- item 7
def test_an_unfinished_model_is_used_with_a_warning(ny_dati, tmp_path):
    models = edited_models(ny_dati, tmp_path, card_edit("training.finished", False))
    result = detect_dati(ny_dati, models, tmp_path / "r")
    assert result.exit_code == 0, result.output
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "model down: training did not finish" in warnings[0]
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert len(report["warnings"]) == 1 and "did not finish" in report["warnings"][0]
    finished = detect_dati(ny_dati, ny_dati["models"], tmp_path / "r2")
    assert "warning" not in finished.stderr
    assert json.loads((tmp_path / "r2" / "report.json").read_text())["warnings"] == []


COUNTS = [
    ("dati", "data.points", 10**12, r"data\.points must be an integer in \[3, 300000\]"),
    ("bc", "data.points", 10**12, r"data\.points must be an integer in \[3, 300000\]"),
    ("dati", "config.network.hidden_units", 10**6,
     r"config\.network\.hidden_units must be an integer in \[1, 256\]"),
    ("dati", "config.network.hidden_layers", 10**6,
     r"config\.network\.hidden_layers must be an integer in \[1, 16\]"),
    ("dati", "config.network.latent_dim", 10**9,
     r"config\.network\.latent_dim must be an integer in \[1, 256\]"),
    ("bc", "config.hidden_units", 10**6, r"config\.hidden_units must be an integer in \[1, 256\]"),
    ("bc", "config.state_features", 10**6, r"config\.state_features must be an integer in"),
    ("dati", "seeds", [2**70, 1, 2], r"seeds\[0\] must be an integer in \[0, "),
    ("dati", "lane_config.validation_rollouts", 10**9,
     r"lane_config\.validation_rollouts must be an integer in \[1, 1000\]"),
    ("dati", "training.episodes_run", 10**18, r"training\.episodes_run must be an integer in"),
    ("nearest", "data.tracks_used", 10**18, r"data\.tracks_used must be an integer in"),
]  # fmt: skip


@pytest.mark.parametrize("method, field, value, needle", COUNTS,
                         ids=[f"{c[0]}-{c[1]}" for c in COUNTS])  # fmt: skip
def test_counts_in_a_card_have_upper_bounds(ny_models, tmp_path, method, field, value, needle):
    models = copy_of(ny_models, tmp_path)
    stem = {"dati": "down", "bc": "down-bc", "nearest": "down-nearest"}[method]
    card = json.loads(card_text(models, stem))
    if field == "seeds":
        value = value[: len(card["seeds"])]
    card_edit(field, value)(card)
    (models / f"{stem}.json").write_text(json.dumps(card))
    result = detect_with(ny_models, models, tmp_path / "r", method)
    one_line_error(result, rf"model card .*{stem}\.json: " + needle)
