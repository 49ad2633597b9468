"""Byte streams of an input, read forwards only: decompressed when the file is, and counting the
bytes taken from disk so that progress bars can show how far a read has come.

Gzip is inflated by ISA-L (`isal`): 0.49 s for the 219 MB of CSV of the speed benchmark,
against 1.14 s for pyarrow's zlib, where reading a gzipped CSV is otherwise bound by the
inflate.
"""

from __future__ import annotations

import codecs
import zipfile
import zlib
from typing import BinaryIO

import pyarrow as pa
import zstandard
from isal import igzip, isal_zlib

READ_ERRORS = (
    zipfile.BadZipFile,
    EOFError,
    OSError,
    zlib.error,
    zstandard.ZstdError,
    pa.ArrowException,
    isal_zlib.error,
)
"""What a corrupt or truncated file raises while it is being read (bad CRC, truncated stream)."""


class ForwardOnly:
    """What pyarrow asks of a file-like object that can only be read forwards."""

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return False


class CountingReader(ForwardOnly):
    """A read-only file wrapper that counts the bytes read, for the progress bars."""

    def __init__(self, raw: BinaryIO) -> None:
        self.raw = raw
        self.bytes_read = 0
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        data = self.raw.read(n)
        self.bytes_read += len(data)
        return data

    def readinto(self, buffer: bytearray | memoryview) -> int:
        """What ISA-L's gzip reader and the line guard ask of a file: straight into `buffer`
        where the file can, else a read and a copy."""
        if hasattr(self.raw, "readinto"):
            size = self.raw.readinto(buffer)
            self.bytes_read += size
            return size
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def close(self) -> None:
        self.closed = True
        self.raw.close()


class Decompressed(ForwardOnly):
    """A decompressing stream (pyarrow's, or ISA-L's gzip) that still reports the compressed
    bytes read to its counter."""

    def __init__(self, stream: pa.NativeFile | BinaryIO, counter: CountingReader) -> None:
        self.stream = stream
        self.counter = counter
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        return self.stream.read(None if n is None or n < 0 else n)

    def readinto(self, buffer: bytearray | memoryview) -> int:
        return self.stream.readinto(buffer)

    def close(self) -> None:
        self.closed = True
        self.stream.close()
        self.counter.close()


ByteStream = CountingReader | Decompressed


def counted_stream(raw: BinaryIO, compression: str | None) -> tuple[ByteStream, CountingReader]:
    """`raw` decompressed (`compression` is pyarrow's name: gzip, zstd, or None), and the counter
    of the bytes read from `raw` itself."""
    counter = CountingReader(raw)
    if compression == "gzip":
        return Decompressed(igzip.IGzipFile(fileobj=counter, mode="rb"), counter), counter
    if compression:
        native = pa.PythonFile(counter, mode="r")
        return Decompressed(pa.CompressedInputStream(native, compression), counter), counter
    return counter, counter


BOMS = (
    (codecs.BOM_UTF32_LE, "utf-32"),
    (codecs.BOM_UTF32_BE, "utf-32"),
    (codecs.BOM_UTF16_LE, "utf-16"),
    (codecs.BOM_UTF16_BE, "utf-16"),
)
"""Byte-order marks of the wide encodings (UTF-32 LE first: it begins with UTF-16 LE's)."""


def bom_encoding(start: bytes) -> str | None:
    """The wide encoding whose byte-order mark `start` begins with, or None (UTF-8)."""
    return next((name for bom, name in BOMS if start.startswith(bom)), None)


def looks_like_utf16(start: bytes) -> bool:
    """Whether text without a byte-order mark is UTF-16: ASCII written that way has a NUL in
    every other byte."""
    sample = start[:4096]
    even, odd = sample[0::2].count(0), sample[1::2].count(0)
    half = len(sample) // 2
    return len(sample) >= 16 and max(even, odd) > 0.9 * half and min(even, odd) < 0.1 * half


class Transcoded(ForwardOnly):
    """A UTF-16 or UTF-32 stream read as UTF-8 (malformed code units become U+FFFD)."""

    def __init__(self, stream: ByteStream, encoding: str) -> None:
        self.stream = stream
        self.decoder = codecs.getincrementaldecoder(encoding)(errors="replace")
        self.closed = False

    def read(self, n: int = -1) -> bytes:
        """Some UTF-8 bytes (perhaps more than `n`); empty only at the end."""
        while True:
            data = self.stream.read(n)
            text = self.decoder.decode(data, final=not data)
            if text or not data:
                return text.encode("utf-8")

    def close(self) -> None:
        self.closed = True
        self.stream.close()
