"""Splitting a vessel's reports into tracks at stops: one small class per rule.

The paper splits only where the time between two kept reports exceeds an hour. In a harbour that
leaves a ferry's whole day as one track: its stops at the piers last 5-15 minutes. The rules here,
modelled on MovingPandas' splitters (`ObservationGapSplitter`, `StopSplitter`), also split where
the vessel *dwells*:

- `GapSplitter` (the paper's rule, MovingPandas' ObservationGapSplitter): a time gap longer than
  `max_gap_s` between consecutive kept reports.
- `DwellGapSplitter`: a stop hidden by the SOG filter. Ingest drops the reports at or below
  `--min-sog` *before* segmenting, so a vessel lying at a pier leaves a gap between its last report
  on the way in and its first on the way out. Reporting gaps while under way look the same, so the
  rule estimates how long the vessel was *not* under way: the gap minus the time it needs to cover
  the straight-line distance across the gap at the mean of the two reported speeds (never below
  `--min-sog`, the slowest a kept report can be). A vessel that sailed on through a reporting gap
  covers the distance in about the gap's time (estimate near zero, or negative); one that lay at a
  pier covers only its approach and departure. A stop is an estimated dwell of at least
  `min_dwell_s` with the two reports at most a diameter (2 x `radius_m`) apart, both inside the
  stop's circle: that keeps slow steaming (2-4 km in half an hour below the SOG threshold) from
  counting as a stop. (MovingPandas' SpeedSplitter is the same idea with the slow reports in
  hand: drop them, then split at gaps longer than the duration.)
- `StopSplitter` (MovingPandas' StopSplitter): a run of kept reports that all stay within
  `radius_m` of the run's first report for at least `min_duration_s`, reports less than
  `min_duration_s` apart (a longer gap is the rule above's). This is what catches a dwell when
  slow reports are kept (`--min-sog 0`: a moored vessel's reports), or a vessel holding station
  or loitering under way (at most `radius_m` in `min_duration_s`: 3.2 kn with the defaults). The
  run's reports are removed from the tracks (rejected as `dwell`), and the track splits there.

The defaults of ingest are 500 m and 5 minutes. MovingPandas' examples use 100 m across and one
minute for people on foot (and speak of stops of 5 minutes); for ships they were chosen on the
New York Harbor ferries (`tests/preprocess/test_stops.py`). At 1-3 minutes between reports the
last report before a pier and the first after it lie 0.1-1 km apart (the Staten Island Ferry:
about 0.5 km in the median), hence a 500 m radius (1 km across); the ferries' pier stops last
5-15 minutes, while reporting gaps of 3-10 minutes under way are common (Kitimat), hence 5
minutes, with the dwell estimate telling the two apart.

Every splitter maps reports sorted by (MMSI, time) to `Splits`: where a new track starts and
which reports to drop. `split_reports` applies a list of them in order; `segment` then numbers the
tracks and drops the short ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from aisdati.geo import haversine_m, haversine_one_m
from aisdati.tracks.schema import KNOT_MPS

MIN_STOP_SPEED_KN = 0.5
"""Floor on the speed `DwellGapSplitter` assumes across a gap, so that `--min-sog 0` does not make
every gap look like a stop."""


@dataclass(frozen=True)
class Reports:
    """One partition's kept reports, sorted by (MMSI, time); `sog` in knots (NaN if unknown)."""

    mmsi: np.ndarray
    time_us: np.ndarray
    lon: np.ndarray | None = None
    lat: np.ndarray | None = None
    sog: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.mmsi)

    def same_vessel(self) -> np.ndarray:
        """[n - 1] whether report i + 1 is of the same vessel as report i."""
        return self.mmsi[1:] == self.mmsi[:-1]

    def need_positions(self, who: str) -> tuple[np.ndarray, np.ndarray]:
        if self.lon is None or self.lat is None:
            raise ValueError(f"{who} needs the reports' positions")
        return self.lon, self.lat


@dataclass(frozen=True)
class Splits:
    """`starts[i]`: report i begins a new track; `drop[i]`: report i belongs to no track."""

    starts: np.ndarray
    drop: np.ndarray


def _no_splits(n: int) -> Splits:
    return Splits(np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))


@dataclass(frozen=True)
class GapSplitter:
    """Split where consecutive reports of a vessel are more than `max_gap_s` apart (the paper's
    rule: one hour)."""

    max_gap_s: float

    def split(self, r: Reports) -> Splits:
        out = _no_splits(len(r))
        if len(r) > 1:
            out.starts[1:] = np.diff(r.time_us) > int(self.max_gap_s * 1e6)
        return out


@dataclass(frozen=True)
class DwellGapSplitter:
    """Split at a gap in which the vessel lay still for at least `min_dwell_s` within a circle of
    `radius_m`: the reports on either side are at most a diameter apart, and the gap's duration,
    less the time needed to cover the distance across it at the mean reported speed of its two
    ends (floored at `min_speed_kn`, the SOG filter's threshold), is at least `min_dwell_s`."""

    radius_m: float
    min_dwell_s: float
    min_speed_kn: float = 3.0

    def split(self, r: Reports) -> Splits:
        out = _no_splits(len(r))
        if len(r) < 2 or self.min_dwell_s <= 0:
            return out
        dist, dwell = self.gaps(r)
        out.starts[1:] = (dwell >= self.min_dwell_s) & (dist <= 2 * self.radius_m) & r.same_vessel()
        return out

    def gaps(self, r: Reports) -> tuple[np.ndarray, np.ndarray]:
        """[n - 1] the distance (m) between report i and report i + 1 and the estimated time
        (s) the vessel spent at rest between them."""
        lon, lat = r.need_positions("DwellGapSplitter")
        gap_s = np.diff(r.time_us) / 1e6
        dist = haversine_m(lon[:-1], lat[:-1], lon[1:], lat[1:])
        floor = max(self.min_speed_kn, MIN_STOP_SPEED_KN)
        if r.sog is None:
            speed = np.full(len(dist), floor)
        else:
            sog = np.asarray(r.sog, dtype=np.float64)
            speed = np.fmax(np.nan_to_num((sog[:-1] + sog[1:]) / 2, nan=floor), floor)
        return dist, gap_s - dist / (speed * KNOT_MPS)


@dataclass(frozen=True)
class StopSplitter:
    """MovingPandas' StopSplitter: a stop is a run of reports that all lie within `radius_m` of
    the run's first report and last at least `min_duration_s`, seen by reports less than
    `min_duration_s` apart; its reports are dropped and the vessel's next report starts a new
    track."""

    radius_m: float
    min_duration_s: float

    def split(self, r: Reports) -> Splits:
        out = _no_splits(len(r))
        if len(r) < 2 or self.min_duration_s <= 0 or self.radius_m <= 0:
            return out
        lon, lat = r.need_positions("StopSplitter")
        stop = _stop_runs(
            r.mmsi,
            r.time_us,
            np.asarray(lon, np.float64),
            np.asarray(lat, np.float64),
            float(self.radius_m),
            int(self.min_duration_s * 1e6),
        )
        out.drop[:] = stop
        # the first report after a stop (same vessel) starts a new track
        out.starts[1:] = stop[:-1] & ~stop[1:] & r.same_vessel()
        return out


@numba.njit(cache=True)
def _stop_runs(mmsi, time_us, lon, lat, radius_m, min_duration_us):  # pragma: no cover - compiled
    """Mask of reports inside a stop: greedy left-to-right, a run starting at report s extends
    while the reports stay within `radius_m` of report s and follow each other by less than
    `min_duration_us` (a dwell inside one longer gap is `DwellGapSplitter`'s to judge, without
    dropping the reports around it); a run lasting `min_duration_us` or more is a stop, and the
    scan resumes after it."""
    n = mmsi.shape[0]
    stop = np.zeros(n, dtype=np.bool_)
    s = 0
    while s < n:
        e = s
        while (
            e + 1 < n and mmsi[e + 1] == mmsi[s] and time_us[e + 1] - time_us[e] < min_duration_us
        ):
            if haversine_one_m(lon[s], lat[s], lon[e + 1], lat[e + 1]) > radius_m:
                break
            e += 1
        if e > s and time_us[e] - time_us[s] >= min_duration_us:
            stop[s : e + 1] = True
            s = e + 1
        else:
            s += 1
    return stop


Splitter = GapSplitter | DwellGapSplitter | StopSplitter


def split_reports(r: Reports, splitters: Sequence[Splitter]) -> Splits:
    """Apply splitters in order; each sees only the reports the ones before it kept. A report
    starts a new track when a splitter says so, when it is a vessel's first kept report, or when
    reports just before it were dropped (a removed stop always separates two tracks)."""
    n = len(r)
    starts = np.zeros(n, dtype=bool)
    drop = np.zeros(n, dtype=bool)
    idx = np.arange(n)
    for splitter in splitters:
        sub = Reports(*(None if a is None else a[idx] for a in _arrays(r)))
        result = splitter.split(sub)
        starts[idx[result.starts]] = True
        drop[idx[result.drop]] = True
        idx = idx[~result.drop]
    if len(idx):
        starts[idx[0]] = True
        gap_before = np.diff(idx) > 1
        starts[idx[1:]] |= (r.mmsi[idx[1:]] != r.mmsi[idx[:-1]]) | gap_before
    starts[drop] = False
    return Splits(starts, drop)


def _arrays(r: Reports) -> tuple[np.ndarray | None, ...]:
    return (r.mmsi, r.time_us, r.lon, r.lat, r.sog)


def dwell_rules(dwell_radius_m: float, dwell_time_s: float, min_sog_kn: float) -> list[Splitter]:
    """The dwell rules of ingest, applied before the paper's gap rule; none when `dwell_time_s`
    is 0 (the paper's segmentation alone)."""
    if dwell_time_s <= 0:
        return []
    return [
        StopSplitter(dwell_radius_m, dwell_time_s),
        DwellGapSplitter(dwell_radius_m, dwell_time_s, min_sog_kn),
    ]
