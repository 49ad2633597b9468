"""Class A position reports (types 1-3) that fill one tag-blocked sentence each, decoded many at
a time: the bulk of every receiver's feed. pyais decodes a message in some 60 us of Python; a
coast's feed at 10,000 vessels spent a third of the watch's time there. Here the lines of that
one common shape are picked by one pattern, their checksums and bit fields computed with numpy
for the whole batch, and every other line is left to pyais (`nmea.NmeaDecoder`).

Only lines that pyais would read the same way are taken: the shape below, with its tag block's
`c:` time as the only time, the sentence's checksum right, fill bits 0, 28 payload characters
(168 bits). The fields are pyais's: the same bits, the same conversions (speed and course in
tenths; latitude and longitude as pyais rounds them, `(10 v + 3) // 6 / 1e6`, bit for bit the
same as `round(v / 600000, 6)`), so that the rows are those pyais gives (a test compares them
on shipped and generated lines).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from aisdati.preprocess.convert import EPOCH_UNITS

SHAPE = re.compile(
    rb"\\(?:[abd-z]:[^,*\\]*,)*c:(\d{1,13})(?:,[abd-z]:[^,*\\]*)*\*[0-9A-Fa-f]{2}\\"
    rb"!([A-Z]{2}VD[MO],1,1,\d?,[AB12]?,([1-3][0-9:;<=>?@A-W`a-w]{27}),0)\*([0-9A-Fa-f]{2})"
)
"""`\\<tag block with one c: time>*hh\\!xxVDM,1,1,<seq>,<channel>,<28 characters of a type 1-3
report>,0*hh`, matched whole: groups are the time, the checksummed text, the payload and the
checksum. Tag fields other than `c` may be there (`s:` the source, ...), each once-lettered, as
pyais reads them."""

FIELDS = {
    "mmsi": (8, 30, False),
    "status": (38, 4, False),
    "speed": (50, 10, False),
    "lon": (61, 28, True),
    "lat": (89, 27, True),
    "course": (116, 12, False),
    "heading": (128, 9, False),
}
"""Each field used of a type 1-3 report: (first bit, bits, signed), as ITU-R M.1371 lays it."""
PAYLOAD_CHARS = 28
HEADING_NOT_AVAILABLE = 511


@dataclass(frozen=True)
class Positions:
    """The reports of the lines taken (`line`: their indices in the batch), in line order."""

    line: np.ndarray
    time: list[str]
    """As the tag block writes it (the rows' `BaseDateTime`, read later as any CSV's)."""
    time_us: np.ndarray
    """The same in microseconds since 1970, as `convert.EPOCH_UNITS` reads it (for spotting
    another receiver's copy before the rows are read)."""
    payload: list[bytes]
    mmsi: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    sog: np.ndarray
    cog: np.ndarray
    heading: np.ndarray
    """-1 where not available (511)."""
    status: np.ndarray


def decode(lines: list[bytes]) -> Positions:
    """The reports of the lines (stripped) of the one common shape with a right checksum."""
    taken, times, bodies, payloads, sums = [], [], [], [], []
    for k, line in enumerate(lines):
        match = SHAPE.fullmatch(line) if line.isascii() else None
        if match is not None:
            taken.append(k)
            times.append(match[1].decode())
            bodies.append(match[2])
            payloads.append(match[3])
            sums.append(match[4])
    said = np.array([int(s, 16) for s in sums], np.uint8)
    good = said == _checksums(bodies)
    keep = np.flatnonzero(good)
    payloads = [payloads[k] for k in keep]
    fields = _fields(payloads)
    heading = fields["heading"]
    return Positions(
        line=np.asarray(taken, np.int64)[keep],
        time=[times[k] for k in keep],
        time_us=_epoch_us(np.array([int(times[k]) for k in keep], np.int64)),
        payload=payloads,
        mmsi=fields["mmsi"],
        lat=(10 * fields["lat"] + 3) // 6 / 1e6,
        lon=(10 * fields["lon"] + 3) // 6 / 1e6,
        sog=fields["speed"] / 10.0,
        cog=fields["course"] / 10.0,
        heading=np.where(heading == HEADING_NOT_AVAILABLE, -1, heading),
        status=fields["status"],
    )


def _epoch_us(numbers: np.ndarray) -> np.ndarray:
    """Microseconds of whole seconds or milliseconds since 1970 (13 digits at most, so no
    other unit), told apart by size as `convert.EPOCH_UNITS` does, by the same float product."""
    seconds = numbers < EPOCH_UNITS[0][0]
    factor = np.where(seconds, EPOCH_UNITS[0][1] / EPOCH_UNITS[0][2], EPOCH_UNITS[1][1])
    return np.rint(numbers * factor).astype(np.int64)


def _checksums(bodies: list[bytes]) -> np.ndarray:
    """The XOR of each text's bytes (NMEA's checksum)."""
    if not bodies:
        return np.zeros(0, np.uint8)
    lengths = np.fromiter((len(b) for b in bodies), np.int64, len(bodies))
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    return np.bitwise_xor.reduceat(np.frombuffer(b"".join(bodies), np.uint8), starts)


def _fields(payloads: list[bytes]) -> dict[str, np.ndarray]:
    """`FIELDS` of each 28-character payload (AIS's six-bit armouring undone), as int64."""
    chars = np.frombuffer(b"".join(payloads), np.uint8).reshape(-1, PAYLOAD_CHARS)
    sixes = chars.astype(np.int64) - 48
    sixes -= 8 * (sixes > 40)
    bits = ((sixes[:, :, None] >> np.arange(5, -1, -1)) & 1).reshape(len(chars), 6 * PAYLOAD_CHARS)
    out = {}
    for name, (first, width, signed) in FIELDS.items():
        value = bits[:, first : first + width] @ (1 << np.arange(width - 1, -1, -1))
        if signed:
            value = np.where(value >= 1 << (width - 1), value - (1 << width), value)
        out[name] = value
    return out
