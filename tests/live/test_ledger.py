"""Events as they happen, on FRIO's recording (the DMA's, whose drift AisAbnormal's tests
assert): the drift is opened once it has lasted the kind's 10 minutes, extended while it
lasts and closed when it ends; a vessel under way that falls silent opens a gap that closes
when it is heard again."""

from __future__ import annotations

from pathlib import Path

import pytest
from pyais.encode import encode_dict

from aisdati.events.settings import EventSettings
from aisdati.live.loop import Watch
from aisdati.live.sources import open_source
from aisdati.live.store import open_store
from tests.helpers.live import FRIO


def position(mmsi: int, seconds: float, lon: float, lat: float, knots: float) -> bytes:
    """One type 1 report as a receiver logs it: a tag block with its time, then the sentence."""
    report = {"type": 1, "mmsi": mmsi, "lon": lon, "lat": lat, "speed": knots, "course": 90.0,
              "heading": 90, "status": 0}  # fmt: skip
    return f"\\c:{int(seconds)}*00\\{encode_dict(report, talker_id='AI')[0]}".encode()


@pytest.fixture
def replayed(tmp_path: Path) -> tuple[Watch, list]:
    watch = Watch(open_store(str(tmp_path / "w.sqlite")))
    changes = [c for chunk in open_source(str(FRIO), print) for c in watch.step(chunk)]
    return watch, changes


def test_frio_drift_opens_grows_and_closes(replayed):
    watch, changes = replayed
    drift = [(c.what, c.event.fields["end"]) for c in changes if c.event.fields["kind"] == "drift"]
    assert [what for what, _ in drift] == ["opened", "closed"]  # one chunk saw it grow
    opened = next(c.event for c in changes if c.what == "opened")
    assert opened.fields["duration_s"] >= EventSettings().drift_min_s
    assert drift[1][1] > drift[0][1]
    assert watch.ledger.open_events() == []


def test_a_drift_seen_report_by_report_is_extended(tmp_path):
    watch = Watch(open_store(str(tmp_path / "w.sqlite")))
    whats = [c.what for chunk in open_source(str(FRIO), print, paced=True)
             for c in watch.step(chunk) if c.event.fields["kind"] == "drift"]  # fmt: skip
    assert whats[0] == "opened" and whats[-1] == "closed"
    assert set(whats[1:-1]) == {"extended"} and len(whats) > 3


def test_a_silent_vessel_opens_a_gap_that_closes_when_it_is_heard(replayed):
    watch, _ = replayed
    last = watch.last[538004030]
    two_hours = last.time_s + 7200
    # the clock moves: three reports agree on the time (one alone is held: aisdati.live.future)
    heard = [position(219000001, two_hours + k, 11.0 + k / 1e4, 57.9, 10.0) for k in (0, 9, 18)]
    opened = watch.step(heard)
    assert [(c.what, c.event.fields["kind"]) for c in opened] == [("opened", "gap")]
    assert "so far" in opened[0].event.fields["evidence"]
    closed = watch.step([position(538004030, two_hours + 60, last.lon + 0.01, last.lat, 10.0)])
    assert [(c.what, c.event.event_id) for c in closed] == [("closed", opened[0].event.event_id)]
    assert closed[0].event.fields["n_reports"] == 2  # now the batch's gap: last and next report
    assert "so far" not in closed[0].event.fields["evidence"]
