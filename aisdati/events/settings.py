"""The settings of the event finders, in one dataclass: the *floors* at which each kind's
finder looks. An alert found at its floor is raised only when its strength (over the floor)
reaches its kind's threshold, which the alert budget sets (`aisdati.events.budget`): on a
model's training period, or by the documented defaults where no model is. The behaviour
rules (drift, sudden speed change, loitering, gap) carry the published definitions they follow
(`aisdati.events.kinds`) as their floors; the consistency rules compare each report with the
vessel's own report-to-report variation of the hours around it, so that one setting serves
2-second and 10-minute reporting alike and an event depends on those hours only, not on what
else is judged."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


@dataclass(frozen=True)
class EventSettings:
    # what a vessel under way is (the consistency kinds judge only it)
    under_way_kn: float = 2.0
    scale_window_s: float = 6 * 3600.0
    """The hours around a report (centred) whose reports give the vessel's own spread."""
    # position-jump
    gps_m: float = 25.0
    """Position noise a report may carry whatever its step (GPS, rounding of coordinates)."""
    clock_s: float = 60.0
    """The clock offset a receiver's time stamps may carry: along its course, that many
    seconds of a vessel's speed is not a jump."""
    jump_z: float = 5.0
    """A step's unexplained displacement, over its scale, that makes it a jump (the floor)."""
    jump_min_m: float = 300.0
    """The smallest unexplained displacement a jump is (a vessel swinging at anchor, GPS
    noise and rounding stay under it)."""
    jump_step_max_s: float = 900.0
    """A jump is a step of at most this long (over a longer silence a vessel may do anything)."""
    jump_min_reports: int = 3
    """Fewest reports a displaced stretch holds (fewer: a glitch, not a shifted stretch)."""
    # speed- and course-inconsistent
    sog_floor_kn: float = 0.2
    cog_floor_deg: float = 2.0
    noise_cap: float = 25.0
    """A report's squared surprise counts at most this much (one wild value is not a stretch)."""
    noise_drift: float = 5.0
    """What each report's squared surprise must exceed to add to the CUSUM."""
    speed_limit: float = 50.0
    """The CUSUM's level that makes a stretch of reported speeds an event (the floor)."""
    course_limit: float = 50.0
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
    loiter_max_s: float = 86400.0
    """Slow for longer than this is a vessel laid up or at its berth, not loitering."""
    # gap at sea
    gap_factor: float = 10.0
    gap_min_s: float = 1800.0
    gap_max_s: float = 86400.0
    gap_under_way_kn: float = 1.0
    # ports and anchorages (after Global Fishing Watch's anchorages: `aisdati.events.anchorages`)
    stopped_kn: float = 0.5
    """A report under this speed is a vessel stopped (GFW: 0.5 kn for anchorages)."""
    anchorage_cell_m: float = 500.0
    """The side of the grid's cells (GFW: S2 cells of level 14, about 0.5 km)."""
    anchorage_min_vessels: int = 3
    """Distinct vessels stopped in a cell that make it an anchorage (GFW: 20, over years of
    the world's traffic; ours judges days to months of one area)."""
    # port visit (GFW: within 3 km of an anchorage and stopped; out beyond 4 km; 3 h or more)
    port_entry_m: float = 3000.0
    port_exit_m: float = 4000.0
    port_min_s: float = 3 * 3600.0
    # encounter (GFW: within 500 m for 2 h or more, under 2 kn, 10 km or more from anchorages)
    encounter_m: float = 500.0
    encounter_min_s: float = 2 * 3600.0
    encounter_kn: float = 2.0
    encounter_port_m: float = 10_000.0
    encounter_step_s: float = 600.0
    """Each vessel's position is interpolated every this many seconds (GFW: 10 minutes)."""
    encounter_max_gap_s: float = 3600.0
    """The longest silence a slow vessel's position is interpolated across."""
    # identity change
    identity_repeats: int = 3
    """Reports a new identity needs before its change is raised (a one-message typo is not)."""
    gap_coverage_m: float = 20_000.0
    """A gap's neighbourhood: other vessels' reports within this of the line between its ends
    tell whether the area kept being heard during it (`aisdati.events.coverage`)."""
    # gnss-interference (`aisdati.events.interference`)
    interference_min_m: float = 1000.0
    """The smallest unexplained displacement of a step (a jump at its floor) counted as a
    vessel displaced: lower than a position jump's alert, above a turn's or a clock's."""
    interference_z: float = 2.5
    """A step's unexplained displacement over the vessel's own scale that counts it displaced:
    half a position jump's floor (`jump_z`), as the vessels displaced alike make the event,
    not each one's size."""
    interference_within_s: float = 900.0
    """Vessels displaced within this of one another are displaced at once (each shows it at its
    next report: within its reporting interval)."""
    interference_radius_m: float = 50_000.0
    """Displaced vessels this close to one another (before or after their jumps) are in one area."""
    interference_min_vessels: int = 3
    """Fewest vessels displaced alike that make an interference (fewer: one vessel's own)."""
    interference_share: float = 0.5
    """Of the vessels heard near the displaced ones as they were displaced, the share displaced
    that makes it an interference (it moves every receiver of its area)."""
    interference_share_m: float = 5000.0
    """Near a displaced vessel: within this of where it was before its jump."""
    interference_point_m: float = 100.0
    """Displaced positions this close to one another are one common point."""
    interference_shift_share: float = 0.25
    """Two displacements are one shift when they differ by at most this share of the larger
    (and at most `interference_point_m` below that)."""
    interference_circle_share: float = 0.02
    """Displaced positions are on a circle when their rms distance from the fitted circle is at
    most this share of its radius."""

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)
