"""The screen never clears a vessel of a kind that finds an event in it
(`aisdati.live.screen`): on real traffic (Kitimat's two months cut into 3-hour windows, the
DMA recordings of a drift, a sudden speed change and a loitering), every window with an event
of a kind at its floor is held for that kind, and most windows, with none, are cleared."""

from __future__ import annotations

import functools
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from aisdati.events.behaviour import land_mask
from aisdati.events.find import found_at_floor
from aisdati.events.motion import local_spread
from aisdati.events.rules import EventRules
from aisdati.events.settings import EventSettings
from aisdati.live.decode import Decoder
from aisdati.live.judge import clean_together
from aisdati.live.screen import SCREENS, Shape, least_spread, may_find
from aisdati.live.vessels import FIELDS, columns_of
from aisdati.preprocess.settings import IngestSettings
from tests.helpers.live import EVENTS, ROOT

KITIMAT = ROOT / "tests" / "data" / "AIS_2018_07-08_Kitimat.csv.gz"
WINDOW_S = 3 * 3600


@functools.cache
def kitimat_windows(window_s: int = WINDOW_S) -> list[np.ndarray]:
    """Kitimat's reports as each vessel's windows of `window_s` (rows of `FIELDS`), the
    vessels with most reports first."""
    f = pd.read_csv(KITIMAT, usecols=["MMSI", "BaseDateTime", "LAT", "LON", "SOG", "COG",
                                      "Heading", "Status"])  # fmt: skip
    t = pd.to_datetime(f["BaseDateTime"], utc=True).astype("datetime64[us, UTC]")
    us = t.astype("int64").to_numpy()
    rows = np.column_stack([
        us, f["LON"], f["LAT"], f["SOG"], f["COG"] % 360,
        np.where(f["Heading"] < 360, f["Heading"], np.nan), f["Status"].fillna(-1),
    ]).astype(np.float64)  # fmt: skip
    key = f["MMSI"].to_numpy() * 10**6 + us // (window_s * 10**6)
    order = np.argsort(key, kind="stable")
    cut = np.flatnonzero(np.diff(key[order])) + 1
    return sorted((rows[i] for i in np.split(order, cut)), key=len, reverse=True)


def recording(name: str) -> np.ndarray:
    cols = columns_of(Decoder().reports((EVENTS / name).read_bytes().splitlines()))
    return np.column_stack([np.asarray(cols[k], np.float64) for k in FIELDS])


@pytest.fixture(scope="module")
def screened() -> tuple[list[list[str]], list[list[str]]]:
    """Each window's kinds found at their floors, and the kinds the screen holds it for."""
    names = ("538004030_drift_1.ais", "219165000_ssc_1.ais", "212123000_drift_1.ais")
    windows = kitimat_windows() + [recording(n) for n in names]
    together = clean_together(list(range(len(windows))), windows, IngestSettings())
    rules = EventRules()
    land = land_mask(together.all.positions(), None)
    held = may_find(together.all, together.bounds, land, rules)
    found = [
        [e.kind for e in found_at_floor(together.of(k), rules.settings)] if size else []
        for k, size in enumerate(together.sizes)
    ]
    return found, held


def test_every_window_with_an_event_is_held(screened):
    found, held = screened
    missed = Counter(k for kinds, h in zip(found, held, strict=True) for k in kinds if k not in h)
    assert not missed, f"the screen cleared windows with events: {dict(missed)}"
    kinds = {kind for kinds in found for kind in kinds}
    assert {"drift", "sudden-speed-change", "loitering", "speed-inconsistent"} <= kinds


def test_most_windows_without_an_event_are_cleared(screened):
    found, held = screened
    quiet = np.array([not kinds for kinds in found])
    assert quiet.sum() > 1000
    cleared = np.array([not h for h in held])
    assert cleared[quiet].mean() > 0.5  # the finders run on fewer than half of them


def test_every_kind_has_a_screen():
    from aisdati.events.find import FINDERS

    assert set(FINDERS) == set(SCREENS)


def spreads(rows: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The speed kind's departures' spread at each inner report (read under way), by
    `least_spread` and by the finder's `local_spread`."""
    together = clean_together(list(range(len(rows))), rows, IngestSettings())
    shape, v, s = Shape(together.all, together.bounds), together.all, EventSettings()
    i = np.flatnonzero(shape.inner)
    moving = v.under_way(s.under_way_kn)
    read = moving[i - 1] | moving[i] | moving[i + 1]
    rough = np.where(read, v.sog[i] - (v.sog[i - 1] + v.sog[i + 1]) / 2, np.nan)
    mine = [shape.group[i] == k for k in range(shape.vessels)]
    finder = [local_spread(v.time_s[i][m], rough[m], s.scale_window_s) for m in mine]
    return least_spread(shape, i, rough, s.scale_window_s), np.concatenate(finder)


def test_the_least_spread_never_exceeds_the_finders():
    """`least_spread` bounds `local_spread` from below at every report: over windows far longer
    than the scale's (Kitimat's ten busiest vessels, two months each), where a report's centred
    window holds only part of the vessel's, and over the watch's 3-hour windows, where it holds
    nearly all of it and the bound is close."""
    least, finder = spreads(kitimat_windows(24 * 3600 * 61)[:10])
    assert np.all(least <= finder)
    least, finder = spreads(kitimat_windows()[:300])
    assert np.all(least <= finder)
    assert (least > 0).sum() > 0.5 * (finder > 0).sum()  # a bound, not nothing
