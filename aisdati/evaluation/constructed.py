"""Constructed cases of the fleet kinds (`aisdati.events.kinds.FLEET`): real traffic with one
known case written into it (two real tracks brought together at sea, two vessels' reports
under one MMSI, a name changed, a block of vessels displaced together, a vessel silenced while
its neighbours keep reporting), so that recall is measured on the reports an analyst has, not
on synthetic tracks. Each kind's constructor is declared once in `CONSTRUCTORS`; `found` says
whether an events table finds a case (its kind, overlapping its time, naming its vessels)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd

from aisdati.evaluation import encounter_case, identity_cases, interference_case, port_visit_case
from aisdati.evaluation.case import Case
from aisdati.events.fleet import named

Constructor = Callable[
    [pd.DataFrame, pd.DataFrame, np.random.Generator],
    "tuple[pd.DataFrame, pd.DataFrame, Case] | None",
]
"""(reports: reports.parquet's rows, identity: vessels.parquet's by MMSI, rng) -> the reports
and identity with one case written in, and the case; None where the traffic offers no place
for one (e.g. no vessel long enough at sea)."""
CONSTRUCTORS: dict[str, Constructor] = {
    "encounter": encounter_case.construct_encounter,
    "port-visit": port_visit_case.construct_port_visit,
    "identity-conflict": identity_cases.merged_mmsi,
    "identity-change": identity_cases.renamed,
    "gnss-interference": interference_case.construct_interference,
    "gap-heard": interference_case.construct_gap_heard,
    "gap-quiet": interference_case.construct_gap_quiet,
}
"""Each constructed case by name: its kind, or its kind and what it expects ("gap-heard")."""


def found(case: Case, events: pd.DataFrame) -> bool:
    """Whether `events` hold an event of the case's kind that overlaps its time and names
    every vessel it involves (and, where the case expects one, says its coverage)."""
    mine = events[events["kind"] == case.kind]
    if case.coverage is not None:
        mine = mine[mine["coverage"] == case.coverage]
    start, end = pd.to_datetime(mine["start"], utc=True), pd.to_datetime(mine["end"], utc=True)
    mine = mine[(start <= case.end) & (end >= case.start)]
    return any(set(case.mmsis) <= named(e) for _, e in mine.iterrows())
