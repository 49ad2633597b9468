"""Who each vessel is (vessels.parquet, and the same columns in tracks.parquet): its name, ship
type and length, each the most frequent value its reports and static messages gave over the
whole input (ties: the one seen last).

The values come with the position rows of a CSV or parquet file (MarineCadastre's `VesselName`,
`VesselType`, `Length`; the DMA's `Name`, `Ship type`, `Length`) or in NMEA static messages
(types 5, 19 and 24). A national month repeats them in every row, so they are never carried
with the rows: each read task tallies them (`VesselTally`: one row per distinct (MMSI, name,
type, length) with its count and where it was last seen, bounded by the vessels, not the rows),
and this process merges the tallies (`tally`) and picks each vessel's values (`winners`). On the
CSV fast path the rows are not even decoded: the scan hashes each row's MMSI and static fields
(`fastcsv`), and only a hash not met before has its row's text read (`VesselTally.know`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aisdati.tracks.schema import IDENTITY_SCHEMA, VESSEL_COLUMNS, VESSEL_SCHEMA, mmsi_of

ORDER_BITS = 40
"""A row's place in the input: its source number above this many bits, its row in the source
below (a source of 10^12 rows is none)."""
COMPACT_ROWS = 1 << 20
"""Tally rows held before they are merged: a tally stays bounded by the vessels."""
PADDING = "@ \t"
"""AIS pads names with '@' (and writers with spaces)."""
SHIP_TYPES = {
    30: "Fishing",
    31: "Towing",
    32: "Towing",
    35: "Military",
    36: "Sailing",
    37: "Pleasure craft",
    50: "Pilot",
    51: "Search and rescue",
    52: "Tug",
    55: "Law enforcement",
    **{code: "High speed craft" for code in range(40, 50)},
    **{code: "Passenger" for code in range(60, 70)},
    **{code: "Cargo" for code in range(70, 80)},
    **{code: "Tanker" for code in range(80, 90)},
}
"""ITU-R M.1371 ship-type codes (as MarineCadastre's `VesselType` and NMEA write them) -> their
group; any other code of 1-99 is 'Other', 0 (not available) and numbers outside 0-99 none."""
OTHER_TYPE = "Other"
NO_TYPE = frozenset({"undefined"})
"""Ship types written as text that say none was given (the DMA's 'Undefined'), lower case."""
STATIC_COLUMNS = ("name", "ship_type", "length")
"""The canonical columns (`layouts.STATIC`) a tally reads, in its order."""
TALLY_SCHEMA = pa.schema(
    [
        *VESSEL_SCHEMA,
        ("count", pa.int64()),
        ("last", pa.int64()),
        ("first_us", pa.int64()),
        ("last_us", pa.int64()),
    ]
)
"""One row per distinct (MMSI, name, ship type, length): how often it was seen, where last
(`ORDER_BITS`), and when first and last (microseconds since the epoch; `NO_FIRST`/`NO_LAST`
where the source gave no time with it): the identity history (`identity_history`)."""
NO_FIRST, NO_LAST = np.iinfo(np.int64).max, np.iinfo(np.int64).min


def ship_type_of(text: str) -> str | None:
    """A ship type as written: a number is its ITU group (`SHIP_TYPES`), other text is kept
    (but `NO_TYPE`)."""
    try:
        number = float(text)
    except ValueError:
        return None if text.lower() in NO_TYPE else text
    if number != np.floor(number) or not 0 < number <= 99:
        return None
    return SHIP_TYPES.get(int(number), OTHER_TYPE)


def length_of(text: str) -> float | None:
    """A length in metres as written, None where it is none (0 is AIS's 'not available')."""
    try:
        number = float(text)
    except ValueError:
        return None
    return number if np.isfinite(number) and number > 0 else None


def _cleaned(arr: pa.Array) -> pa.Array:
    """Text without AIS padding, null where nothing is left (numbers written as text)."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    if not (pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type)):
        arr = pc.cast(arr, pa.string())
    text = pc.utf8_trim(arr, characters=PADDING)
    return pc.if_else(pc.equal(text, ""), pa.scalar(None, pa.string()), text).cast(pa.string())


def _per_value(arr: pa.Array, read: Callable[[str], object], kind: pa.DataType) -> pa.Array:
    """`read` of each distinct cleaned value (a file repeats a vessel's values in every row)."""
    encoded = pc.dictionary_encode(_cleaned(arr))
    values = pa.array([read(v) for v in encoded.dictionary.to_pylist()], kind)
    return values.take(encoded.indices)


def _values(columns: dict[str, pa.Array], n: int) -> list[pa.Array]:
    """The static columns (`STATIC_COLUMNS`, as the source wrote them) as vessels.parquet holds
    them (`VESSEL_COLUMNS`), null where a column is absent or a value none."""
    readers = {"ship_type": (ship_type_of, pa.string()), "length": (length_of, pa.float64())}
    values = []
    for key, field in zip(STATIC_COLUMNS, VESSEL_COLUMNS, strict=True):
        if key not in columns:
            values.append(pa.nulls(n, VESSEL_SCHEMA.field(field).type))
        elif key in readers:
            values.append(_per_value(columns[key], *readers[key]))
        else:
            values.append(_cleaned(columns[key]))
    return values


def _given(mmsi: np.ndarray, values: list[pa.Array]) -> np.ndarray:
    """Which rows have an MMSI and give any value."""
    given = np.zeros(len(mmsi), bool)
    for value in values:
        given |= value.is_valid().to_numpy(zero_copy_only=False)
    return given & (mmsi > 0)


def _rows(
    mmsi: np.ndarray, values: list[pa.Array], order: np.ndarray, time_us: np.ndarray | None = None
) -> pa.Table:
    ones = np.ones(len(mmsi), np.int64)
    first, last = _times(time_us, len(mmsi))
    columns = [pa.array(mmsi, pa.int64()), *values, ones, order.astype(np.int64), first, last]
    return pa.table(columns, schema=TALLY_SCHEMA)


def _times(time_us: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows' times (microseconds; NaT's or none: unknown) as their first and last time."""
    if time_us is None:
        return np.full(n, NO_FIRST), np.full(n, NO_LAST)
    time_us = np.asarray(time_us).view(np.int64)
    return np.where(time_us == NO_LAST, NO_FIRST, time_us), time_us


def statics_rows(
    mmsi: np.ndarray,
    columns: dict[str, pa.Array],
    order: np.ndarray,
    time_us: np.ndarray | None = None,
) -> pa.Table:
    """Tally rows (`TALLY_SCHEMA`, a count of 1 each) of rows with these MMSIs (0: none) and
    static columns (`STATIC_COLUMNS`, as the source wrote them; absent: none), at places
    `order` and times `time_us` (None: unknown); rows without an MMSI, or without any value,
    are left out."""
    values = _values(columns, len(mmsi))
    return _rows(mmsi, values, order, time_us).filter(pa.array(_given(mmsi, values)))


def tally(rows: pa.Table) -> pa.Table:
    """Tally rows merged: one per distinct (MMSI, name, ship type, length)."""
    keys = VESSEL_SCHEMA.names
    sums = [("count", "sum"), ("last", "max"), ("first_us", "min"), ("last_us", "max")]
    merged = rows.group_by(keys, use_threads=False).aggregate(sums)
    return merged.rename_columns([*keys, *TALLY_SCHEMA.names[len(keys) :]]).cast(TALLY_SCHEMA)


class VesselTally:
    """One source's tally, fed as it is read: `add` takes rows with their static columns, and on
    the CSV fast path `add_counts` takes counts per hash (`fastcsv`'s `ParsedBlock.keys`), whose
    values `know` was told once, by the number it gave the hash (`numbers`), in arrays that grow
    with the vessels, not the rows."""

    def __init__(self) -> None:
        self._tables: list[pa.Table] = []
        self._held = 0
        self._sorted = np.zeros(0, np.int64)
        """The hashes known, sorted."""
        self._numbers = np.zeros(0, np.int64)
        """Each sorted hash's number (the order they became known)."""
        self._counts = np.zeros(0, np.int64)
        self._last = np.zeros(0, np.int64)
        self._first_us = np.zeros(0, np.int64)
        self._last_us = np.zeros(0, np.int64)
        self._values: list[pa.Table] = []
        """Tally rows of the known hashes, by number."""

    def add(
        self,
        mmsi: np.ndarray,
        columns: dict[str, pa.Array],
        order: np.ndarray,
        time_us: np.ndarray | None = None,
    ) -> None:
        """Rows (see `statics_rows`) at places `order` of the source, at times `time_us`."""
        if not columns or not len(mmsi):
            return
        self._tables.append(tally(statics_rows(mmsi, columns, order, time_us)))
        self._held += self._tables[-1].num_rows
        if self._held > COMPACT_ROWS:
            self._tables, self._held = [tally(pa.concat_tables(self._tables))], 0

    def numbers(self, keys: np.ndarray) -> np.ndarray:
        """Each hash's number, -1 where `know` was not told it."""
        if not len(self._sorted):
            return np.full(len(keys), -1, np.int64)
        at = np.minimum(np.searchsorted(self._sorted, keys), len(self._sorted) - 1)
        return np.where(self._sorted[at] == keys, self._numbers[at], -1)

    def know(self, keys: np.ndarray, mmsi: np.ndarray, columns: dict[str, pa.Array]) -> np.ndarray:
        """The vessel and static values of rows with these (new, distinct) hashes; their
        numbers."""
        values = _values(columns, len(keys))
        self._values.append(_rows(mmsi, values, np.zeros(len(keys), np.int64)))
        numbers = np.arange(len(self._counts), len(self._counts) + len(keys))
        hashes = np.concatenate([self._sorted, keys])
        order = np.argsort(hashes, kind="stable")
        self._sorted = hashes[order]
        self._numbers = np.concatenate([self._numbers, numbers])[order]
        self._counts = np.concatenate([self._counts, np.zeros(len(keys), np.int64)])
        self._last = np.concatenate([self._last, np.zeros(len(keys), np.int64)])
        self._first_us = np.concatenate([self._first_us, np.full(len(keys), NO_FIRST)])
        self._last_us = np.concatenate([self._last_us, np.full(len(keys), NO_LAST)])
        return numbers

    def add_counts(
        self,
        numbers: np.ndarray,
        counts: np.ndarray,
        order: np.ndarray,
        times_us: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Counts per hash, by the hashes' (distinct) numbers, each last seen at `order` (later
        than any place before), first and last at `times_us` (None: unknown)."""
        self._counts[numbers] += counts
        self._last[numbers] = order
        if times_us is not None:
            first, _ = _times(times_us[0], len(numbers))
            self._first_us[numbers] = np.minimum(self._first_us[numbers], first)
            self._last_us[numbers] = np.maximum(self._last_us[numbers], times_us[1])

    def table(self, src: int) -> pa.Table:
        """The tally of the source numbered `src` (`TALLY_SCHEMA`, places in the input)."""
        tables = [TALLY_SCHEMA.empty_table(), *self._tables, self._keyed_table()]
        merged = tally(pa.concat_tables(tables))
        last = pc.add(merged.column("last"), pa.scalar(src << ORDER_BITS, pa.int64()))
        return merged.set_column(merged.schema.get_field_index("last"), "last", last)

    def _keyed_table(self) -> pa.Table:
        """The counts per hash as tally rows, each hash with its values (a hash whose rows give
        none is left out)."""
        rows = pa.concat_tables([TALLY_SCHEMA.empty_table(), *self._values])
        kept = (
            ("count", self._counts),
            ("last", self._last),
            ("first_us", self._first_us),
            ("last_us", self._last_us),
        )
        for name, column in kept:
            rows = rows.set_column(TALLY_SCHEMA.get_field_index(name), name, pa.array(column))
        values = [rows.column(field) for field in VESSEL_COLUMNS]
        given = _given(rows.column("mmsi").to_numpy(), values) & (self._counts > 0)
        return rows.filter(pa.array(given))


def winners(tallies: list[pa.Table]) -> pa.Table:
    """Each vessel's values (`VESSEL_SCHEMA`, sorted by MMSI) from the tallies of every source:
    per column, its most frequent value, the one seen last among equals."""
    merged = tally(pa.concat_tables([TALLY_SCHEMA.empty_table(), *tallies]))
    vessels = pa.table({"mmsi": pc.unique(merged.column("mmsi"))}).sort_by("mmsi")
    for field in VESSEL_COLUMNS:
        vessels = vessels.append_column(VESSEL_SCHEMA.field(field), _winner(merged, field, vessels))
    return vessels


def _winner(merged: pa.Table, field: str, vessels: pa.Table) -> pa.Array:
    """One column's value per vessel of `vessels` (null where none was given)."""
    given = merged.filter(pc.is_valid(merged.column(field)))
    counted = given.group_by(["mmsi", field], use_threads=False).aggregate(
        [("count", "sum"), ("last", "max")]
    )
    order = [("mmsi", "ascending"), ("count_sum", "descending"), ("last_max", "descending")]
    counted = counted.sort_by(order)
    mmsi = counted.column("mmsi").to_numpy()
    first = np.flatnonzero(np.r_[True, mmsi[1:] != mmsi[:-1]]) if len(mmsi) else np.zeros(0, int)
    return values_by_mmsi(counted.take(pa.array(first)), field, vessels.column("mmsi").to_numpy())


def values_by_mmsi(table: pa.Table, field: str, mmsi: np.ndarray) -> pa.Array:
    """`table[field]` (its rows sorted by their unique MMSIs) of each of `mmsi`, null where the
    table has no row."""
    known = table.column("mmsi").to_numpy()
    kind = VESSEL_SCHEMA.field(field).type
    if not len(known):
        return pa.nulls(len(mmsi), kind)
    at = np.minimum(np.searchsorted(known, mmsi), len(known) - 1)
    hit = known[at] == mmsi
    values = table.column(field).combine_chunks().take(pa.array(at))
    return pc.if_else(pa.array(hit), values, pa.scalar(None, kind))


def vessels_table(found: pa.Table, mmsi: np.ndarray) -> pa.Table:
    """vessels.parquet: one row per vessel of `mmsi` (sorted, unique), with its values from
    `found` (`winners`) or none; a second transmitter's id (`schema.TRANSMITTER_STEP`) with
    those of its MMSI, whose static messages no receiver can tell apart."""
    named = np.array([mmsi_of(m) for m in mmsi], np.int64)
    columns = [values_by_mmsi(found, field, named) for field in VESSEL_COLUMNS]
    return pa.table([pa.array(mmsi, pa.int64()), *columns], schema=VESSEL_SCHEMA)


def with_vessels(tracks: pa.Table, vessels: pa.Table) -> pa.Table:
    """Rows of tracks.parquet with their vessel's columns (`VESSEL_COLUMNS`) from
    vessels.parquet's table."""
    mmsi = tracks.column("mmsi").to_numpy()
    for field in VESSEL_COLUMNS:
        at = tracks.schema.get_field_index(field)
        values = values_by_mmsi(vessels, field, mmsi)
        tracks = tracks.set_column(at, tracks.schema.field(at), values)
    return tracks


def identity_history(tallies: list[pa.Table]) -> pa.Table:
    """identities.parquet (`IDENTITY_SCHEMA`): each distinct identity of each vessel over every
    source's tally, with its first and last time (null where no source gave one) and its
    reports, sorted by MMSI, then first time."""
    merged = tally(pa.concat_tables([TALLY_SCHEMA.empty_table(), *tallies]))
    first, last = merged.column("first_us"), merged.column("last_us")
    columns = [merged.column(name) for name in VESSEL_SCHEMA.names]
    for times, none in ((first, NO_FIRST), (last, NO_LAST)):
        known = pc.not_equal(times, pa.scalar(none, pa.int64()))
        as_time = times.cast(pa.timestamp("us")).cast(IDENTITY_SCHEMA.field("first").type)
        columns.append(pc.if_else(known, as_time, pa.scalar(None, as_time.type)))
    columns.append(merged.column("count"))
    history = pa.table(columns, schema=IDENTITY_SCHEMA)
    return history.sort_by([("mmsi", "ascending"), ("first", "ascending")])
