"""Reading one zip member, deflated members inflated by ISA-L.

`zipfile` inflates with zlib: 1.25 s for the 219 MB member of the speed benchmark's zip, about
40 % of reading, checking and filtering it; ISA-L takes 0.50 s. So a deflated member (the
MarineCadastre zips) is read here from its raw bytes in the archive, inflated by ISA-L and its
CRC-32 checked at the end as `zipfile` checks it (a corrupt member fails the same way:
`zipfile.BadZipFile` or a decompression error, an `EOFError` when cut short). Other members
(stored, encrypted) are `zipfile`'s own streams.
"""

from __future__ import annotations

import struct
import zipfile
from pathlib import Path
from typing import BinaryIO

from aisdati.preprocess.streams import ForwardOnly, isal_zlib

CHUNK_BYTES = 1 << 20
"""Compressed bytes read from the archive at a time."""
LOCAL_HEADER = struct.Struct("<4s22xHH")
"""A local file header: its signature, then (after 22 bytes) the lengths of name and extra."""


def open_member(zf: zipfile.ZipFile, name: str) -> BinaryIO | InflatedMember:
    """The bytes of member `name`, forwards (ISA-L's inflate for a deflated one)."""
    info = zf.getinfo(name)
    if info.compress_type != zipfile.ZIP_DEFLATED or info.flag_bits & 0x1:
        return zf.open(info)
    return InflatedMember(Path(zf.filename), info)


class InflatedMember(ForwardOnly):
    """A deflated member's bytes, inflated by ISA-L from the archive file itself: `read(n)`
    gives `n` bytes until the end (no more than that held, whatever the compression ratio)."""

    def __init__(self, path: Path, info: zipfile.ZipInfo) -> None:
        self.info = info
        self.file = open(path, "rb")  # noqa: SIM115 - closed with the member
        self.closed = False
        self.file.seek(info.header_offset)
        header = self.file.read(LOCAL_HEADER.size)
        if len(header) < LOCAL_HEADER.size or not header.startswith(b"PK\x03\x04"):
            self.close()
            raise zipfile.BadZipFile(f"bad local file header of {info.filename!r}")
        _, name_len, extra_len = LOCAL_HEADER.unpack(header)
        self.file.seek(name_len + extra_len, 1)
        self.left = info.compress_size
        self.inflater = isal_zlib.decompressobj(-15)
        self.pending = b""
        self.crc = 0
        self.size = 0

    def read(self, n: int = -1) -> bytes:
        if n is None or n < 0:
            return b"".join(iter(lambda: self.read(CHUNK_BYTES), b""))
        return b"".join(self._inflate(n))

    def readinto(self, buffer: bytearray | memoryview) -> int:
        """`read` into `buffer`, each inflated piece copied once (the line guard reads a chunk
        after the start of a line it carries over)."""
        view, size = memoryview(buffer), 0
        for piece in self._inflate(len(view)):
            view[size : size + len(piece)] = piece
            size += len(piece)
        return size

    def _inflate(self, n: int) -> list[bytes]:
        """The next pieces of the member, `n` bytes of them in all until the end."""
        pieces, wanted = [], n
        while wanted > 0 and not self.inflater.eof:
            if not self.pending and self.left:
                self.pending = self.file.read(min(CHUNK_BYTES, self.left))
                if not self.pending:
                    raise EOFError(f"{self.info.filename!r} is cut short in the archive")
                self.left -= len(self.pending)
            data = self.inflater.decompress(self.pending, wanted)
            self.pending = self.inflater.unconsumed_tail
            if not (data or self.pending or self.left or self.inflater.eof):
                raise EOFError(f"{self.info.filename!r} ends before its last deflate block")
            pieces.append(data)
            wanted -= len(data)
            self.crc = isal_zlib.crc32(data, self.crc)
            self.size += len(data)
        if self.inflater.eof:
            self._check()
        return pieces

    def _check(self) -> None:
        """What `zipfile` checks at a member's end: its size and CRC-32."""
        if self.size != self.info.file_size or self.crc != self.info.CRC:
            raise zipfile.BadZipFile(f"Bad CRC-32 for file {self.info.filename!r}")

    def close(self) -> None:
        self.closed = True
        self.file.close()
