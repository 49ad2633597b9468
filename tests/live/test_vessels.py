"""Each vessel's window stays within its bounds, and vessels are forgotten (and counted) when
silent too long or too many: memory stays bounded when vessels keep appearing."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa

from aisdati.live.judge import clean_together
from aisdati.live.vessels import FIELDS, Vessels
from aisdati.preprocess.convert import PARTITION_SCHEMA
from aisdati.preprocess.settings import IngestSettings


def reports(mmsi: list[int], seconds: list[float]) -> pa.Table:
    n = len(mmsi)
    return pa.table(
        [
            np.array(mmsi, np.int64),
            pa.array((np.array(seconds) * 1e6).astype(np.int64)).cast(pa.timestamp("us", "UTC")),
            np.linspace(10, 11, n), np.linspace(57, 58, n), np.full(n, 8.0), np.full(n, 90.0),
            np.full(n, 90.0, np.float32), pa.nulls(n, pa.int16()), np.zeros(n, np.int32),
        ],
        schema=PARTITION_SCHEMA,
    )  # fmt: skip


def test_a_window_keeps_its_last_reports_in_time_order():
    v = Vessels(window_s=100.0, max_reports=5)
    v.add(reports([1] * 8, [70, 0, 10, 20, 30, 40, 50, 60]))  # one late report first
    cols = v.window(1)
    assert cols["time_us"].tolist() == [30e6, 40e6, 50e6, 60e6, 70e6]
    v.add(reports([1, 1], [200, 210]))
    assert v.window(1)["time_us"].tolist() == [200e6, 210e6]  # the older left the 100 s
    assert v.window(1)["status"].tolist() == [-1, -1]


def test_vessels_silent_too_long_or_too_many_are_forgotten():
    v = Vessels(forget_s=1000.0, max_vessels=3)
    v.add(reports([1, 2, 3, 4, 5], [0, 10, 20, 30, 40]))
    assert sorted(v.forget()) == [1, 2]  # five heard, three kept: the longest silent go
    v.add(reports([9], [2000.0]))
    assert sorted(v.forget()) == [3, 4, 5]  # silent over 1000 s of the feed's clock
    assert list(v.recent) == [9] and v.forgotten == 5


def test_identity_fields_not_given_are_kept_and_each_message_is_in_the_history():
    v = Vessels()
    v.identify({7: [(("FRIO", None, np.nan), 1_000_000)]})
    v.identify({7: [((None, "Tanker", 274.0), 2_000_000), ((None, "Tanker", 274.0), 3_000_000)]})
    identity = v.recent[7].identity
    assert (identity.name, identity.ship_type, identity.length_m) == ("FRIO", "Tanker", 274.0)
    history = identity.history_table()
    assert history["name"].tolist()[0] == "FRIO" and history["ship_type"].tolist()[1] == "Tanker"
    assert history["name"].isna().tolist() == [False, True]
    assert history["reports"].tolist() == [1, 2]
    assert history["first"].tolist() == [pd.Timestamp(s, unit="s", tz="UTC") for s in (1, 2)]
    assert history["last"].tolist() == [pd.Timestamp(s, unit="s", tz="UTC") for s in (1, 3)]


def cleaned(windows: dict[int, dict[str, np.ndarray]]) -> dict:
    """Each window's cleaned reports by MMSI, the windows cleaned in one pass."""
    rows = [np.column_stack([np.asarray(w[k], np.float64) for k in FIELDS])
            for w in windows.values()]  # fmt: skip
    together = clean_together(list(windows), rows, IngestSettings())
    return {m: together.of(k) for k, m in enumerate(together.mmsi)}


def test_windows_cleaned_together_are_each_cleaned_alone():
    """The chunk's vessels are cleaned in one pass (`judge.clean_together`): each keeps what it
    keeps alone, a position outlier and a repeated time out, whatever the other vessels hold."""
    v = Vessels()
    v.add(reports([7] * 6 + [3] * 5, [0, 60, 120, 120, 180, 240, 0, 30, 60, 90, 120]))
    windows = {m: v.window(m) for m in (7, 3)}
    for cols in windows.values():  # ~7 kn east
        cols["lon"][:] = 10.0 + 0.002 * np.arange(len(cols["lon"]))
        cols["lat"][:] = 57.0
    windows[7]["lat"][4] = 0.0  # 57 degrees south of the others: an outlier
    together = cleaned(windows)
    for mmsi, cols in windows.items():
        alone = cleaned({mmsi: cols})[mmsi]
        assert together[mmsi].mmsi == mmsi
        for name in ("time_s", "lon", "lat", "sog", "cog", "heading", "status"):
            assert np.array_equal(getattr(together[mmsi], name), getattr(alone, name))
    assert len(together[7]) == 4 and len(together[3]) == 5
