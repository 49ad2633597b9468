"""Reading back what ingest kept of every report (reports.parquet) and of every vessel
(vessels.parquet), for the event finders. An ingest output from before reports.parquet (or
evaluate's injected copy, which has only tracks) is read from points.parquet: its tracks'
reports, heading and status where it has them."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pyarrow.dataset as ds

from aisdati.errors import UserError

REPORTS = "reports.parquet"
VESSELS = "vessels.parquet"
IDENTITIES = "identities.parquet"
IDENTITY = ("name", "ship_type", "length_m")


def has_reports(data_dir: Path) -> bool:
    """Whether the ingest output holds every report (reports.parquet), not only its tracks'."""
    return (data_dir / REPORTS).exists()


def read_reports(
    data_dir: Path, track_ids: list[int] | None = None, mmsis: list[int] | None = None
) -> pd.DataFrame:
    """The reports to judge, sorted by vessel and time: every report of reports.parquet (or,
    where the output predates it, of points.parquet's tracks); `track_ids`: only the reports of
    those tracks; `mmsis`: only those vessels' reports."""
    path = data_dir / (REPORTS if has_reports(data_dir) else "points.parquet")
    if not path.exists():
        wanted = data_dir / REPORTS
        raise UserError(f"{wanted} not found: run `aisdati ingest --out {data_dir}` first")
    try:
        dataset = ds.dataset(path, format="parquet")
        wanted = ds.field("track_id").isin(track_ids) if track_ids is not None else None
        if mmsis is not None:
            of_vessels = ds.field("mmsi").isin(mmsis)
            wanted = of_vessels if wanted is None else wanted & of_vessels
        frame = dataset.to_table(filter=wanted).to_pandas()
    except (OSError, ValueError) as exc:
        raise UserError(f"cannot read {path}: {str(exc).splitlines()[0]}") from None
    return frame.sort_values(["mmsi", "time"], kind="stable").reset_index(drop=True)


def motion_derived(data_dir: Path) -> bool:
    """Whether ingest derived SOG and COG from positions for every file it read (a
    positions-only input): its reports' motion then says nothing the positions do not."""
    path = data_dir / "ingest_report.json"
    if not path.exists():
        return False
    files = json.loads(path.read_text()).get("files") or []
    return bool(files) and all({"sog", "cog"} & set(f.get("derived") or []) for f in files)


def read_vessels(data_dir: Path) -> pd.DataFrame:
    """Each vessel's name, type and length (vessels.parquet), indexed by MMSI; empty where the
    ingest output predates it."""
    path = data_dir / VESSELS
    if not path.exists():
        return pd.DataFrame(columns=list(IDENTITY), index=pd.Index([], name="mmsi"))
    return pd.read_parquet(path).set_index("mmsi")


def read_identities(data_dir: Path) -> pd.DataFrame | None:
    """The identity history of every vessel (identities.parquet, `aisdati.tracks.schema.
    IDENTITY_SCHEMA`); None where the ingest output predates it."""
    path = data_dir / IDENTITIES
    return pd.read_parquet(path) if path.exists() else None
