"""Real Kitimat traffic with one encounter constructed in it (`aisdati.evaluation.
encounter_case`), cut to the days around it so that the tests judge it in seconds, and written
as an ingest output for the command line."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from aisdati.evaluation.constructed import CONSTRUCTORS, Case
from aisdati.tracks.reports import REPORTS, read_reports, read_vessels
from aisdati.tracks.schema import REPORTS_SCHEMA

AROUND = pd.Timedelta(days=5)


def met(kitimat: Path, seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame, Case]:
    """Kitimat's reports of the days around one constructed encounter, its identities and the
    case (the first seed from `seed` on that gives one)."""
    reports, identity = read_reports(kitimat), read_vessels(kitimat)
    for s in range(seed, seed + 20):
        made = CONSTRUCTORS["encounter"](reports, identity, np.random.default_rng(s))
        if made is not None:
            out, identity, case = made
            near = (out["time"] >= case.start - AROUND) & (out["time"] <= case.end + AROUND)
            return out[near].reset_index(drop=True), identity, case
    raise AssertionError("Kitimat offers no place for an encounter")


def as_ingest_output(kitimat: Path, reports: pd.DataFrame, folder: Path) -> Path:
    """A copy of the ingest output `kitimat` whose reports.parquet holds `reports`."""
    shutil.copytree(kitimat, folder)
    shutil.rmtree(folder / REPORTS)
    (folder / REPORTS).mkdir()
    table = pa.Table.from_pandas(
        reports[REPORTS_SCHEMA.names], REPORTS_SCHEMA, preserve_index=False
    )
    pq.write_table(table, folder / REPORTS / "part-00000.parquet")
    return folder
