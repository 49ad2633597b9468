"""The real recordings with known outcomes (tests/data/events/: the Danish Maritime
Authority's raw NMEA, whose outcomes AisAbnormal's tests assert), from the raw files through
`aisdati ingest` and `aisdati detect --models none`."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from aisdati.events.kinds import MODEL_FREE
from aisdati.events.settings import EventSettings
from aisdati.tracks.store import load_tracks, read_track_table
from tests.helpers.area import save_nearest
from tests.helpers.cli import one_line_error, run
from tests.helpers.models import detect_args, train_ny_nearest

EVENTS = Path(__file__).resolve().parents[1] / "data" / "events"
HOLD = pd.Timedelta(seconds=EventSettings().drift_min_s)


def _events(tmp_path: Path, name: str) -> tuple[pd.DataFrame, dict]:
    data, out = tmp_path / "data", tmp_path / "events"
    got = run("ingest", "--input", EVENTS / name, "--roi", "none", "--min-points", "5",
              "--out", data)  # fmt: skip
    assert got.exit_code == 0, got.output
    got = run("detect", "--data", data, "--models", "none", "--out", out)
    assert got.exit_code == 0, got.output
    report = json.loads((out / "report.json").read_text())
    geojson = json.loads((out / "events.geojson").read_text())
    assert len(geojson["features"]) == len(report["events"])
    assert set(report["events_by_kind"]) <= set(MODEL_FREE)  # no model: no learned kind
    return pd.read_parquet(out / "events.parquet"), report


def test_frio_drifts_as_aisabnormal_found(tmp_path):
    events, report = _events(tmp_path, "538004030_drift_1.ais")
    drift = events[events["kind"] == "drift"]
    assert len(drift) >= 1
    # AisAbnormal dates a drift when it has lasted 10 minutes; ours from its first report
    raised = drift["start"].iloc[0] + HOLD
    assert abs(raised - pd.Timestamp("2014-09-28 16:50:04.556", tz="UTC")) <= pd.Timedelta("10min")
    assert drift["mmsi"].iloc[0] == 538004030
    points = pd.read_parquet(tmp_path / "data" / "points.parquet")
    assert report["reports_judged"] > len(points)  # the drifting (slow) reports are judged too
    assert drift["name"].iloc[0] == "FRIO"


def test_stoc_marcia_does_not_drift(tmp_path):
    events, _ = _events(tmp_path, "212123000_drift_1.ais")
    assert "drift" not in set(events["kind"])


def test_lotus_changes_speed_suddenly(tmp_path):
    events, _ = _events(tmp_path, "219165000_ssc_1.ais")
    ssc = events[events["kind"] == "sudden-speed-change"]
    assert len(ssc) == 1
    at = pd.Timestamp("2014-10-05 16:10:11.424", tz="UTC")
    assert abs(ssc["start"].iloc[0] - at) <= pd.Timedelta("5min")


def test_an_unknown_model_folder_is_one_line(tmp_path):
    one_line_error(
        run("detect", "--data", tmp_path, "--models", "none", "--out", tmp_path / "o"),
        "not found",
    )


def test_a_model_from_before_event_calibration_loads_and_says_the_defaults_judge(tmp_path):
    world = train_ny_nearest(tmp_path)
    card = world["models"] / "down-nearest.json"
    doc = json.loads(card.read_text())
    assert "event-days" in doc["calibration"]  # train records the alert budget's period
    assert any(k.startswith("event:") for k in doc["calibration"])
    doc["calibration"] = {k: v for k, v in doc["calibration"].items() if k != "event-days"}
    card.write_text(json.dumps(doc))  # as a card written before the budget (per-track stats)
    got = run(*detect_args(world, tmp_path / "out"))
    assert got.exit_code == 0, got.output
    assert "predate(s) the alert budget" in " ".join(got.output.split())
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert any("alert budget" in w for w in report["warnings"])


def _judged(world: dict, out: Path, *which) -> tuple[pd.DataFrame, pd.DataFrame]:
    got = run(*detect_args(world, out, *which))
    assert got.exit_code == 0, got.output
    return pd.read_parquet(out / "scores.parquet"), pd.read_parquet(out / "events.parquet")


def _of_track(events: pd.DataFrame, track_id: int) -> set[tuple]:
    mine = events[events["track_id"] == track_id]
    return {(e.kind, e.start, e.end, e.strength) for e in mine.itertuples()}


def _same_alone_as_in_the_batch(world: dict, tmp_path: Path, cluster: str) -> int:
    """`detect --cluster C` and `detect --track ID` give each track the same events and flag;
    the number of the tracks compared that had an event."""
    scores, events = _judged(world, tmp_path / "batch", "--cluster", cluster)
    with_events = set(events["track_id"].dropna().astype("int64"))
    ids = sorted(scores["track_id"], key=lambda t: (t not in with_events, t))[:4]
    for track_id in ids:
        alone, alone_events = _judged(world, tmp_path / f"t{track_id}", "--track", track_id)
        row = scores.set_index("track_id").loc[track_id]
        assert bool(alone["flagged"].iloc[0]) == bool(row["flagged"]), track_id
        assert _of_track(alone_events, track_id) == _of_track(events, track_id), track_id
    return len(with_events & set(ids))


def test_a_track_has_the_same_events_and_flag_alone_as_in_the_batch_kitimat(
    months, kitimat, tmp_path
):
    july, _, _ = months
    save_nearest(july, "all", tmp_path / "models")
    world = {"proc": kitimat, "models": tmp_path / "models"}
    assert _same_alone_as_in_the_batch(world, tmp_path, "all") >= 1


def test_a_track_has_the_same_events_and_flag_alone_as_in_the_batch_ny_harbor(processed, tmp_path):
    """The NY Harbor hour: an area model of every other vessel's tracks judges the rest."""
    table = read_track_table(processed)
    vessels = sorted(table["mmsi"].unique())
    ids = table.loc[table["mmsi"].isin(vessels[::2]), "track_id"].tolist()
    save_nearest(load_tracks(processed, ids), "all", tmp_path / "models")
    world = {"proc": processed, "models": tmp_path / "models"}
    _same_alone_as_in_the_batch(world, tmp_path, "all")
