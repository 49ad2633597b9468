"""Labels for `aisdati detect --labels` on the real Kitimat tracks: incident lists (vessel, time
window, kind) as labels with per-kind metrics (issue 28, item 4), and rows that disagree about
one track refused instead of decided by their order (issue 27, item 4); the metrics of flags
and scores against labels, and bad label files refused before any work (issue 13, item 12)."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from aisdati.detection.labels import evaluate_labels, match_labels, read_labels
from aisdati.detection.routing import NOT_JUDGED_FAR
from aisdati.errors import UserError
from aisdati.tracks.store import load_tracks, read_track_table
from tests.helpers.cli import one_line_error
from tests.helpers.models import detect_dati


@pytest.fixture(scope="module")
def scored(kitimat):
    """20 real Kitimat tracks (the conftest ingest's first), with made-up scores: the last five
    score highest and are flagged."""
    out = kitimat
    ids = sorted(int(i) for i in read_track_table(out)["track_id"])[:20]
    tracks = load_tracks(out, ids)
    score = np.linspace(0.05, 1.0, len(tracks))
    scores = pd.DataFrame(
        {
            "track_id": [t.track_id for t in tracks],
            "mmsi": [t.mmsi for t in tracks],
            "score": score,
            "flagged": score > 0.75,
            "n_points": [len(t.positions) for t in tracks],
            "ashore_reports": 0,
        }
    )
    return out, tracks, scores


def middle_of(track, zone_hours: int = 0) -> tuple[str, str]:
    """A one-hour window in the middle of a track, written in a zone `zone_hours` east of UTC."""
    start = pd.Timestamp(track.start)
    start = start.tz_localize("UTC") if start.tzinfo is None else start
    mid = start + pd.to_timedelta(float(np.sum(track.dts)) / 2, unit="h")
    zone = f"{zone_hours:+03d}:00"
    a = (mid - pd.Timedelta("30min")).tz_convert(zone_hours * 3600).isoformat()
    b = (mid + pd.Timedelta("30min")).tz_convert(zone_hours * 3600).isoformat()
    assert a.endswith(zone) or zone_hours == 0
    return a, b


def test_an_incident_list_labels_every_track_and_gives_per_kind_metrics(scored, tmp_path):
    _, tracks, scores = scored
    deviation, propulsion, tow = tracks[-1], tracks[-2], tracks[3]
    rows = [
        (deviation.mmsi, *middle_of(deviation, -8), "route deviation"),  # Pacific time
        (propulsion.mmsi, *middle_of(propulsion), "loss of propulsion"),
        (tow.mmsi, *middle_of(tow, 2), "irregular tow"),
        (tow.mmsi, "1999-01-01T00:00:00Z", "1999-01-02T00:00:00Z", "irregular tow"),  # no track
    ]
    path = tmp_path / "incidents.csv"
    pd.DataFrame(rows, columns=["MMSI", "start", "end", "kind"]).to_csv(path, index=False)

    metrics = evaluate_labels(scores, tracks, path)
    assert metrics["labels_layout"] == "mmsi,start,end[,kind][,label]"
    assert metrics["labelled_tracks"] == len(tracks)  # the rest counts as normal
    positives = {deviation.track_id, propulsion.track_id, tow.track_id}
    assert metrics["anomalies_labelled"] == len(positives)
    assert metrics["labels_unmatched"] == 1  # the 1999 window
    by_kind = metrics["by_kind"]
    assert set(by_kind) == {"route deviation", "loss of propulsion", "irregular tow"}
    assert by_kind["route deviation"]["flagged"] == 1 and by_kind["route deviation"]["roc_auc"] == 1
    # track 3 scores low: its kind's AUC is its rank among the normal tracks, and it is missed
    assert by_kind["irregular tow"]["recall"] == 0.0
    assert 0 < by_kind["irregular tow"]["roc_auc"] < 0.5
    assert metrics["recall"] == pytest.approx(2 / 3)


def test_a_window_outside_a_track_does_not_label_it(scored, tmp_path):
    _, tracks, scores = scored
    track = tracks[0]
    start = pd.Timestamp(track.start)
    start = start.tz_localize("UTC") if start.tzinfo is None else start
    path = tmp_path / "before.csv"
    before = [(start - pd.Timedelta("2h")).isoformat(), (start - pd.Timedelta("1h")).isoformat()]
    other = tracks[-1]
    pd.DataFrame(
        [(track.mmsi, *before), (other.mmsi, *middle_of(other))], columns=["mmsi", "start", "end"]
    ).to_csv(path, index=False)
    matched = match_labels(scores, tracks, read_labels(path))
    assert matched.label[0] == 0 and matched.label[-1] == 1
    assert matched.row_matched.tolist() == [False, True]


def test_rows_less_than_a_minute_apart_with_two_labels_are_refused(scored, tmp_path):
    """Two rows 30 s apart both match the track starting between them: refused, naming both
    rows, instead of the later row silently winning."""
    _, tracks, scores = scored
    track = tracks[5]
    start = pd.Timestamp(track.start)
    path = tmp_path / "labels.csv"
    path.write_text(
        "mmsi,start,label\n"
        f"{track.mmsi},{(start - pd.Timedelta('15s')).isoformat()},1\n"
        f"{track.mmsi},{(start + pd.Timedelta('15s')).isoformat()},0\n"
    )
    with pytest.raises(
        UserError, match=re.escape(f"rows 2 and 1 both match track {track.track_id}")
    ):
        evaluate_labels(scores, tracks, path)


def test_a_repeated_track_id_is_not_counted_as_unmatched(scored, tmp_path):
    _, tracks, scores = scored
    path = tmp_path / "labels.csv"
    a, b = tracks[0].track_id, tracks[-1].track_id
    path.write_text(f"track_id,label,kind\n{a},0,\n{b},1,jump\n{b},1,jump\n999999,1,jump\n")
    metrics = evaluate_labels(scores, tracks, path)
    assert metrics["labelled_tracks"] == 2
    assert metrics["label_rows"] == 4 and metrics["labels_unmatched"] == 1  # only 999999
    assert metrics["by_kind"]["jump"]["anomalies"] == 1


@pytest.mark.parametrize(
    "text, needle",
    [
        ("mmsi,start,end\n1,2020-01-02,2020-01-01\n", "row 1: the window ends before it starts"),
        ("mmsi,start,end\n1,2020-01-01,later\n", "row 1: end must be a time"),
        ("mmsi,label\n1,1\n", "needs a 'track_id' column, or 'mmsi' and 'start'"),
    ],
)
def test_bad_incident_lists_are_one_line_errors(tmp_path, text, needle):
    path = tmp_path / "labels.csv"
    path.write_text(text)
    with pytest.raises(UserError, match=re.escape(needle)):
        read_labels(path)


def test_detect_reports_metrics_per_kind_of_an_incident_list(scored, cli, tmp_path):
    """End to end: a nearest model of route-1, every route-1 track judged, two incident windows
    on its tracks, and report.json / metrics.json break the metrics down by kind."""
    data, _, _ = scored
    models = tmp_path / "models"
    r = cli(
        "train", "--method", "nearest", "--cluster", "route-1", "--data", data, "--out", models,
        "--max-tracks", 25,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    trained = set(json.loads((models / "route-1-nearest.json").read_text())["data"]["track_ids"])
    table = read_track_table(data)
    route = table[table["route"] == "route-1"].sort_values("track_id")
    heldout = [int(i) for i in route["track_id"] if int(i) not in trained]
    tracks = load_tracks(data, heldout[:2])
    path = tmp_path / "incidents.csv"
    rows = [(t.mmsi, *middle_of(t), kind) for t, kind in zip(tracks, ["drift", "tow"], strict=True)]
    pd.DataFrame(rows, columns=["mmsi", "start", "end", "kind"]).to_csv(path, index=False)
    out = tmp_path / "report"
    r = cli(
        "detect", "--method", "nearest", "--cluster", "route-1", "--data", data,
        "--models", models, "--labels", path, "--contamination", "0.05", "--out", out,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    report = json.loads((out / "report.json").read_text())
    by_kind = report["metrics"]["by_kind"]
    assert set(by_kind) == {"drift", "tow"}
    assert all(v["anomalies"] == 1 for v in by_kind.values())
    assert json.loads((out / "metrics.json").read_text())["by_kind"] == by_kind


def test_report_counts_the_tracks_no_model_judged(kitimat, cli, tmp_path):
    """Every track of the chosen set is accounted for in report.json: judged (by which model)
    or not, and why (the model's own training tracks; starts too far from its training starts)."""
    models = tmp_path / "models"
    r = cli(
        "train", "--method", "nearest", "--cluster", "route-1", "--data", kitimat,
        "--out", models, "--max-tracks", 25,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    out = tmp_path / "report"
    r = cli(
        "detect", "--method", "nearest", "--cluster", "all", "--data", kitimat,
        "--models", models, "--top-percent", 10, "--out", out,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    report = json.loads((out / "report.json").read_text())
    cov = report["coverage"]
    # the model's own training tracks are no candidates: listed apart, every other one counted
    assert cov["training_tracks"] == len(cov["training_track_ids"]) == 25
    assert cov["candidates"] == len(read_track_table(kitimat)) - 25
    assert cov["judged"] == report["test_tracks"] == cov["judged_by"]["route-1-nearest"]
    assert cov["judged"] + sum(cov["not_judged"].values()) == cov["candidates"]
    assert sorted(cov["not_judged_tracks"][NOT_JUDGED_FAR]) == sorted(
        set(read_track_table(kitimat)["track_id"]) - set(pd.read_parquet(out / "scores.parquet")
        ["track_id"]) - set(cov["training_track_ids"])
    )  # fmt: skip


def test_label_metrics_weighted_f1_and_auc():
    from aisdati.detection.labels import label_metrics

    y = np.array([1, 1, 0, 0, 0, 0])
    flagged = np.array([1, 0, 1, 0, 0, 0])
    score = np.array([0.9, 0.6, 0.8, 0.1, 0.2, 0.3])
    m = label_metrics(y, flagged, score)
    assert m["precision"] == pytest.approx(0.5) and m["recall"] == pytest.approx(0.5)
    # class 1: F1 0.5 (support 2); class 0: precision 3/4, recall 3/4, F1 0.75 (support 4)
    assert m["f1_weighted"] == pytest.approx((2 * 0.5 + 4 * 0.75) / 6)
    assert m["roc_auc"] == pytest.approx(7 / 8)


# --------------------------------------------------------------------------------- item 12
LABELS = [
    ("track_id,label\nabc,1\n", "row 1: track_id must be an integer in \\[0, .*got 'abc'"),
    ("track_id,label\n3,1\n,0\n", "row 2: track_id must be an integer .*got ''"),
    ("track_id,label\n99999999999999999999,1\n", "row 1: track_id must be an integer in"),
    ("track_id,label\n3,yes\n", "row 1: label must be 0 or 1, got 'yes'"),
    ("track_id,label\n3,1\n3,0\n", "track_id 3 has both labels 0 and 1"),
    ("mmsi,start,label\n367000140,soon,1\n", "row 1: start must be a time"),
    ("mmsi,start,label\n-5,2020-06-30T00:00:00,1\n", "row 1: mmsi must be an integer in \\[1,"),
    ("track_id,label\n", "the file holds no labels"),
]


@pytest.mark.parametrize("text, needle", LABELS)
def test_bad_label_files_are_refused_before_any_work(ny_dati, tmp_path, text, needle):
    labels = tmp_path / "labels.csv"
    labels.write_text(text)
    result = detect_dati(ny_dati, ny_dati["models"], tmp_path / "r", "--labels", labels)
    one_line_error(result, re.escape(str(labels)) + ": " + needle)
    assert not (tmp_path / "r" / "scores.parquet").exists()  # no rollout ran
