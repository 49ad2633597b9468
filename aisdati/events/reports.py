"""One vessel's reports in time order, as the event finders read them: positions, what the
vessel reports of its motion, and the geometry of each step between two reports.

The step geometry follows the kinematic rule DATI moves by (eq. 5 of the paper, in a local
flat frame, exact at the few kilometres of one step): the reported SOG and COG, as a velocity,
say where the previous report puts the vessel next."""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import cached_property

import numpy as np
import pandas as pd

from aisdati.geo import EARTH_RADIUS_M
from aisdati.tracks.schema import KNOT_MPS

M_PER_DEG = EARTH_RADIUS_M * np.pi / 180.0
AT_ANCHOR, MOORED = 1, 5
"""Navigational status codes (ITU-R M.1371) of a vessel that says it is not under way."""


@dataclass(frozen=True)
class VesselReports:
    """One vessel's reports, sorted by time (arrays of equal length)."""

    mmsi: int
    time_s: np.ndarray
    """Seconds since the epoch (float64)."""
    lon: np.ndarray
    lat: np.ndarray
    sog: np.ndarray
    """Reported speed over ground, knots."""
    cog: np.ndarray
    """Reported course over ground, degrees."""
    heading: np.ndarray
    """Degrees; NaN where not available."""
    status: np.ndarray
    """Navigational status code; -1 where not available."""
    track_id: np.ndarray
    """The track each report is a point of; -1 where none."""

    def __len__(self) -> int:
        return len(self.time_s)

    @classmethod
    def of(cls, frame: pd.DataFrame) -> VesselReports:
        """From one vessel's rows (reports.parquet's columns, `aisdati.tracks.schema.
        REPORTS_SCHEMA`; heading, status and track_id may be absent), sorted by time."""
        frame = frame.sort_values("time", kind="stable")
        n = len(frame)
        time = pd.to_datetime(frame["time"], utc=True)
        return cls(
            int(frame["mmsi"].iloc[0]),
            time.astype("int64").to_numpy() / _per_second(time.dt.unit),
            frame["lon"].to_numpy(np.float64),
            frame["lat"].to_numpy(np.float64),
            frame["sog"].to_numpy(np.float64),
            frame["cog"].to_numpy(np.float64),
            _column(frame, "heading", np.nan, n),
            _column(frame, "status", -1, n),
            _column(frame, "track_id", -1, n),
        )

    def positions(self, rows: slice | np.ndarray = slice(None)) -> np.ndarray:
        """[n, 2] lon/lat of the reports `rows`."""
        return np.column_stack([self.lon[rows], self.lat[rows]])

    def under_way(self, min_kn: float) -> np.ndarray:
        """[n] whether each report has the vessel under way: at least `min_kn` reported, and
        not saying it is at anchor or moored."""
        return (self.sog >= min_kn) & ~np.isin(self.status, (AT_ANCHOR, MOORED))

    @cached_property
    def dt_s(self) -> np.ndarray:
        """[n - 1] seconds between consecutive reports."""
        return np.diff(self.time_s)

    @cached_property
    def moved(self) -> np.ndarray:
        """[n - 1, 2] east/north metres each step moved, by the positions."""
        east = np.diff(self.lon) * np.cos(np.radians(self.lat[:-1])) * M_PER_DEG
        north = np.diff(self.lat) * M_PER_DEG
        return np.column_stack([east, north])

    @cached_property
    def velocity(self) -> np.ndarray:
        """[n, 2] east/north m/s each report says the vessel moves at (SOG along COG)."""
        course = np.radians(self.cog)
        speed = self.sog * KNOT_MPS
        return np.column_stack([speed * np.sin(course), speed * np.cos(course)])

    @cached_property
    def residual(self) -> np.ndarray:
        """[n - 1, 2] metres: where each report is, less where the kinematic rule puts it from
        the previous report with the two reports' mean reported velocity (exact for a vessel
        that turns or speeds up steadily)."""
        predicted = (self.velocity[:-1] + self.velocity[1:]) / 2 * self.dt_s[:, None]
        return self.moved - predicted

    @cached_property
    def implied_kn(self) -> np.ndarray:
        """[n - 1] the speed each step's positions imply, knots."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.hypot(*self.moved.T) / np.maximum(self.dt_s, 1e-9) / KNOT_MPS


ARRAYS = tuple(f.name for f in fields(VesselReports) if f.name != "mmsi")
"""The per-report arrays of `VesselReports`."""


def concatenated(parts: list[VesselReports], mmsi: int) -> VesselReports:
    """The reports of several vessels one after another under `mmsi` (not sorted by time)."""
    return VesselReports(
        mmsi, **{n: np.concatenate([getattr(p, n) for p in parts] or [np.empty(0)]) for n in ARRAYS}
    )


def heard_as_one(parts: list[VesselReports], mmsi: int) -> VesselReports:
    """The reports of several vessel ids as one vessel `mmsi`, by time: what a receiver heard
    under one MMSI before ingest split its two transmitters (`aisdati.tracks.schema.
    TRANSMITTER_STEP`). Interference displaces a vessel's reports far enough to be taken for a
    second transmitter's; heard as one, they are its jumps again."""
    if len(parts) == 1:
        return parts[0]
    joined = concatenated(parts, mmsi)
    order = np.argsort(joined.time_s, kind="stable")
    return VesselReports(mmsi, **{n: getattr(joined, n)[order] for n in ARRAYS})


def _per_second(unit: str) -> float:
    return {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}[unit]


def _column(frame: pd.DataFrame, name: str, missing: float, n: int) -> np.ndarray:
    if name not in frame.columns:
        return np.full(n, missing, dtype=np.float64)
    return frame[name].astype("float64").fillna(missing).to_numpy()


def vessels(frame: pd.DataFrame) -> list[VesselReports]:
    """Each vessel's reports of a table of many (reports.parquet's columns)."""
    return [VesselReports.of(group) for _, group in frame.groupby("mmsi", sort=True)]
