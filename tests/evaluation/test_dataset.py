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
            "--altered", "0.3", "--strength", "0.3", "--fleet-kinds", "none",
            "--out", out)  # fmt: skip
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "evaluation.json").read_text())
    table = read_track_table(kitimat)
    later = int((table["start"] >= AUGUST).sum())
    assert doc["split"]["heldout_tracks"] == later
    assert doc["split"]["injected"] == round(later * 0.3)
    assert doc["split"]["training_tracks"] == len(table) - later
    row = next(x for x in doc["results"] if x["kind"] == "all" and x["score"] == "lane")
    assert 0.0 <= row["false_alarm_rate"] <= 1.0 and row["roc_auc"] is not None


def _written(out):
    import pyarrow.parquet as pq

    return pq.read_table(out / "points.parquet").to_pandas(), pd.read_csv(out / "labels.csv")


def test_altered_tracks_report_their_kinds_motion_and_untouched_ones_keep_theirs(kitimat, tmp_path):
    """The leak of issue 59 (part 5): altered tracks' SOG/COG were derived from positions while
    untouched ones kept their reports; now a shifted stretch keeps what its reports said."""
    import pyarrow.parquet as pq

    from aisdati.evaluation.dataset import build
    from aisdati.evaluation.inject import DEFAULTS

    split = build(kitimat, "other", tmp_path, ("shift", "course-noise"), DEFAULTS, seed=1)
    points, labels = _written(tmp_path)
    source = pq.read_table(kitimat / "points.parquet").to_pandas()
    for row in labels.itertuples():
        new = points[points["track_id"] == row.track_id].sort_values("time")
        old = source[source["track_id"] == row.source_track_id].sort_values("time")
        assert len(new) == len(old)
        same_motion = ["sog"] if row.kind == "course-noise" else ["sog", "cog"]
        for name in same_motion:
            assert (new[name].to_numpy() == old[name].to_numpy()).all(), (row.kind, name)
        moved = new["lon"].to_numpy() != old["lon"].to_numpy()
        assert moved.any() == (row.kind == "shift")
    assert set(labels["kind"].dropna()) >= {"shift", "course-noise"} and len(split.heldout_ids)


def test_thin_keeps_one_report_per_duration_on_every_track(kitimat, tmp_path):
    from aisdati.evaluation.dataset import build
    from aisdati.evaluation.inject import DEFAULTS

    build(kitimat, "other", tmp_path, ("gap",), DEFAULTS, seed=0, thin_s=600.0)
    points, labels = _written(tmp_path)
    tracks = pd.read_parquet(tmp_path / "tracks.parquet")
    untouched = points[~points["track_id"].isin(labels.loc[labels["label"] == 1, "track_id"])]
    for _, g in untouched.groupby("track_id"):
        assert (g["time"].sort_values().diff().dropna() >= pd.Timedelta("10min")).all()
    counts = points.groupby("track_id").size()
    assert (tracks.set_index("track_id")["n_points"] == counts).all()
    before = read_track_table(kitimat).set_index("track_id")["n_points"]
    kept = [t for t in counts.index if t in before.index]
    assert (counts[kept] < before[kept]).all()
