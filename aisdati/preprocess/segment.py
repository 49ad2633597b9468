"""Segmentation: split each vessel's reports at stops and keep the long segments.

With reports at or below the SOG threshold filtered out, a stop shows up as a gap in time, so a
vessel's history is cut wherever two consecutive kept reports are more than `stop_gap_s` apart
(section 6 of the paper: stop points of more than an hour). Optional `stops` rules (see
`aisdati.preprocess.stops`) also cut where the vessel dwells for a shorter time, and may drop the
reports of the dwell itself. Segments with fewer than `min_points` reports are rejected (the paper
keeps at least 900).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from aisdati.preprocess.report import CODE
from aisdati.preprocess.stops import GapSplitter, Reports, Splitter, split_reports


def segment(
    mmsi: np.ndarray,
    time_us: np.ndarray,
    stop_gap_s: float,
    min_points: int,
    stops: Sequence[Splitter] = (),
    lon: np.ndarray | None = None,
    lat: np.ndarray | None = None,
    sog: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """For reports sorted by (MMSI, time): the track index of each report (-1 when its segment is
    too short or it lies inside a stop, tracks numbered 0.. in order), a rejection code per
    report, and the number of segments dropped as too short. `stops` are applied before the gap
    rule (positions and SOG are needed by the dwell rules)."""
    n = len(mmsi)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.uint8), 0
    splits = split_reports(Reports(mmsi, time_us, lon, lat, sog), [*stops, GapSplitter(stop_gap_s)])
    kept = np.flatnonzero(~splits.drop)
    seg = np.cumsum(splits.starts[kept]) - 1
    sizes = np.bincount(seg) if len(kept) else np.zeros(0, dtype=np.int64)
    long_enough = sizes >= min_points
    track_of_seg = np.where(long_enough, np.cumsum(long_enough) - 1, -1)
    track = np.full(n, -1, dtype=np.int64)
    track[kept] = track_of_seg[seg]
    codes = np.where(track < 0, CODE["short_segment"], 0).astype(np.uint8)
    codes[splits.drop] = CODE["dwell"]
    return track, codes, int((~long_enough).sum())


def antimeridian_crossing(mmsi: np.ndarray, lon: np.ndarray, track: np.ndarray) -> int | None:
    """The MMSI of the first kept track (`track` >= 0, rows sorted by (MMSI, time)) whose
    consecutive reports are more than 180 degrees of longitude apart, i.e. that crosses the
    antimeridian; None when none does. Region boxes, corridors and route clusters are not
    circular in longitude, so such a track would span every longitude."""
    kept = np.flatnonzero(track >= 0)
    if len(kept) < 2:
        return None
    same = track[kept[1:]] == track[kept[:-1]]
    jumps = same & (np.abs(np.diff(lon[kept])) > 180.0)
    return int(mmsi[kept[1:][jumps][0]]) if jumps.any() else None


def antimeridian_message(mmsi: int) -> str:
    """The one-line refusal of a track across 180 degrees, and what to do instead."""
    return (
        f"vessel {mmsi} has a track that crosses the antimeridian (longitude +-180): aisdati "
        "does not yet handle tracks across 180 degrees (its region boxes, corridors and route "
        "clusters are not circular in longitude); shift the longitudes (e.g. into 0..360) or "
        "split the data at 180; nothing written"
    )
