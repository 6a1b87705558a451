"""A bounded pre-scan of an MCAP file's record framing, before the mcap library (or betterosi)
reads it: every length is checked against the file and its record, chunk sizes and the total
decompressed size are bounded (docs/security.md)."""

from __future__ import annotations

import struct
from typing import Any

from aveas_format.errors import FormatError, RecordingIOError

# --- MCAP: a bounded pre-scan of the record framing, before the mcap library reads the file ---

#: no MCAP chunk may declare more uncompressed bytes than this (one chunk is decompressed at a time)
MAX_MCAP_CHUNK_BYTES = 512 * 1024 * 1024
#: the uncompressed sizes of all chunks together may not exceed this multiple of the file size ...
MAX_MCAP_RATIO = 1000
#: ... or, for small files, this many bytes
MAX_MCAP_UNCOMPRESSED_FLOOR = 64 * 1024 * 1024

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_MCAP_NAMES = {1: "Header", 2: "Footer", 3: "Schema", 4: "Channel", 5: "Message", 6: "Chunk",
               7: "MessageIndex", 8: "ChunkIndex", 9: "Attachment", 10: "AttachmentIndex",
               11: "Statistics", 12: "Metadata", 13: "MetadataIndex", 14: "SummaryOffset",
               15: "DataEnd"}
_LZ4_STEP = 1024 * 1024


class _Rec:
    """A cursor over one record's body ``[pos, end)`` of a memory-mapped MCAP file; every read is
    checked against the record's end, so no field can point outside its record."""

    __slots__ = ("m", "pos", "end", "start", "kind", "path")

    def __init__(self, m: Any, start: int, end: int, kind: str, path: object) -> None:
        self.m, self.start, self.pos, self.end = m, start, start + 9, end
        self.kind, self.path = kind, path

    def fail(self, what: str) -> None:
        raise FormatError(f"MCAP {self.kind} record: {what}", path=self.path, byte=self.start)

    def take(self, n: int, what: str) -> int:
        if n > self.end - self.pos:
            self.fail(f"{what} of {n:,} bytes at byte {self.pos} runs past the record's end "
                      f"({self.end - self.pos:,} bytes left)")
        p = self.pos
        self.pos += n
        return p

    def u(self, fmt: str, what: str) -> int:
        p = self.take(struct.calcsize(fmt), what)
        return struct.unpack_from(fmt, self.m, p)[0]

    def blob(self, fmt: str, what: str) -> tuple[int, int]:
        n = self.u(fmt, f"length of {what}")
        return self.take(n, what), n

    def string_map(self, what: str) -> None:
        start, n = self.blob("<I", what)
        sub = _Rec(self.m, 0, start + n, self.kind, self.path)
        sub.start, sub.pos = self.start, start
        while sub.pos < sub.end:
            sub.blob("<I", f"key of {what}")
            sub.blob("<I", f"value of {what}")


def _check_mcap_chunk(r: _Rec) -> tuple[int, int]:
    """Check a Chunk record; returns (uncompressed size, compressed size)."""
    r.take(16, "message times")
    usize = r.u("<Q", "uncompressed_size")
    r.take(4, "uncompressed_crc")
    cp, cn = r.blob("<I", "compression")
    if cn > 16:  # "", "zstd", "lz4"; the reader would copy a name of any length
        r.fail(f"compression name of {cn:,} bytes")
    comp = bytes(r.m[cp:cp + cn]).decode("utf-8", "replace")
    dp, dn = r.blob("<Q", "records")
    if usize > MAX_MCAP_CHUNK_BYTES:
        r.fail(f"declares {usize:,} uncompressed bytes (limit {MAX_MCAP_CHUNK_BYTES:,}); refused")
    data = memoryview(r.m)[dp:dp + dn]
    try:
        if comp == "zstd" and dn:
            import zstandard

            declared = zstandard.frame_content_size(data)
            if declared > usize:  # python-zstandard allocates the frame's content size as given
                r.fail(f"zstd frame declares {declared:,} bytes but the chunk {usize:,}; refused")
        elif comp == "lz4" and dn:
            import lz4.frame

            declared = lz4.frame.get_frame_info(data)["content_size"]
            if declared > usize:
                r.fail(f"lz4 frame declares {declared:,} bytes but the chunk {usize:,}; refused")
            if declared == 0:  # size unknown: lz4 grows its buffer; count the output in steps
                dec = lz4.frame.LZ4FrameDecompressor()
                total = len(dec.decompress(data, max_length=_LZ4_STEP) or b"")
                while total <= usize and not (dec.eof or dec.needs_input):
                    total += len(dec.decompress(b"", max_length=_LZ4_STEP) or b"")
                if total > usize:
                    r.fail(f"lz4 data decompresses to more than the declared {usize:,} bytes; "
                           f"refused")
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 - the decompressors raise various kinds
        r.fail(f"damaged {comp} data: {type(e).__name__}: {e}")
    finally:
        data.release()
    return usize, dn


def _check_mcap_record(r: _Rec) -> tuple[int, int]:
    """Check that every length field of a record the mcap reader parses stays inside the record."""
    op = r.m[r.start]
    if op == 1:  # Header
        r.blob("<I", "profile")
        r.blob("<I", "library")
    elif op == 2:
        r.take(20, "footer fields")
    elif op == 3:  # Schema
        r.take(2, "id")
        r.blob("<I", "name")
        r.blob("<I", "encoding")
        r.blob("<I", "data")
    elif op == 4:  # Channel
        r.take(4, "ids")
        r.blob("<I", "topic")
        r.blob("<I", "message_encoding")
        r.string_map("metadata")
    elif op == 5:
        r.take(22, "message header")
    elif op == 6:
        return _check_mcap_chunk(r)
    elif op == 7:  # MessageIndex
        r.take(2, "channel_id")
        r.blob("<I", "records")
    elif op == 8:  # ChunkIndex
        r.take(32, "chunk index fields")
        r.blob("<I", "message_index_offsets")
        r.take(8, "message_index_length")
        r.blob("<I", "compression")
        r.take(16, "sizes")
    elif op == 9:  # Attachment
        r.take(16, "times")
        r.blob("<I", "name")
        r.blob("<I", "media_type")
        r.blob("<Q", "data")
        r.take(4, "crc")
    elif op == 10:  # AttachmentIndex
        r.take(40, "attachment index fields")
        r.blob("<I", "name")
        r.blob("<I", "media_type")
    elif op == 11:  # Statistics
        r.take(42, "statistics fields")
        r.blob("<I", "channel_message_counts")
    elif op == 12:  # Metadata
        r.blob("<I", "name")
        r.string_map("metadata")
    elif op == 13:  # MetadataIndex
        r.take(16, "offset and length")
        r.blob("<I", "name")
    elif op == 14:
        r.take(17, "summary offset fields")
    elif op == 15:
        r.take(4, "data_section_crc")
    return 0, 0


def check_mcap(path: object) -> None:
    """Refuse an MCAP file whose framing could make the ``mcap`` reader allocate more than the file
    holds, before that reader sees it. One bounded pass over the record headers (opcode u8, length
    u64 after the 8-byte magic), seeking over the bodies: every record must fit in the file and
    every length-prefixed field in its record; a Chunk may declare at most
    :data:`MAX_MCAP_CHUNK_BYTES` uncompressed (and its zstd/lz4 frame no more than that), all
    chunks together at most :data:`MAX_MCAP_RATIO` times the file size (or
    :data:`MAX_MCAP_UNCOMPRESSED_FLOOR`); the Footer must close the file, and its summary offset
    and the summary's chunk/attachment/metadata indexes must point at records of the right kind.
    Errors are :class:`FormatError` naming the file and the byte offset."""
    import mmap
    from array import array
    from bisect import bisect_left

    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror}", path=path) from None
    with f:
        size = f.seek(0, 2)
        if size < 16 + 9 + 20:
            raise FormatError(f"not a readable MCAP file: {size} bytes is shorter than magic + "
                              f"footer + magic (truncated?)", path=path)
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
            if m[:8] != _MCAP_MAGIC:
                raise FormatError("not a readable MCAP file: no MCAP magic at byte 0", path=path)
            if m[size - 8:] != _MCAP_MAGIC:
                raise FormatError(f"no MCAP magic at the end (byte {size - 8}): the file is "
                                  f"truncated or not closed by its writer", path=path)
            end = size - 8
            footer_at = end - 29
            if m[footer_at] != 2 or struct.unpack_from("<Q", m, footer_at + 1)[0] != 20:
                raise FormatError(f"no MCAP Footer record at byte {footer_at} (truncated file?)",
                                  path=path)
            summary_start = struct.unpack_from("<Q", m, footer_at + 9)[0]
            if summary_start and not 8 <= summary_start <= footer_at:
                raise FormatError(f"MCAP footer's summary_start {summary_start} lies outside the "
                                  f"file's records", path=path, byte=footer_at)
            # where the Chunk, Attachment and Metadata records start
            offsets = {6: array("Q"), 9: array("Q"), 12: array("Q")}
            # the summary's index records: their offset, the target's opcode, the target offset
            idx_at, idx_op, idx_to = array("Q"), array("B"), array("Q")
            u32, u64 = struct.Struct("<I").unpack_from, struct.Struct("<Q").unpack_from
            total_u = 0
            summary_seen = summary_start == 0
            pos = 8
            head = struct.Struct("<BQ").unpack_from
            while True:
                if end - pos < 9:
                    raise FormatError(f"truncated MCAP record header ({end - pos} bytes left "
                                      f"before the end magic)", path=path, byte=pos)
                op, length = head(m, pos)
                if length > end - pos - 9:
                    kind = _MCAP_NAMES.get(op, f"opcode 0x{op:02x}")
                    raise FormatError(f"MCAP {kind} record declares {length:,} bytes but only "
                                      f"{end - pos - 9:,} remain before the end magic (truncated "
                                      f"or damaged file)", path=path, byte=pos)
                rec_end = pos + 9 + length
                if pos == summary_start:
                    summary_seen = True
                if op in offsets:
                    offsets[op].append(pos)
                if op == 7:  # MessageIndex, fast path: channel_id u16, records u32 + entries
                    if length >= 6 and 6 + u32(m, pos + 11)[0] <= length:
                        pos = rec_end
                        continue
                elif op == 8:  # ChunkIndex, fast path
                    b = pos + 9
                    if length >= 48:
                        q = 36 + u32(m, b + 32)[0]
                        if q + 12 <= length and q + 28 + u32(m, b + q + 8)[0] <= length:
                            idx_at.append(pos)
                            idx_op.append(6)
                            idx_to.append(u64(m, b + 16)[0])
                            pos = rec_end
                            continue
                elif op == 6 and length >= 40:  # uncompressed Chunk, fast path
                    b = pos + 9
                    usize, cn = u64(m, b + 16)[0], u32(m, b + 28)[0]
                    if (cn == 0 and usize <= MAX_MCAP_CHUNK_BYTES
                            and 40 + u64(m, b + 32)[0] <= length):
                        total_u += usize
                        pos = rec_end
                        continue
                if op != 5:  # Messages (most records of an unchunked file) have no inner lengths
                    r = _Rec(m, pos, rec_end, _MCAP_NAMES.get(op, f"opcode 0x{op:02x}"), path)
                    total_u += _check_mcap_record(r)[0]
                    if op in (8, 10, 13):
                        idx_at.append(pos)
                        idx_op.append(op - 2 if op == 8 else op - 1)
                        idx_to.append(u64(m, pos + 9 + (16 if op == 8 else 0))[0])
                elif length < 22:
                    raise FormatError(f"MCAP Message record of {length} bytes is shorter than its "
                                      f"22-byte header", path=path, byte=pos)
                if op == 2:
                    if pos != footer_at:
                        raise FormatError(f"MCAP Footer record at byte {pos}, expected at "
                                          f"{footer_at}", path=path, byte=pos)
                    break
                pos = rec_end
            if not summary_seen:
                raise FormatError(f"MCAP footer's summary_start {summary_start} is no record "
                                  f"boundary", path=path, byte=footer_at)
            limit = max(MAX_MCAP_RATIO * size, MAX_MCAP_UNCOMPRESSED_FLOOR)
            if total_u > limit:
                raise FormatError(f"MCAP chunks declare {total_u:,} uncompressed bytes, more than "
                                  f"{MAX_MCAP_RATIO}x the file size ({limit:,}); refused",
                                  path=path)
            for at, op, target in zip(idx_at, idx_op, idx_to):
                arr = offsets[op]
                i = bisect_left(arr, target)
                if i == len(arr) or arr[i] != target:
                    index = _MCAP_NAMES[op + 2 if op == 6 else op + 1]
                    raise FormatError(f"MCAP {index} points at byte {target}, where no "
                                      f"{_MCAP_NAMES[op]} record starts",
                                      path=path, byte=at)
