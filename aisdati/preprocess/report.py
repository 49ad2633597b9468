"""Reasons a row can be rejected, and the per-stage counts that prove nothing vanished.

Every stage marks each row it looks at with a reason code (0 = kept). Counting those codes is
cheap (one `bincount` per batch) and gives the invariant the tests check:
rows read == sum of rejected rows + kept points.

The counts are those of the tracks (what a model learns from). reports.parquet keeps more: the
`slow` reports, and the others that fell out of a track after the vessel's own cleaning
(`short_segment`, `dwell`); `reports_kept` counts its rows, outside the balance.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

KEPT = 0

# code -> (stage, reason, description), listed in the order the checks are applied (a code
# added later takes the next number, wherever it is listed).
REASONS: dict[int, tuple[str, str, str]] = {
    1: ("read", "malformed_row", "too many or too few fields"),
    2: ("read", "header_line", "header repeated mid-file (joined files); later rows read under it"),
    3: ("read", "not_ais", "NMEA line that is no AIS sentence (other sentences, noise)"),
    4: ("read", "bad_checksum", "NMEA sentence whose checksum does not match"),
    5: ("read", "truncated", "NMEA sentence cut short or empty, or message with parts missing"),
    6: ("read", "not_position", "AIS message that is no position report (not 1-3, 18, 19, 27)"),
    7: ("read", "no_time", "AIS message without a time (tag block, timestamp column, $PGHP)"),
    8: ("read", "duplicate_reception", "another receiver's copy of an NMEA message (within 30 s)"),
    9: ("read", "missing_value", "blank (or NaN) MMSI, time, position, SOG or COG"),
    10: ("read", "bad_number", "non-numeric or infinite LAT, LON, SOG or COG"),
    11: ("read", "bad_mmsi", "MMSI not a positive integer of at most 18 digits"),
    12: ("read", "bad_time", "unparsable time, or not in 1990-2099"),
    13: ("clean", "sentinel_lat", "LAT 91 (not available)"),
    14: ("clean", "sentinel_lon", "LON 181 (not available)"),
    15: ("clean", "sentinel_sog", "SOG 102.3 (not available)"),
    16: ("clean", "sentinel_cog", "COG 360 (not available)"),
    17: ("clean", "out_of_range", "LAT/LON/SOG/COG outside their valid ranges"),
    26: ("filter", "outside_period", "time before --since or at or after --until"),
    18: ("filter", "outside_roi", "outside the region of interest"),
    19: ("filter", "slow", "SOG at or below --min-sog (not learned from; in reports.parquet)"),
    20: ("vessel", "duplicate", "exact duplicate of another report"),
    21: ("vessel", "repeated_timestamp", "second report of a vessel at the same time"),
    22: ("vessel", "implied_speed", "position outlier: implied speed above --max-speed"),
    25: ("vessel", "same_time_flood", "report of a vessel at one time beyond a piece's worth"),
    23: ("segment", "short_segment", "in a segment with fewer than --min-points reports"),
    24: ("segment", "dwell", "inside a stop: within --dwell-radius for at least --dwell-time"),
}
CODE = {reason: code for code, (_, reason, _) in REASONS.items()}
N_CODES = max(REASONS) + 1


@dataclass
class IngestCounts:
    """Row counts per rejection reason, plus what was kept; summed over batches and tasks."""

    rows_read: int = 0
    rejected: np.ndarray = field(default_factory=lambda: np.zeros(N_CODES, dtype=np.int64))
    files: list[dict[str, Any]] = field(default_factory=list)
    kept_points: int = 0
    reports_kept: int = 0
    """Rows of reports.parquet: every report judged, whatever its speed (not in the balance)."""
    short_segments: int = 0
    tracks: dict[str, int] = field(default_factory=lambda: {"up": 0, "down": 0, "other": 0})
    two_transmitters: list[int] = field(default_factory=list)
    """The MMSIs heard from two transmitters at once, each kept as two vessels
    (`aisdati.preprocess.transmitters`): set once the vessels are known, not summed."""

    def add_codes(self, codes: np.ndarray) -> None:
        """Count the rejection codes of one batch (code 0, kept, is not counted here)."""
        counts = np.bincount(codes, minlength=N_CODES)
        counts[KEPT] = 0
        self.rejected += counts

    def add(self, reason: str, n: int) -> None:
        self.rejected[CODE[reason]] += n

    def merge(self, other: IngestCounts) -> None:
        """Add the counts of one task (its files listed after those already here)."""
        self.rows_read += other.rows_read
        self.rejected += other.rejected
        self.files.extend(other.files)
        self.kept_points += other.kept_points
        self.reports_kept += other.reports_kept
        self.short_segments += other.short_segments
        for name, n in other.tracks.items():
            self.tracks[name] = self.tracks.get(name, 0) + n

    @property
    def total_rejected(self) -> int:
        return int(self.rejected.sum())

    def rejected_by_reason(self) -> dict[str, int]:
        return {reason: int(self.rejected[code]) for code, (_, reason, _) in REASONS.items()}

    def balanced(self) -> bool:
        """True when every row read is accounted for, as kept or under one reason."""
        return self.rows_read == self.total_rejected + self.kept_points

    def as_dict(self) -> dict[str, Any]:
        return {
            "rows_read": self.rows_read,
            "rejected": self.rejected_by_reason(),
            "rejected_total": self.total_rejected,
            "kept_points": self.kept_points,
            "reports_kept": self.reports_kept,
            "short_segments_dropped": self.short_segments,
            "tracks": {**self.tracks, "total": sum(self.tracks.values())},
            "two_transmitters": self.two_transmitters,
            "files": self.files,
        }


def no_tracks_message(counts: IngestCounts) -> str:
    """The one-line error of a run that kept no track: where the rows went, and what to loosen."""
    reasons = sorted(
        ((n, reason) for reason, n in counts.rejected_by_reason().items() if n), reverse=True
    )
    where = ", ".join(f"{reason} {n:,}" for n, reason in reasons) or "none"
    return (
        f"no track kept: {counts.rows_read:,} rows read, rejected: {where}; nothing written "
        "(loosen --min-points, --min-sog, --stop-gap, --dwell-time or --roi, or check the input)"
    )
