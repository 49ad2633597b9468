"""The alert budget on real traffic, forward in time: calibrated on Kitimat's July, judged on
August's untouched reports (every report, on a track or not), and its rules on their own."""

from __future__ import annotations

import numpy as np
import pytest

from aisdati.detection.events import model_free_events
from aisdati.evaluation.alerts import alert_rates
from aisdati.events.budget import Thresholds, thresholds_for
from aisdati.events.calibrate import calibration, is_calibrated, thresholds_of, training_period
from aisdati.events.find import find_events
from aisdati.events.kinds import ACTIVITY, ALERT, BUDGETED, KINDS
from aisdati.events.reports import AT_ANCHOR, VesselReports, vessels
from aisdati.events.rules import EventRules
from aisdati.events.stretch import Found, merged
from aisdati.geo import moved_m
from aisdati.tracks.reports import read_reports, read_vessels
from aisdati.tracks.store import read_track_table
from tests.helpers.area import AUGUST


@pytest.fixture(scope="module")
def august(kitimat) -> dict:
    """July calibrates (its tracks' vessels over their span, as `train` does), August is
    judged: its events and the measure of record."""
    reports, tracks = read_reports(kitimat), read_track_table(kitimat)
    july = tracks[tracks["start"] < AUGUST]
    recorded = calibration(vessels(training_period(reports[reports["time"] < AUGUST], july)))
    how = thresholds_of([recorded])
    later = reports[reports["time"] >= AUGUST]
    events = model_free_events(later, read_vessels(kitimat), EventRules(thresholds=how))
    ids = tracks.loc[tracks["start"] >= AUGUST, "track_id"].to_numpy()
    return {"how": how, "events": events, "rates": alert_rates(events, later, ids, 200)}


def test_the_budget_holds_on_the_next_month(august):
    rates = august["rates"]
    assert rates["vessel_days"] > 500
    assert rates["alerts_per_1000"] <= 10.0
    assert rates["tracks_flagged_share"] <= 0.05
    assert rates["same_kind_overlaps"] == 0 and rates["over_bound"] == 0


def test_alerts_and_activity_are_apart_and_alerts_say_how_rare(august):
    events = august["events"]
    assert set(events["class"]) <= {ALERT, ACTIVITY}
    assert (events["class"] == events["kind"].map(lambda k: KINDS[k].cls)).all()
    alerts = events[events["class"] == ALERT]
    assert (alerts["strength"] >= 1).all()
    assert (alerts["rarity_days"] > 0).all()
    assert events.loc[events["class"] == ACTIVITY, "rarity_days"].isna().all()


def test_water_filling_shares_the_budget_and_spares_silent_kinds():
    strengths = {"position-jump": list(np.linspace(10, 1, 40)), "speed-inconsistent": [3.0, 2.0]}
    how = thresholds_for(strengths, vessel_days=2000, budget=10)  # 20 alerts in all
    raised = {k: sum(s >= how.of(k) for s in v) for k, v in strengths.items()}
    assert sum(raised.values()) <= 20
    assert raised["speed-inconsistent"] == 2 and raised["position-jump"] == 18
    assert all(how.of(k) == 1.0 for k in BUDGETED if k not in strengths)
    strong = Found("position-jump", 0, 5, 0, 10.0 / how.of("position-jump"), "")
    weak = Found("position-jump", 0, 5, 0, 1.0, "")
    assert how.rarity_days(strong) > how.rarity_days(weak)
    assert Thresholds().rarity_days(strong) is None and is_calibrated({}) is False


def test_one_event_per_thing():
    a, b = Found("gap", 0, 1, 0, 2.0, "a"), Found("gap", 1, 2, 1, 3.0, "b")
    assert merged([a, b]) == [a, b]  # sharing an end report is not overlapping
    c, d = Found("drift", 0, 10, 2, 2.0, "c"), Found("drift", 5, 20, 12, 3.0, "d")
    assert merged([d, c]) == [Found("drift", 0, 20, 12, 3.0, "d")]


def _swinging(under_way: bool) -> VesselReports:
    """Three hours of reports a minute apart around a point (a vessel on its anchor chain)
    with 20 of them displaced 600 m, at anchor or under way."""
    n = 180
    t = 1.5e9 + 60.0 * np.arange(n)
    angle = np.linspace(0, 4 * np.pi, n)
    lon, lat = moved_m(np.full(n, -129.0), np.full(n, 53.0), np.degrees(angle), 60.0)
    lon[80:100], lat[80:100] = moved_m(lon[80:100], lat[80:100], 90.0, 600.0)
    sog = np.full(n, 8.0 if under_way else 0.2)
    if under_way:  # sailing north at 8 kn, reports saying so
        lon, lat = moved_m(lon, lat, 0.0, 8.0 * 0.514444 * (t - t[0]))
    status = np.full(n, -1.0 if under_way else AT_ANCHOR)
    cog, heading = np.zeros(n), np.full(n, np.nan)
    return VesselReports(1, t, lon, lat, sog, cog, heading, status, np.full(n, -1.0))


def test_a_vessel_at_anchor_is_not_jumping_one_under_way_is():
    assert not [e for e in find_events(_swinging(False)) if e.kind == "position-jump"]
    jumps = [e for e in find_events(_swinging(True)) if e.kind == "position-jump"]
    assert len(jumps) == 1 and (jumps[0].start, jumps[0].end) == (80, 99)
