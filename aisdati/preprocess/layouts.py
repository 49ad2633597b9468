"""Which source column holds what: the spellings of the needed columns in the CSV and parquet
layouts seen in the wild, and the layouts that need more than names (the Danish Maritime
Authority's day-first timestamps).

Columns are matched by name, ignoring case, underscores, spaces and other punctuation, so
`BaseDateTime`, `base_date_time` and the DMA's `# Timestamp` all name the time; their order does
not matter and extra columns are ignored.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from aisdati.errors import UserError

ALIASES: dict[str, tuple[str, ...]] = {
    "mmsi": ("mmsi",),
    "time": ("basedatetime", "basedatatime", "datetime", "timestamp", "time", "datetimeutc"),
    "lat": ("lat", "latitude", "lattitude"),
    "lon": ("lon", "long", "lng", "longitude", "longtitude"),
    "sog": ("sog", "speedoverground"),
    "cog": ("cog", "courseoverground"),
    "heading": ("heading", "trueheading"),
    "status": ("status", "navigationalstatus", "navstatus"),
    "name": ("vesselname", "name", "shipname"),
    "ship_type": ("vesseltype", "shiptype"),
    "length": ("length", "vessellength"),
}
"""Canonical column -> normalised spellings (lower case, letters and digits only)."""
REQUIRED = ("mmsi", "time", "lat", "lon")
OPTIONAL = ("heading", "status", "name", "ship_type", "length")
"""Columns read where a file has them, never needed: a blank or bad value rejects no row, and
where two columns look like one of them the first is read."""
STATIC = ("name", "ship_type", "length")
"""The optional columns that tell who the vessel is (`aisdati.preprocess.vessels`), not where it
is: they go into vessels.parquet, not into the rows."""


@dataclass(frozen=True)
class Layout:
    """A family of files told apart by their column names."""

    name: str
    marker_columns: frozenset[str]
    """Normalised names that all appear in this layout's header (and in no other's)."""
    time_format: str | None
    """`strptime` format of the time column, or None for ISO 8601 text or epoch numbers."""


MARINECADASTRE = Layout("marinecadastre", frozenset(), None)
DMA = Layout(
    "dma",
    frozenset({"timestamp", "typeofmobile"}),
    "%d/%m/%Y %H:%M:%S",
)
"""The Danish Maritime Authority's AIS CSV (aisdk-*.csv): `# Timestamp,Type of mobile,MMSI,
Latitude,Longitude,...,Data source type,A,B,C,D`, times day first (`01/12/2021 00:00:00`), UTC."""
LAYOUTS = (DMA,)
"""Layouts recognised by their marker columns; anything else reads as MarineCadastre's."""


def normalise_name(name: str) -> str:
    """A column name as matched against `ALIASES`: lower case letters and digits only."""
    return re.sub(r"[^a-z0-9]", "", name.lower())


def layout_of(names: list[str]) -> Layout:
    """The layout whose marker columns the header holds (MarineCadastre's when none)."""
    present = {normalise_name(n) for n in names}
    return next((lay for lay in LAYOUTS if lay.marker_columns <= present), MARINECADASTRE)


def resolve_columns(names: list[str], label: str) -> dict[str, str]:
    """Canonical column -> the source's own column name. Raises a `UserError` naming a missing
    required column; SOG and COG may be absent (they are then derived from the positions), and
    so may the `OPTIONAL` ones."""
    found: dict[str, str] = {}
    for name in names:
        key = normalise_name(name)
        for canonical, spellings in ALIASES.items():
            if key in spellings:
                if canonical in found and canonical in OPTIONAL:
                    continue
                if canonical in found:
                    raise UserError(
                        f"{label}: columns {found[canonical][:40]!r} and {name[:40]!r} both look "
                        f"like {canonical.upper()}"
                    )
                found[canonical] = name
    missing = [c for c in REQUIRED if c not in found]
    if missing:
        wanted = ", ".join(f"{c.upper()} (e.g. {ALIASES[c][0]})" for c in missing)
        shown = repr([n if len(n) <= 40 else n[:37] + "..." for n in names[:30]])
        more = f" and {len(names) - 30} more" if len(names) > 30 else ""
        raise UserError(f"{label}: missing required column {wanted}; header is {shown}{more}")
    return found
