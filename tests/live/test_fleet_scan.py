"""The watch's hook for the kinds found across vessels (`Watch._fleet`): every `FLEET_SCAN_S` of the
feed it runs the registered fleet finders over all windows, and their events go through the
ledger as the others' (opened while found, closed once not), while one vessel's judgement
leaves them as they are. A stand-in finder (two vessels within 2 km at their last reports, an
`encounter`) is registered for the test: the real ones come with their kinds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pyais.encode import encode_dict

from aisdati.events import fleet
from aisdati.events.record import event_row
from aisdati.geo import haversine_m
from aisdati.live import loop
from aisdati.live.loop import Watch
from aisdati.live.store import open_store

START_S = 1_600_000_000


def position(mmsi: int, seconds: float, lon: float, lat: float) -> bytes:
    report = {"type": 1, "mmsi": mmsi, "lon": lon, "lat": lat, "speed": 5.0, "course": 90.0,
              "heading": 90, "status": 0}  # fmt: skip
    return f"\\c:{int(seconds)}*00\\{encode_dict(report, talker_id='AI')[0]}".encode()


def side_by_side(fleet_: fleet.Fleet, rules) -> list[dict]:
    """An encounter of each pair of vessels within 2 km at their last reports."""
    out = []
    ms = sorted(fleet_.vessels)
    for i, a in enumerate(ms):
        for b in ms[i + 1 :]:
            va, vb = fleet_.vessels[a], fleet_.vessels[b]
            if haversine_m(va.lon[-1], va.lat[-1], vb.lon[-1], vb.lat[-1]) <= 2000.0:
                times = (float(max(va.time_s[0], vb.time_s[0])), float(va.time_s[-1]))
                out.append(event_row(a, "encounter", times, len(va), (va.lon[-1], va.lat[-1]),
                                     (va.lon.tolist(), va.lat.tolist()), 1.0, "side by side",
                                     others=[fleet_.who(b)]))  # fmt: skip
    return out


def minute(k: int, apart_deg: float) -> list[bytes]:
    """Minute `k` of two vessels reporting every 10 s, `apart_deg` of longitude apart."""
    return [
        position(mmsi, START_S + 60 * k + s, 11.0 + (60 * k + s) * 1e-5 + off, 57.0)
        for s in range(0, 60, 10)
        for mmsi, off in ((219000001, 0.0), (219000002, apart_deg))
    ]


def test_fleet_events_open_and_close_through_the_ledger(tmp_path: Path, monkeypatch):
    monkeypatch.setitem(fleet.FLEET_FINDERS, "encounter", side_by_side)
    monkeypatch.setattr(loop, "FLEET_SCAN_S", loop.SCAN_S)  # a scan every minute of the feed
    watch = Watch(open_store(str(tmp_path / "w.sqlite")))
    changes = [(k, c) for k in range(6) for c in watch.step(minute(k, 0.005 if k < 3 else 0.5))]
    encounters = [(k, c.what) for k, c in changes if c.event.fields["kind"] == "encounter"]
    assert encounters[0] == (0, "opened")  # the first scan, at the first chunk
    assert [what for _, what in encounters][-1] == "closed"
    assert all(k < 4 for k, what in encounters if what != "closed")  # (apart from minute 3)
    (opened,) = [c.event for _, c in changes if c.what == "opened"]
    assert np.isclose(opened.fields["lat"], 57.0)
    assert '"mmsi": 219000002' in opened.fields["others"]
    assert watch.ledger.open_events() == []
