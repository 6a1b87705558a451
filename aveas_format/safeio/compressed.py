"""Compressed files (``.gz``, ``.zst``, told by the name): read through their decompressor in
bounded memory and to a bounded size (a decompression bomb stops at the limit, a damaged stream
is a :class:`~aveas_format.errors.FormatError` naming the file), and written as a stream.

The OpenLABEL import reads ``.json.gz`` / ``.json.zst`` through :func:`open_file` (nothing is
unpacked to disk) and its export writes them through :func:`compressed`.
"""

from __future__ import annotations

from pathlib import Path

from aveas_format.errors import FormatError, RecordingIOError, require
from aveas_format.safeio.readers import MAX_STREAMED_JSON_BYTES

#: name suffix -> decompressor
COMPRESSED = {".gz": "gzip", ".zst": "zstandard"}
#: compression levels of the written streams: fast, most of the size gain (docs/performance.md)
GZIP_LEVEL, ZSTD_LEVEL = 3, 1


def compression(path: Path) -> str | None:
    """``"gzip"`` / ``"zstandard"`` for a ``.json.gz`` / ``.json.zst`` file (by its name), else None."""
    return COMPRESSED.get(Path(path).suffix.lower())


class Decompressed:
    """A file read through its decompressor, at most ``MAX_STREAMED_JSON_BYTES`` of it (beyond: a
    :class:`FormatError`), seekable as the JSON readers need it: forward by reading on, backward
    by starting over."""

    def __init__(self, path: Path, kind: str) -> None:
        self.path, self.kind = path, kind
        self.raw = self.f = None
        self._open()

    def _open(self) -> None:
        self.close()
        self.raw = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        if self.kind == "gzip":
            import gzip

            self.f = gzip.GzipFile(fileobj=self.raw, mode="rb")
        else:
            zstandard = require("zstandard", extra="zstd", what="reading .json.zst")
            self.f = zstandard.ZstdDecompressor().stream_reader(self.raw, read_across_frames=True)
        self.pos = 0

    def read(self, n: int = -1) -> bytes:
        try:
            data = self.f.read(n) if n is not None and n >= 0 else self.f.read()
        except (OSError, EOFError, ValueError) as e:  # gzip.BadGzipFile, zstd.ZstdError, truncated
            raise FormatError(f"cannot decompress ({self.kind}): {e}", path=self.path) from None
        self.pos += len(data)
        if self.pos > MAX_STREAMED_JSON_BYTES:  # (a decompression bomb: the plain file's limit)
            raise FormatError(f"JSON of more than {MAX_STREAMED_JSON_BYTES:,} bytes once decompressed "
                              "exceeds the limit", path=self.path)
        return data

    def seek(self, pos: int, whence: int = 0) -> int:
        if whence != 0:
            raise ValueError("only absolute seeks")
        if pos < self.pos:
            self._open()
        while self.pos < pos:
            if not self.read(min(1 << 20, pos - self.pos)):
                break
        return self.pos

    def tell(self) -> int:
        return self.pos

    def close(self) -> None:
        for f in (self.f, self.raw):
            if f is not None:
                f.close()

    def __enter__(self) -> Decompressed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_file(path: Path):
    """The file for reading (decompressed where its name says it is compressed)."""
    kind = compression(path)
    try:
        return Decompressed(Path(path), kind) if kind else open(path, "rb")  # noqa: SIM115
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None


def compressed(chunks, kind: str):
    """The chunks compressed as a stream: one gzip member / one zstd frame (``kind`` as
    :func:`compression` says)."""
    if kind == "gzip":
        import zlib

        c = zlib.compressobj(GZIP_LEVEL, zlib.DEFLATED, 31)  # 31: the gzip container
    else:
        zstandard = require("zstandard", extra="zstd", what="writing .zst")
        c = zstandard.ZstdCompressor(level=ZSTD_LEVEL).compressobj()
    for data in chunks:
        out = c.compress(data)
        if out:
            yield out
    yield c.flush()
