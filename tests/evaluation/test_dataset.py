"""The evaluation's data set (`aisdati.evaluation.dataset`): split by time, the earlier tracks
train and every later one is judged (issue 26)."""

from __future__ import annotations

import json

import pandas as pd

from aisdati.tracks.store import read_track_table

AUGUST = pd.Timestamp("2018-08-01", tz="UTC")


def test_evaluate_splits_by_time_and_judges_every_later_track(cli, kitimat, tmp_path):
    out = tmp_path / "ev"
    r = cli("evaluate", "--data", kitimat, "--cluster", "all", "--before",
            "2018-08-01", "--detectors", "nearest", "--kinds", "detour,jump,loiter",
            "--altered", "0.3", "--strength", "0.3", "--out", out)  # fmt: skip
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "evaluation.json").read_text())
    table = read_track_table(kitimat)
    later = int((table["start"] >= AUGUST).sum())
    assert doc["split"]["heldout_tracks"] == later
    assert doc["split"]["injected"] == round(later * 0.3)
    assert doc["split"]["training_tracks"] == len(table) - later
    row = next(x for x in doc["results"] if x["kind"] == "all" and x["score"] == "lane")
    assert 0.0 <= row["false_alarm_rate"] <= 1.0 and row["roc_auc"] is not None
