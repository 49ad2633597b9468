"""`identity-change` from an identity history (`aisdati.events.identity.identity_changes`), on
the identity FRIO's type 5 messages give (tests/data/events): a one-message typo is no change,
a field a message leaves out is no change, a new name reported repeatedly is one, with before
and after."""

from __future__ import annotations

import numpy as np
import pandas as pd

from aisdati.events.identity import change_evidence, identity_changes

FRIO = {"mmsi": 538004030, "name": "FRIO", "ship_type": "Tanker", "length_m": 274.0}


def history(*rows: tuple[dict, str, int]) -> pd.DataFrame:
    """Rows of identities.parquet: (values over FRIO's, first time, reports), an hour each."""
    out = []
    for values, first, n in rows:
        start = pd.Timestamp(first, tz="UTC")
        out.append({**FRIO, **values, "first": start, "last": start + pd.Timedelta(hours=1),
                    "reports": n})  # fmt: skip
    return pd.DataFrame(out)


def test_a_typo_sent_once_is_no_change():
    typo = history(({}, "2014-09-28 16:00", 40), ({"name": "FRI0"}, "2014-09-28 16:30", 1))
    assert identity_changes(typo, repeats=3) == []


def test_a_field_left_out_is_no_change():
    parts = history(
        ({}, "2014-09-28 16:00", 40),
        ({"ship_type": None, "length_m": np.nan}, "2014-09-28 17:00", 20),  # a type 24 part A
        ({"name": None}, "2014-09-28 18:00", 20),  # part B
    )
    assert identity_changes(parts, repeats=3) == []


def test_a_new_name_reported_repeatedly_is_a_change_with_before_and_after():
    renamed = history(({}, "2014-09-28 16:00", 40), ({"name": "FRIO II"}, "2014-09-28 17:00", 3))
    ((before, after),) = identity_changes(renamed, repeats=3)
    assert after["first"] == pd.Timestamp("2014-09-28 17:00", tz="UTC")
    assert change_evidence(before, after) == "name 'FRIO' -> 'FRIO II'"
    longer = history(({}, "2014-09-28 16:00", 40), ({"length_m": 280.0}, "2014-09-28 17:00", 5))
    ((before, after),) = identity_changes(longer, repeats=3)
    assert change_evidence(before, after) == "length 274 m -> 280 m"
