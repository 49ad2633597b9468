"""Settings of `aisdati ingest`, with the paper's values (section 6) as defaults."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

import pandas as pd

from aisdati.errors import UserError
from aisdati.options import parse_time


@dataclass(frozen=True)
class IngestSettings:
    """Thresholds of the filter, clean and segment stages.

    Defaults are the paper's: SOG > 3 kn, a stop is a gap of more than one hour, tracks keep at
    least 900 reports. `max_speed_kn` bounds the implied speed between consecutive kept reports of
    one vessel (position outliers); 50 kn is above any merchant vessel's top speed.
    """

    min_sog_kn: float = 3.0
    max_speed_kn: float = 50.0
    stop_gap_s: float = 3600.0
    min_points: int = 900
    keep_rejects: bool = False
    dwell_radius_m: float = 500.0
    """Stops by dwell (`aisdati.preprocess.stops`): a vessel that stays within this radius for
    `dwell_time_s` (seen in its reports, or across a gap in them) ends a track there."""
    dwell_time_s: float = 300.0
    """0 turns dwell splitting off (the paper's gap rule alone)."""
    clusters: str = "routes"
    """'routes': the paper's direction clusters and route clusters; 'direction': the paper's
    clusters only (no route column values, no routes files)."""
    route_min_tracks: int = 5
    route_eps_km: float | None = None
    """None: HDBSCAN (no distance scale); a number: DBSCAN radius and shape tolerance, km."""
    route_seed: int = 0
    rows_per_bucket: int = 2_000_000
    """Upper bound on the rows of one on-disk vessel partition; keeps memory bounded."""
    since: str | None = None
    """The period taken (`--since`, `--until`): reports from `since` (inclusive) to `until`
    (exclusive), ISO 8601 in UTC; None: unbounded. The others are counted as `outside_period`."""
    until: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def period_us(self) -> tuple[int | None, int | None]:
        """The period's bounds in microseconds since 1970 (what the time column holds)."""
        return _us(self.since), _us(self.until)


def _us(time: str | None) -> int | None:
    return None if time is None else pd.Timestamp(time).value // 1000


def parse_since_until(since: str | None, until: str | None) -> tuple[str | None, str | None]:
    """--since and --until (dates or ISO 8601 times, UTC unless a zone is given) -> their ISO
    UTC forms; a bad value, or a period that holds no instant, is a one-line `UserError`."""
    start = None if since is None else parse_time(since, "--since")
    end = None if until is None else parse_time(until, "--until")
    if start is not None and end is not None and start >= end:
        raise UserError(
            f"--since {since} is not before --until {until}: the period holds no report "
            "(--since is inclusive, --until exclusive)"
        )
    return (
        None if start is None else start.isoformat(),
        None if end is None else end.isoformat(),
    )


_UNITS_S = {"s": 1.0, "sec": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}


def parse_duration(text: str, option: str = "--stop-gap", allow_zero: bool = False) -> float:
    """'1h', '90min', '3600s', '1.5h' -> seconds (for --stop-gap; `allow_zero`: also '0')."""
    if allow_zero and text.strip() in ("0", "off"):
        return 0.0
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*(s|sec|m|min|h|d)\s*", text.lower())
    if not match or float(match[1]) <= 0:
        zero = " (0 or off: none)" if allow_zero else ""
        raise UserError(
            f"{option} {text!r}: expected a positive duration such as 1h, 90min, 600s{zero}"
        )
    return float(match[1]) * _UNITS_S[match[2]]
