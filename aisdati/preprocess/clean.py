"""Filter and clean: sentinels and ranges, period, region of interest and SOG, duplicates,
position outliers, and SOG/COG for sources that only give positions.

Two kinds of stage. `check_values`, `filter_period` and `filter_area_speed` look at one row at a
time, so they run on every record batch as it is read (vectorised, cheap, and they drop most
rows early).
`clean_vessels` needs each vessel's reports in time order, so it runs on a partition that holds
whole vessels. Every function returns a rejection code per row (see `report.REASONS`) instead of
dropping rows, so each dropped row is counted under one reason.
"""

from __future__ import annotations

import numba
import numpy as np
import pyarrow as pa

from aisdati.geo import haversine_m, haversine_one_m, initial_bearing_deg
from aisdati.preprocess.report import CODE
from aisdati.preprocess.roi import in_roi
from aisdati.preprocess.settings import IngestSettings
from aisdati.preprocess.transmitters import split_transmitters
from aisdati.tracks.schema import KNOT_MPS

SENTINEL_LAT = 91.0
SENTINEL_LON = 181.0
SENTINEL_SOG = 102.3
SENTINEL_COG = 360.0
MAX_VALID_SOG = 102.2
"""AIS encodes 'not available' as LAT 91, LON 181, SOG 102.3, COG 360 (and heading 511; heading is
not read, since the pipeline does not use it, so it rejects nothing)."""

POSITION_TOLERANCE_M = 50.0
"""Slack on the implied-speed test: GPS noise and whole-second timestamps make two honest
reports a few seconds apart look faster than they are."""


def _mark(codes: np.ndarray, mask: np.ndarray, reason: str) -> None:
    """Give `reason` to the rows of `mask` that no earlier check rejected."""
    codes[(codes == 0) & mask] = CODE[reason]


def _col(table: pa.Table, name: str) -> np.ndarray:
    return table.column(name).to_numpy()


def check_values(table: pa.Table, codes: np.ndarray) -> pa.Table:
    """Reject sentinels and out-of-range values; return the table with COG normalised into
    [0, 360) (some sources write -60.6 for 299.4). One compiled pass over the rows: as five
    vectorised masks and a modulo it was a fifth of the CSV reading's time."""
    lat, lon, sog, cog = (_col(table, c) for c in ("lat", "lon", "sog", "cog"))
    cog = _check_rows(
        lat,
        lon,
        sog,
        cog,
        codes,
        np.array([CODE[r] for r in ("sentinel_lat", "sentinel_lon", "sentinel_sog")], np.uint8),
        np.uint8(CODE["sentinel_cog"]),
        np.uint8(CODE["out_of_range"]),
    )
    return table.set_column(table.schema.get_field_index("cog"), "cog", pa.array(cog))


@numba.njit(cache=True, nogil=True)
def _check_rows(lat, lon, sog, cog, codes, sentinel, sentinel_cog, out_of_range):
    """`check_values`' kernel: each row's first failed check, in the order sentinels (LAT, LON,
    SOG, COG) then ranges, into `codes` where it is 0; the COG column normalised. NaN fails no
    check (SOG and COG still to be derived are NaN)."""
    n = lat.shape[0]
    out = np.empty(n, np.float64)
    for i in range(n):
        c = cog[i]
        if codes[i] == 0:
            if lat[i] == SENTINEL_LAT:
                codes[i] = sentinel[0]
            elif lon[i] == SENTINEL_LON:
                codes[i] = sentinel[1]
            elif sog[i] == SENTINEL_SOG:
                codes[i] = sentinel[2]
            elif c == SENTINEL_COG:
                codes[i] = sentinel_cog
            elif (
                abs(lat[i]) > 90
                or abs(lon[i]) > 180
                or sog[i] < 0
                or sog[i] > MAX_VALID_SOG
                or c <= -360
                or c > 360
            ):
                codes[i] = out_of_range
        if c < 0.0 or c >= 360.0:
            c = np.mod(c, 360.0)
            if c >= 360.0:  # np.mod(-1e-15, 360) rounds to 360
                c = 0.0
        out[i] = c
    return out


def filter_period(table: pa.Table, codes: np.ndarray, settings: IngestSettings) -> None:
    """Reject reports outside the period (`--since`, inclusive; `--until`, exclusive)."""
    since, until = settings.period_us()
    if since is None and until is None:
        return
    time_us = _col(table, "time").view(np.int64)
    if since is not None:
        _mark(codes, time_us < since, "outside_period")
    if until is not None:
        _mark(codes, time_us >= until, "outside_period")


def filter_area_speed(table: pa.Table, codes: np.ndarray, roi, settings: IngestSettings) -> None:
    """Reject reports outside the region of interest (when there is one) and at or below
    `min_sog_kn`. Rows whose SOG is still to be derived are judged after derivation."""
    if roi is not None:
        idx = np.flatnonzero(codes == 0)
        inside = in_roi(roi, _col(table, "lon")[idx], _col(table, "lat")[idx])
        codes[idx[~inside]] = CODE["outside_roi"]
    with np.errstate(invalid="ignore"):
        _mark(codes, _col(table, "sog") <= settings.min_sog_kn, "slow")


REANCHOR_RUN = 3
"""Consecutive rejected reports that agree with each other and outvote the reference: then the
reference was the outlier (a bad first report), and those reports are kept from then on."""


@numba.njit(cache=True)
def _too_fast(i, j, time_us, lon, lat, max_mps, tolerance_m):
    """Whether report j cannot be reached from report i at `max_mps` (plus GPS tolerance)."""
    dist = haversine_one_m(lon[i], lat[i], lon[j], lat[j])
    return dist > max_mps * abs(time_us[j] - time_us[i]) / 1e6 + tolerance_m


@numba.njit(cache=True)
def _implied_speed_outliers(mmsi, time_us, lon, lat, max_mps, tolerance_m, reset_us):
    """Mask of reports too far from the previous *kept* report of the same vessel to be reached
    at `max_mps`. Sequential by nature (a rejected report must not become the reference), so
    compiled. After a gap longer than `reset_us` the next report is trusted again; and when
    `REANCHOR_RUN` consecutive rejected reports agree with each other, they are kept and the last
    becomes the reference; the old reference is rejected too when nothing had confirmed it (a
    vessel's first report). So one bad report cannot reject the rest of a vessel's history."""
    n = mmsi.shape[0]
    reject = np.zeros(n, dtype=np.bool_)
    last = -1
    confirmed = False  # whether the reference was reached from an earlier kept report
    run_start = -1  # first of the current run of consecutive, mutually consistent rejections
    for i in range(n):
        if last < 0 or mmsi[i] != mmsi[last] or time_us[i] - time_us[last] > reset_us:
            last = i
            confirmed = False
            run_start = -1
            continue
        if not _too_fast(last, i, time_us, lon, lat, max_mps, tolerance_m):
            last = i
            confirmed = True
            run_start = -1
            continue
        reject[i] = True
        if run_start >= 0 and not _too_fast(i - 1, i, time_us, lon, lat, max_mps, tolerance_m):
            if i - run_start + 1 >= REANCHOR_RUN:
                reject[run_start : i + 1] = False
                reject[last] = reject[last] or not confirmed
                last = i
                confirmed = True
                run_start = -1
        else:
            run_start = i
    return reject


def clean_vessels(table: pa.Table, settings: IngestSettings) -> tuple[pa.Table, np.ndarray]:
    """Per-vessel cleaning of a partition holding whole vessels: sort by (MMSI, time), tell
    apart two transmitters sharing an MMSI (`transmitters.split_transmitters`: the second's
    reports kept under an id of its own, not dropped as outliers), reject exact duplicates and
    repeated timestamps, then position outliers by implied speed, then derive missing SOG/COG
    from the kept positions and apply the SOG filter to them.
    Returns the sorted table (with SOG/COG filled in) and one code per row."""
    order = np.lexsort((_col(table, "time").view(np.int64), _col(table, "mmsi")))
    table = split_transmitters(
        table.take(pa.array(order)),
        settings.max_speed_kn * KNOT_MPS,
        POSITION_TOLERANCE_M,
        int(settings.stop_gap_s * 1e6),
    )
    mmsi = _col(table, "mmsi")
    time_us = _col(table, "time").view(np.int64)
    lon, lat, sog, cog = (_col(table, c).copy() for c in ("lon", "lat", "sog", "cog"))
    codes = np.zeros(len(mmsi), dtype=np.uint8)
    if len(mmsi) == 0:
        return table, codes

    first = np.r_[True, (mmsi[1:] != mmsi[:-1]) | (time_us[1:] != time_us[:-1])]
    head = np.maximum.accumulate(np.where(first, np.arange(len(first)), 0))
    same = (lon == lon[head]) & (lat == lat[head])
    for v in (sog, cog):
        same &= (v == v[head]) | (np.isnan(v) & np.isnan(v[head]))
    _mark(codes, ~first & same, "duplicate")
    _mark(codes, ~first, "repeated_timestamp")

    kept = np.flatnonzero(codes == 0)
    outliers = _implied_speed_outliers(
        mmsi[kept],
        time_us[kept],
        lon[kept],
        lat[kept],
        settings.max_speed_kn * KNOT_MPS,
        POSITION_TOLERANCE_M,
        int(settings.stop_gap_s * 1e6),
    )
    codes[kept[outliers]] = CODE["implied_speed"]

    kept = np.flatnonzero(codes == 0)
    need_sog = np.isnan(sog[kept])
    need_cog = np.isnan(cog[kept])
    if need_sog.any() or need_cog.any():
        d_sog, d_cog = derive_sog_cog(mmsi[kept], time_us[kept], lon[kept], lat[kept], settings)
        sog[kept[need_sog]] = d_sog[need_sog]
        cog[kept[need_cog]] = d_cog[need_cog]
        slow = kept[need_sog & (d_sog <= settings.min_sog_kn)]
        codes[slow] = CODE["slow"]
    table = table.set_column(4, "sog", pa.array(sog)).set_column(5, "cog", pa.array(cog))
    return table, codes


def derive_sog_cog(
    mmsi: np.ndarray,
    time_us: np.ndarray,
    lon: np.ndarray,
    lat: np.ndarray,
    settings: IngestSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """SOG (knots) and COG (degrees) from consecutive positions of each vessel, sorted by time:
    from the previous report when it is of the same vessel and less than a stop gap earlier, else
    towards the next one; a report with neither neighbour is at rest (SOG 0)."""
    n = len(mmsi)
    step_sog = np.zeros(max(n - 1, 0))
    step_cog = np.zeros(max(n - 1, 0))
    linked = np.zeros(max(n - 1, 0), dtype=bool)
    if n > 1:
        dt_s = (time_us[1:] - time_us[:-1]) / 1e6
        linked = (mmsi[1:] == mmsi[:-1]) & (dt_s > 0) & (dt_s <= settings.stop_gap_s)
        dist = haversine_m(lon[:-1], lat[:-1], lon[1:], lat[1:])
        with np.errstate(divide="ignore", invalid="ignore"):
            step_sog = np.where(linked, dist / np.where(dt_s > 0, dt_s, 1.0) / KNOT_MPS, 0.0)
        step_cog = initial_bearing_deg(lon[:-1], lat[:-1], lon[1:], lat[1:])
    sog = np.zeros(n)
    cog = np.zeros(n)
    back = np.r_[False, linked]  # row i has a step from i-1
    fwd = np.r_[linked, False] & ~back  # otherwise use the step to i+1
    sog[back] = step_sog[back[1:]]
    cog[back] = step_cog[back[1:]]
    sog[fwd] = step_sog[fwd[:-1]]
    cog[fwd] = step_cog[fwd[:-1]]
    return sog, cog
