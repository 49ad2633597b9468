"""The data contracts of an ingest output (DESIGN.md), defined once: the columns and types of
points.parquet, tracks.parquet, reports.parquet, vessels.parquet, rejects.parquet and
routes.parquet, the names of the track sets (clusters and routes), and the unit of the speeds
they hold.

`aisdati.preprocess` writes these files and `aisdati.tracks.store` (training, detection) and
`aisdati.evaluation.dataset` (the evaluation's injected copy) read or write them, all through
these names."""

from __future__ import annotations

import pyarrow as pa

KNOT_MPS = 1852.0 / 3600.0
"""One knot (the unit of AIS SOG, and of `sog` in points.parquet) in metres per second."""

CLUSTERS = ("up", "down", "other")
"""The paper's direction clusters (tracks.parquet's `cluster`)."""
ROUTE_PREFIX = "route-"
"""Route clusters are named route-1, route-2, ... by size (tracks.parquet's `route`)."""
UNROUTED = "unrouted"
"""The name of the tracks that fit no route (`route` is null)."""
AREA = "all"
"""Every track of the ingest: the tracks an area model learns and judges."""

UTC_US = pa.timestamp("us", tz="UTC")
REPORT_FIELDS = [
    ("mmsi", pa.int64()),
    ("time", UTC_US),
    ("lon", pa.float64()),
    ("lat", pa.float64()),
    ("sog", pa.float32()),
    ("cog", pa.float32()),
    ("heading", pa.float32()),
    ("status", pa.int16()),
]
"""What one report holds, in points.parquet and reports.parquet alike."""
POINTS_SCHEMA = pa.schema([("track_id", pa.int64()), *REPORT_FIELDS])
"""A report a track is made of. `heading` (degrees, [0, 360)) is NaN where the report gave none
(AIS's 511, a blank); `status` is the navigational status (ITU-R M.1371: 0 under way using
engine, 1 at anchor, 5 moored, ...; 0-14), null where it is not defined (15) or not given."""
TRANSMITTER_STEP = 1_000_000_000
"""One MMSI heard from two transmitters at once (`aisdati.preprocess.transmitters`) is kept as
two vessels: the first transmitter under the MMSI, the second under MMSI + this (366123456's
second transmitter is 1366123456), so that no track joins them. MMSIs are nine digits; ingest
accepts longer numbers but never splits them, and reads an id of ten digits starting with 1 as
a second transmitter's."""


def mmsi_of(vessel: int) -> int:
    """The MMSI a vessel id stands for: itself, or the MMSI of a second transmitter's id."""
    vessel = int(vessel)
    return vessel - TRANSMITTER_STEP if is_second_transmitter(vessel) else vessel


def is_second_transmitter(vessel: int) -> bool:
    return TRANSMITTER_STEP <= vessel < 2 * TRANSMITTER_STEP


VESSEL_SCHEMA = pa.schema(
    [
        ("mmsi", pa.int64()),
        ("name", pa.string()),
        ("ship_type", pa.string()),
        ("length_m", pa.float64()),
    ]
)
"""vessels.parquet: who each vessel is, its most frequent value over the input (null or NaN where
none was given); `ship_type` is the ITU ship-type group of a numeric code (Fishing, Tug, Cargo,
...) or the source's own text."""
VESSEL_COLUMNS = VESSEL_SCHEMA.names[1:]
"""What tracks.parquet repeats of its vessel."""

IDENTITY_SCHEMA = pa.schema(
    [
        *VESSEL_SCHEMA,
        ("first", UTC_US),
        ("last", UTC_US),
        ("reports", pa.int64()),
    ]
)
"""identities.parquet: each identity a vessel reported (its name, ship type and length, as
vessels.parquet holds them; null where a message left one out), with its first and last time
(null where the source gave static data without times) and how many reports gave it: the
history `identity-change` is found in (`aisdati.events.identity`), sorted by MMSI, then first."""
TRACKS_SCHEMA = pa.schema(
    [
        ("track_id", pa.int64()),
        ("mmsi", pa.int64()),
        ("start", UTC_US),
        ("end", UTC_US),
        ("n_points", pa.int64()),
        ("length_km", pa.float64()),
        ("cluster", pa.string()),
        ("lon0", pa.float64()),
        ("lat0", pa.float64()),
        ("route", pa.string()),
        ("stage", pa.string()),
        ("name", pa.string()),  # the vessel's, as in vessels.parquet (`VESSEL_COLUMNS`)
        ("ship_type", pa.string()),
        ("length_m", pa.float64()),
        ("geometry", pa.binary()),
    ]
)
TRACK_COLUMNS = ["track_id", "mmsi", "start", "end", "n_points", "length_km", "cluster", "route"]
"""The columns of tracks.parquet that a track table holds (`aisdati.tracks.store`)."""
REJECTS_SCHEMA = pa.schema(
    [
        ("source", pa.string()),
        ("reason", pa.string()),
        ("mmsi", pa.int64()),
        ("time", UTC_US),
        ("lon", pa.float64()),
        ("lat", pa.float64()),
        ("sog", pa.float64()),
        ("cog", pa.float64()),
        ("raw", pa.string()),
    ]
)
REPORTS_SCHEMA = pa.schema([*REPORT_FIELDS, ("track_id", pa.int64())])
"""reports.parquet: every report that passed the value checks, the region of interest and the
vessel's own cleaning (duplicates, repeated times, position outliers), whatever its speed; its
`track_id` where it is a point of that track, null otherwise. The SOG filter (`--min-sog`) shapes
what a model learns from (points.parquet); what is judged keeps every report, so a vessel that
drifts, loiters or stops is judged on those reports too."""
ROUTES_SCHEMA = pa.schema(
    [
        ("route", pa.string()),
        ("n_tracks", pa.int64()),
        ("entry_lon", pa.float64()),
        ("entry_lat", pa.float64()),
        ("exit_lon", pa.float64()),
        ("exit_lat", pa.float64()),
        ("median_length_km", pa.float64()),
        ("medoid_track_id", pa.int64()),
        ("spread_km", pa.float64()),
        ("geometry", pa.binary()),
    ]
)
ROUTE_COLUMNS = ROUTES_SCHEMA.names[:-1]
"""A route's facts: routes.parquet's columns but its medoid's geometry."""


def geo_metadata(*geometry_types: str) -> dict:
    """GeoParquet metadata of a file whose `geometry` column holds WKB of these types; no `crs`
    means OGC:CRS84 (WGS84 lon/lat)."""
    return {
        "version": "1.1.0",
        "primary_column": "geometry",
        "columns": {"geometry": {"encoding": "WKB", "geometry_types": list(geometry_types)}},
    }


GEO_METADATA = geo_metadata("LineString")
"""GeoParquet metadata of tracks.parquet and routes.parquet."""
