"""The settings of the event finders, in one dataclass. The behaviour rules (drift, sudden
speed change, loitering) carry the published definitions they follow (`aisdati.events.kinds`);
the consistency rules compare each report with the vessel's own report-to-report variation, so
that one setting serves 2-second and 10-minute reporting alike. The defaults serve where no
model is (`detect --models none`); a model calibrates the thresholds of the consistency kinds
and of the gap on its own training tracks (`aisdati.events.calibrate`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class EventSettings:
    # position-jump
    gps_m: float = 25.0
    """Position noise a report may carry whatever its step (GPS, rounding of coordinates)."""
    jump_z: float = 8.0
    """A step's unexplained displacement, over its scale, that makes it a jump."""
    jump_min_reports: int = 3
    """Fewest reports a displaced stretch holds (fewer: a glitch, not a shifted stretch)."""
    jump_max_share: float = 0.5
    """Most of a vessel's reports a displaced stretch may hold."""
    # speed- and course-inconsistent
    sog_floor_kn: float = 0.2
    cog_floor_deg: float = 2.0
    under_way_kn: float = 2.0
    """Course is read only where the vessel reports at least this speed."""
    noise_cap: float = 25.0
    """A report's squared surprise counts at most this much (one wild value is not a stretch)."""
    noise_drift: float = 5.0
    """What each report's squared surprise must exceed to add to the CUSUM."""
    speed_limit: float = 150.0
    """The CUSUM's level that makes a stretch of reported speeds an event."""
    course_limit: float = 150.0
    """The same for reported courses."""
    # drift (AisAbnormal)
    drift_min_kn: float = 1.0
    drift_max_kn: float = 5.0
    drift_angle_deg: float = 45.0
    drift_min_s: float = 600.0
    drift_min_length_m: float = 50.0
    # sudden speed change (AisAbnormal)
    ssc_from_kn: float = 7.0
    ssc_to_kn: float = 1.0
    ssc_within_s: float = 30.0
    ssc_hold_s: float = 60.0
    # loitering (after Global Fishing Watch)
    loiter_kn: float = 2.0
    loiter_min_s: float = 3600.0
    # gap at sea
    gap_factor: float = 10.0
    gap_min_s: float = 1800.0
    """The shortest gap at sea; an area's model calibrates it on its training tracks'
    silences (its coverage holes), as it does `jump_z`, `speed_limit` and `course_limit`
    (`aisdati.events.calibrate`)."""
    gap_max_s: float = 86400.0
    gap_under_way_kn: float = 1.0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)
