"""Conversion: one record batch of source columns (any layout, as the source typed them) into the
canonical frame the later stages read (`PARTITION_SCHEMA`), with a rejection code per row for
values that are blank, not numbers, not MMSIs or not times, so one bad value costs one counted
row, not the file. The optional heading and navigational status reject nothing: a value that is
none becomes NaN or null."""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from aisdati.errors import UserError
from aisdati.preprocess.layouts import normalise_name
from aisdati.preprocess.report import CODE

MAX_MMSI_DIGITS = 18
"""MMSIs are nine digits by the standard, but real files hold longer ones (e.g. 1072211352), so
any positive integer of at most this many digits is a vessel, kept exactly as written: MMSIs are
read as integers, never through float64, which would merge 9007199254740992 and ...993 into one
vessel. Longer ones (no int64 holds 20 digits), zero, negatives, fractions and exponent notation
(`3.67E+08`, which a spreadsheet writes after dropping digits) are `bad_mmsi`."""
MAX_MMSI = 10**MAX_MMSI_DIGITS - 1
MMSI_TEXT = rf"^\+?0*(?P<digits>[0-9]{{1,{MAX_MMSI_DIGITS}}})(?:\.0*)?$"
"""An MMSI written as text: digits, perhaps with the `.0` of an export that wrote it as a float."""

PARTITION_SCHEMA = pa.schema(
    [
        ("mmsi", pa.int64()),
        ("time", pa.timestamp("us", tz="UTC")),
        ("lon", pa.float64()),
        ("lat", pa.float64()),
        ("sog", pa.float64()),
        ("cog", pa.float64()),
        ("heading", pa.float32()),
        ("status", pa.int16()),
        ("src", pa.int32()),
    ]
)
"""Rows between the stages: canonical names and types; NaN SOG/COG means 'derive it'; heading
and status as in points.parquet (`aisdati.tracks.schema.POINTS_SCHEMA`)."""
ROW_NUMBERS = ("lat", "lon", "sog", "cog")
"""The number columns a row needs (where the file has them): blank or bad, the row is rejected."""
HEADING_RANGE = (0.0, 360.0)
"""A heading is in [0, 360) degrees; anything else (AIS's 511: not available) is none."""
STATUS_RANGE = (0, 14)
"""Navigational status codes (ITU-R M.1371); 15 is 'not defined', read as none."""
STATUS_NAMES = {
    normalise_name(text): code
    for code, texts in {
        0: ("Under way using engine", "Underway using engine"),
        1: ("At anchor",),
        2: ("Not under command",),
        3: (
            "Restricted maneuverability",
            "Restricted manoeuvrability",
            "Restricted manoeuverability",
        ),
        4: ("Constrained by her draught", "Constrained by draught"),
        5: ("Moored",),
        6: ("Aground",),
        7: ("Engaged in fishing",),
        8: ("Under way sailing", "Underway sailing"),
        9: ("Reserved for future amendment [HSC]",),
        10: ("Reserved for future amendment [WIG]",),
        11: ("Power-driven vessel towing astern",),
        12: ("Power-driven vessel pushing ahead or towing alongside",),
        14: ("AIS-SART", "AIS-SART is active", "AIS-SART (active)"),
    }.items()
    for text in texts
}
"""The status names the Danish Maritime Authority writes (`Navigational status`), by their
normalised spelling (`layouts.normalise_name`). 'Unknown value', 'Not defined' and 'Reserved for
future use' (which of 11-13?) are none."""


def _to_float(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Values as float64 (NaN for blanks and for what is no number) and a mask of the values that
    are no finite number: unparsable text, or infinite (`inf`, `-Infinity`, `1e400`). A value
    written as NaN (any spelling, or a float NaN) comes back as NaN but unmasked: to_canonical
    counts it as a missing value, which is what pandas means by it."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        try:
            values = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False)
        except pa.ArrowInvalid:  # a bad value somewhere in this batch: per value, slower
            text = pd.Series(arr.to_pandas(), dtype=object).str.strip()
            values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64)
            unparsed = np.isnan(values) & ~_null_mask(arr)
            written_nan = text[unparsed].str.lower().str.lstrip("+-") == "nan"
            unparsed[np.flatnonzero(unparsed)[written_nan.to_numpy(dtype=bool)]] = False
            return values, unparsed | np.isinf(values)
    else:
        values = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False)
    return values, np.isinf(values)


def _to_mmsi(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """MMSIs as int64 (0 where there is none) and a mask of the non-null values that are no MMSI
    (see `MAX_MMSI_DIGITS`)."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    if pa.types.is_decimal(arr.type):
        arr = pc.cast(arr, pa.string())
    nulls = _null_mask(arr)
    if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        values = _text_mmsi(arr)
    else:
        values = arr.to_numpy(zero_copy_only=False)
    if values.dtype.kind not in "iu":  # a float column: integral values only
        values = np.where(values == np.floor(values), values, 0)
    with np.errstate(invalid="ignore"):
        ok = (values >= 1) & (values <= MAX_MMSI)
    return np.where(ok, values, 0).astype(np.int64), ~ok & ~nulls


TIME_RANGE_US = (
    int(pd.Timestamp("1990-01-01", tz="UTC").value // 1000),
    int(pd.Timestamp("2100-01-01", tz="UTC").value // 1000),
)
"""Times outside [1990, 2100) are no AIS reports (AIS began in the 2000s): a time column read in
the wrong unit lands in 1970 or far in the future, and is rejected row by row as bad_time."""
EPOCH_DIGITS = r"^[0-9]{9,15}$"
"""Epoch seconds or milliseconds (any time since 1973) written as text, each exactly a float."""
EPOCH_UNITS = ((1e11, 1_000_000, 1), (1e14, 1_000, 1), (1e17, 1, 1), (math.inf, 1, 1_000))
"""Numeric times are seconds, milliseconds, microseconds or nanoseconds since 1970, told apart by
their size (|t| below 1e11, 1e14, 1e17 or more: any time from 1973 to 5138 in each unit):
(bound, multiplier, divisor) to microseconds."""


def time_us(arr: pa.Array, time_format: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Microseconds since the epoch (UTC; times without a zone are UTC, as MarineCadastre's are)
    and a mask of the values that are not times: unparsable, or outside `TIME_RANGE_US`.
    Timestamps keep their unit; numbers (a parquet column of epoch seconds, or such strings in a
    CSV) are read in the unit their size gives (`EPOCH_UNITS`); text is ISO 8601 or such numbers,
    or, with `time_format` (a layout's `strptime` format), that format only."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    nulls = _null_mask(arr)
    if pa.types.is_timestamp(arr.type):
        values = arr.cast(pa.timestamp("us", tz=arr.type.tz))
        out = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        bad = np.zeros(len(arr), dtype=bool)
    elif pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type):
        out, bad = _epoch_us(arr.to_numpy(zero_copy_only=False))
    elif (pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type)) and time_format:
        out, bad = _formatted_time_us(arr, time_format)
    elif pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        out, bad = _text_time_us(arr)
    else:
        try:
            values = pc.cast(arr, pa.timestamp("us"))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            raise UserError(
                f"the time column holds {arr.type} values: expected times, text or numbers"
            ) from None
        out = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        bad = np.zeros(len(arr), dtype=bool)
    out = np.asarray(out, dtype=np.int64)
    bad = (bad | (out < TIME_RANGE_US[0]) | (out >= TIME_RANGE_US[1])) & ~nulls
    return out, bad


def _epoch_us(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Epoch numbers (any unit, see `EPOCH_UNITS`) as microseconds, and a mask of non-numbers."""
    out = np.zeros(len(values), dtype=np.int64)
    if values.dtype.kind in "iu":
        ints = values.astype(np.int64)
        size = np.abs(ints.astype(np.float64))
        low = 0.0
        for bound, mul, div in EPOCH_UNITS:
            sel = (size >= low) & (size < bound)
            with np.errstate(over="ignore"):
                out[sel] = ints[sel] * mul // div
            low = bound
        return out, np.zeros(len(values), dtype=bool)
    floats = values.astype(np.float64)
    bad = ~np.isfinite(floats)
    size = np.abs(np.where(bad, 0.0, floats))
    scale = np.ones(len(floats))
    low = 0.0
    for bound, mul, div in EPOCH_UNITS:
        scale[(size >= low) & (size < bound)] = mul / div
        low = bound
    scaled = np.round(np.where(bad, 0.0, floats) * scale)
    bad |= ~(np.abs(scaled) < TIME_RANGE_US[1])  # a 60-digit time: no int64, and no AIS report
    out[~bad] = scaled[~bad].astype(np.int64)
    return out, bad


def _text_time_us(arr: pa.Array) -> tuple[np.ndarray, np.ndarray]:
    """Times written as text: ISO 8601 (fast path in Arrow, else pandas), or epoch numbers.
    Text of 9-15 digits alone is no ISO 8601 time (pandas reads none of it as one): where every
    value is such, as receivers' tag blocks write times, it is read as numbers at once."""
    if arr.null_count == 0 and pc.all(pc.match_substring_regex(arr, EPOCH_DIGITS)).as_py():
        return _epoch_us(pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False))
    for kind in (pa.timestamp("us"), pa.timestamp("us", tz="UTC")):
        try:
            values = pc.cast(arr, kind)
        except pa.ArrowInvalid:
            continue
        ints = pc.fill_null(values.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
        return ints, np.zeros(len(arr), dtype=bool)
    text = arr.to_pandas()
    parsed = pd.to_datetime(text, errors="coerce", utc=True, format="ISO8601").dt.as_unit("us")
    out = parsed.to_numpy(dtype="datetime64[us]").view(np.int64).copy()
    bad = parsed.isna().to_numpy() & ~_null_mask(arr)
    if bad.any():  # numbers: epoch seconds (or ms, us, ns) written as text
        numbers = pd.to_numeric(text[bad], errors="coerce").to_numpy(dtype=np.float64)
        epoch, not_number = _epoch_us(numbers)
        idx = np.flatnonzero(bad)
        out[idx[~not_number]] = epoch[~not_number]
        bad[idx[~not_number]] = False
    return out, bad


def _formatted_time_us(arr: pa.Array, time_format: str) -> tuple[np.ndarray, np.ndarray]:
    """Times written as text in one `strptime` format (e.g. the DMA's `%d/%m/%Y %H:%M:%S`)."""
    parsed = pc.strptime(arr, format=time_format, unit="us", error_is_null=True)
    out = pc.fill_null(parsed.view(pa.int64()), 0).to_numpy(zero_copy_only=False)
    return out, _null_mask(parsed) & ~_null_mask(arr)


def _text_mmsi(arr: pa.Array) -> np.ndarray:
    """MMSIs written as text, as int64 (0 where the text is none, see `MMSI_TEXT`): Arrow's
    integer parser when every value is plain digits (the usual case; it also reads `0x` hex,
    which no MMSI is), else the pattern, about 25 times slower."""
    if not pc.any(pc.starts_with(arr, "0x", ignore_case=True)).as_py():
        try:
            return pc.fill_null(pc.cast(arr, pa.int64()), 0).to_numpy(zero_copy_only=False)
        except pa.ArrowInvalid:
            pass
    match = pc.extract_regex(pc.utf8_trim_whitespace(arr), MMSI_TEXT)
    digits = pc.if_else(pc.is_valid(match), match.field("digits"), "0")
    return pc.cast(digits, pa.int64()).to_numpy(zero_copy_only=False)


def is_time_type(kind: pa.DataType) -> bool:
    """Whether a typed (parquet) column can hold times: timestamps, dates, numbers or text."""
    return (
        pa.types.is_timestamp(kind)
        or pa.types.is_date(kind)
        or pa.types.is_integer(kind)
        or pa.types.is_floating(kind)
        or pa.types.is_string(kind)
        or pa.types.is_large_string(kind)
        or pa.types.is_dictionary(kind)
    )


def _null_mask(arr: pa.Array) -> np.ndarray:
    """Whether each value is null; an array without nulls (every fast-path block) is answered
    from its count: unpacking its validity bits took 90 % of `to_canonical`'s time."""
    if arr.null_count == 0:
        return np.zeros(len(arr), dtype=bool)
    return arr.is_null().to_numpy(zero_copy_only=False)


def heading_of(arr: pa.Array) -> np.ndarray:
    """Headings as float32 degrees, NaN where there is none (511, blank, no number, outside
    `HEADING_RANGE`)."""
    values, _ = _to_float(arr)
    with np.errstate(invalid="ignore"):
        ok = (values >= HEADING_RANGE[0]) & (values < HEADING_RANGE[1])
    return np.where(ok, values, np.nan).astype(np.float32)


def status_of(arr: pa.Array) -> pa.Array:
    """Navigational status codes as int16, null where there is none: a number outside
    `STATUS_RANGE` or not whole, or text that is neither such a number nor a name of
    `STATUS_NAMES`."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary_decode()
    if pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type):
        encoded = pc.dictionary_encode(arr)  # a file holds a few distinct texts: each read once
        known = np.array([_status_text(t) for t in encoded.dictionary.to_pylist()], np.float64)
        index = pc.fill_null(encoded.indices, -1).to_numpy(zero_copy_only=False)
        values = np.where(index >= 0, np.r_[known, np.nan][index], np.nan)
    else:
        values = pc.cast(arr, pa.float64()).to_numpy(zero_copy_only=False)
    with np.errstate(invalid="ignore"):
        ok = (values == np.floor(values)) & (values >= STATUS_RANGE[0])
        ok &= values <= STATUS_RANGE[1]
    return pa.array(np.where(ok, values, 0).astype(np.int16), mask=~ok)


def _status_text(text: str) -> float:
    """One status text's code (NaN: none), as `status_of` reads it."""
    try:
        return float(text)
    except ValueError:
        return float(STATUS_NAMES.get(normalise_name(text), np.nan))


def _optional(batch: pa.RecordBatch, columns: dict[str, str], key: str) -> pa.Array | None:
    """The batch's column of an optional canonical column, None where the file (or this stretch
    of it) has none."""
    name = columns.get(key)
    return batch.column(name) if name in batch.schema.names else None


def to_canonical(
    batch: pa.RecordBatch, columns: dict[str, str], src: int, time_format: str | None = None
) -> tuple[pa.Table, np.ndarray]:
    """Convert one batch to `PARTITION_SCHEMA`, with a rejection code per row for blanks,
    non-numbers, bad MMSIs and unparsable times (0 where the row is fine); the optional heading
    and status reject nothing. `columns` maps canonical names to the batch's
    (`resolve_columns`; the vessel's own columns are not read here); `time_format` is the
    layout's."""
    n = batch.num_rows
    codes = np.zeros(n, dtype=np.uint8)
    needed = ("mmsi", "time", *ROW_NUMBERS)
    raw = {key: batch.column(columns[key]) for key in needed if key in columns}
    missing = np.zeros(n, dtype=bool)
    for arr in raw.values():
        missing |= _null_mask(arr)
    numbers, bad_number = {}, np.zeros(n, dtype=bool)
    for key in ROW_NUMBERS:
        if key in raw:
            numbers[key], bad = _to_float(raw[key])
            bad_number |= bad
            missing |= np.isnan(numbers[key]) & ~bad  # written as NaN
        else:
            numbers[key] = np.full(n, np.nan)
    mmsi, bad_mmsi = _to_mmsi(raw["mmsi"])
    times, bad_time = time_us(raw["time"], time_format)
    for mask, reason in (
        (missing, "missing_value"),
        (bad_number, "bad_number"),
        (bad_mmsi, "bad_mmsi"),
        (bad_time, "bad_time"),
    ):
        codes[(codes == 0) & mask] = CODE[reason]
    heading, status = _optional(batch, columns, "heading"), _optional(batch, columns, "status")
    table = pa.table(
        [
            mmsi,
            pa.array(times, pa.int64()).view(pa.timestamp("us", tz="UTC")),
            numbers["lon"],
            numbers["lat"],
            numbers["sog"],
            numbers["cog"],
            np.full(n, np.nan, np.float32) if heading is None else heading_of(heading),
            pa.nulls(n, pa.int16()) if status is None else status_of(status),
            np.full(n, src, dtype=np.int32),
        ],
        schema=PARTITION_SCHEMA,
    )
    return table, codes


def canonical_tables(
    batches: Iterable[pa.RecordBatch], columns: dict[str, str], src: int, time_format: str | None
) -> Iterator[tuple[pa.Table, np.ndarray]]:
    """`to_canonical` of each batch: the rows of a reader that has no faster way."""
    for batch in batches:
        yield to_canonical(batch, columns, src, time_format)
