"""Hardened readers for untrusted input: one XML parser factory, bounded JSON, ZIP member checks.

Recordings and source files arrive from many partners and ``validate`` runs on submissions nobody
has looked at yet (docs/security.md). Every reader of the package parses XML through
:func:`xml_parser` / :func:`iterparse` (no DTD loading, no external entities, no network, libxml2's
default limits against entity-expansion bombs and huge trees), JSON through :func:`load_json`
(size and nesting limits) and ZIP archives through :func:`check_zip_member` (no absolute or ``..``
names, bounded decompressed size and ratio).
"""

from __future__ import annotations

import json
import struct
import zipfile
from pathlib import PurePosixPath
from typing import IO, Any

from lxml import etree

from aveas_format.errors import FormatError, RecordingIOError

#: recording.json and other metadata files
MAX_JSON_BYTES = 64 * 1024 * 1024
#: OpenLABEL and other bulk JSON inputs
MAX_BULK_JSON_BYTES = 4 * 1024 * 1024 * 1024
MAX_JSON_DEPTH = 64
#: a compressed ZIP member is decompressed into memory: at most this many bytes ...
MAX_ZIP_MEMBER_BYTES = 8 * 1024 * 1024 * 1024
#: ... and at most this ratio of decompressed to compressed size (zip bombs reach 1000:1 and more)
MAX_ZIP_RATIO = 200


def xml_parser(*, remove_comments: bool = True, **kw: Any) -> etree.XMLParser:
    """An lxml parser that never loads a DTD, resolves no entity, touches no network and keeps
    libxml2's limits (no ``huge_tree``): external-entity and entity-expansion attacks fail."""
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                           dtd_validation=False, huge_tree=False, remove_comments=remove_comments,
                           remove_pis=True, **kw)


def iterparse(source: str | IO[bytes], **kw: Any) -> etree.iterparse:
    """``lxml.etree.iterparse`` with the protections of :func:`xml_parser`."""
    kw.setdefault("remove_comments", True)
    return etree.iterparse(source, resolve_entities=False, no_network=True, load_dtd=False,
                           dtd_validation=False, huge_tree=False, remove_pis=True, **kw)


def _depth_ok(obj: Any, limit: int) -> bool:
    stack = [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if d > limit:
            return False
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return True


def load_json(data: bytes | str, *, path: object = None, max_bytes: int = MAX_JSON_BYTES,
              max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON with a size and a nesting limit; errors name the file and line/column."""
    size = len(data)
    if size > max_bytes:
        raise FormatError(f"JSON of {size:,} bytes exceeds the limit of {max_bytes:,}", path=path)
    try:
        obj = json.loads(data)
    except UnicodeDecodeError:
        raise FormatError("not UTF-8 text", path=path) from None
    except json.JSONDecodeError as e:
        raise FormatError(f"broken JSON: {e.msg}", path=path, line=e.lineno, column=e.colno) from None
    except RecursionError:
        raise FormatError(f"JSON nested deeper than {max_depth} levels", path=path) from None
    if not _depth_ok(obj, max_depth):
        raise FormatError(f"JSON nested deeper than {max_depth} levels", path=path)
    return obj


def check_zip_member(info: zipfile.ZipInfo, archive: object) -> None:
    """Refuse a member with an absolute or parent-relative name, or one that decompresses to more
    than :data:`MAX_ZIP_MEMBER_BYTES` or at a ratio above :data:`MAX_ZIP_RATIO`."""
    name = info.filename
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or (len(name) > 1 and name[1] == ":"):
        raise RecordingIOError(f"ZIP member {name!r} has an unsafe path; refused", path=archive)
    if info.compress_type != zipfile.ZIP_STORED:
        if info.file_size > MAX_ZIP_MEMBER_BYTES:
            raise RecordingIOError(f"ZIP member {name!r} decompresses to {info.file_size:,} bytes "
                                   f"(limit {MAX_ZIP_MEMBER_BYTES:,}); refused", path=archive)
        if info.file_size > 1024 * 1024 and info.file_size > MAX_ZIP_RATIO * max(info.compress_size, 1):
            raise RecordingIOError(f"ZIP member {name!r} has a compression ratio above "
                                   f"{MAX_ZIP_RATIO}:1 (a zip bomb?); refused", path=archive)


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


# --- streamed JSON (ijson): limits, error messages and a structural pre-scan ---

def check_json_size(path: object, *, max_bytes: int = MAX_BULK_JSON_BYTES) -> int:
    """The size of the file at ``path``; a :class:`FormatError` (as :func:`load_json` gives) where it
    exceeds ``max_bytes``, a :class:`RecordingIOError` where it cannot be read."""
    import os

    try:
        size = os.stat(path).st_size
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    if size > max_bytes:
        raise FormatError(f"JSON of {size:,} bytes exceeds the limit of {max_bytes:,}", path=path)
    return size


class CountingReader:
    """A binary reader that counts the bytes handed out (where a streaming parser has got to) and
    can splice a byte range out of the file, replacing it by other bytes."""

    def __init__(self, f: IO[bytes], skip: tuple[int, int, bytes] | None = None, *,
                 start: int = 0, stop: int | None = None) -> None:
        self.f, self.pos, self.skip, self.stop = f, start, skip, stop
        if start:
            f.seek(start)

    def read(self, n: int = -1) -> bytes:
        if n is None or n < 0:
            n = 1 << 62
        if self.stop is not None:
            n = max(0, min(n, self.stop - self.pos))
            if n == 0:
                return b""
        if self.skip is not None:
            start, end, repl = self.skip
            if self.pos < start:
                data = self.f.read(min(n, start - self.pos))
                self.pos += len(data)
                return data
            if self.pos == start:
                self.f.seek(end)
                self.pos = end
                self.skip = None
                return repl
        data = self.f.read(n)
        self.pos += len(data)
        return data


def stream_json_error(e: Exception, *, path: object, consumed: int | None = None) -> FormatError:
    """A :class:`FormatError` naming the file (and how far the parser had read) for an error of
    ``ijson`` (yajl's message names the problem and shows the text around it)."""
    arg = e.args[0] if e.args else ""
    msg = arg.decode("utf-8", "replace") if isinstance(arg, bytes) else str(e)
    lines = [ln.strip() for ln in msg.splitlines() if ln.strip()]
    if any("UTF8" in ln or "UTF-8" in ln for ln in lines[:1]):
        where = f" (in the bytes before byte {consumed:,})" if consumed else ""
        return FormatError(f"not UTF-8 text{where}", path=path)
    head = lines[0] if lines else type(e).__name__
    context = lines[1] if len(lines) > 1 and "(right here)" not in lines[1] else None
    text = f"broken JSON: {head.rstrip('.')}"
    if context:
        text += f", near {context[:80]!r}"
    if consumed is not None:
        text += f" (within the 64 KiB before byte {consumed:,})"
    return FormatError(text, path=path)


_WS = b" \t\r\n"


class _Peek:
    """Single bytes at any offset of a binary file, without moving its read position."""

    def __init__(self, f: IO[bytes]) -> None:
        self.f = f
        try:
            self.fd: int | None = f.fileno()
        except (AttributeError, OSError, ValueError):
            self.fd = None

    def get(self, n: int, pos: int) -> bytes:
        import os

        if self.fd is not None:
            return os.pread(self.fd, n, pos)
        here = self.f.tell()
        self.f.seek(pos)
        try:
            return self.f.read(n)
        finally:
            self.f.seek(here)

    def skip_ws(self, i: int) -> tuple[int, int | None]:
        """The first offset from ``i`` that is no JSON whitespace and its byte (None at the end)."""
        while True:
            data = self.get(64, i)
            if not data:
                return i, None
            for k, c in enumerate(data):
                if c not in _WS:
                    return i + k, c
            i += len(data)


def scan_json_member(f: IO[bytes], key: str, member: str, *, chunk: int = 1024 * 1024
                     ) -> tuple[int, tuple[int, int] | None, bool]:
    """A vectorised structural pass over the JSON text in the binary file ``f`` (read from its
    start in chunks; meant for text that a streaming parser checks anyway): returns
    ``(depth, span, ok)``. ``depth`` is the deepest nesting of containers, ``span`` the byte range
    ``[start, end)`` of the object value of ``doc[key][member]`` (None where there is none) and
    ``ok`` False where the structure is not as expected (unbalanced brackets or strings, ``key`` or
    ``member`` appearing twice): then use another reader. Memory: a few arrays of one chunk."""
    import numpy as np

    peek = _Peek(f)
    kpat = json.dumps(key).encode()
    mpat = json.dumps(member).encode()
    look = max(len(kpat), len(mpat))
    depth = maxd = parity = 0  # parity: 1 while inside a string
    key_val: int | None = None  # where the value of doc[key] starts, and its end
    key_end: int | None = None
    mem_val: int | None = None
    mem_end: int | None = None
    found_key = found_mem = 0
    off = 0
    f.seek(0)
    while True:
        buf = f.read(chunk)
        if not buf:
            break
        n = len(buf)

        def byte_at(j: int, buf: bytes = buf, off: int = off, n: int = n) -> int:
            return buf[j - off] if off <= j < off + n else peek.get(1, j)[0]

        a = np.frombuffer(buf, np.uint8)
        q = np.flatnonzero(a == 34)
        if len(q):
            esc = np.zeros(len(q), bool)
            prev = np.zeros(len(q), bool)
            pos = q > 0
            prev[pos] = a[q[pos] - 1] == 92
            if q[0] == 0 and off > 0:
                prev[0] = byte_at(off - 1) == 92
            for i in np.flatnonzero(prev):
                j = off + int(q[i]) - 1
                run = 0
                while j >= 0 and byte_at(j) == 92:
                    run += 1
                    j -= 1
                esc[i] = run % 2 == 1
            q = q[~esc]
        br = np.flatnonzero((a == 123) | (a == 125) | (a == 91) | (a == 93))
        inside = ((parity + np.searchsorted(q, br)) & 1).astype(bool)
        s = br[~inside]
        d = np.where((a[s] == 123) | (a[s] == 91), 1, -1)
        dep = depth + np.cumsum(d)
        if len(dep):
            if dep.min() < 0:
                return maxd, None, False
            maxd = max(maxd, int(dep.max()))
        # candidate keys starting in this chunk
        text = buf + peek.get(look, off + n)
        cands = []
        for pat, level in ((kpat, 1), (mpat, 2)):
            i = text.find(pat)
            while 0 <= i < n:
                cands.append((i, level, pat))
                i = text.find(pat, i + 1)
        for loc, level, pat in sorted(cands):
            k = int(np.searchsorted(q, loc))
            if k >= len(q) or q[k] != loc or (parity + k) & 1:
                continue  # not an opening quote outside a string
            b = int(np.searchsorted(s, loc))
            if (int(dep[b - 1]) if b else depth) != level:
                continue
            j, c = peek.skip_ws(off + loc + len(pat))
            if c != 58:  # ':' - else a string value, not a key
                continue
            j, c = peek.skip_ws(j + 1)
            p = off + loc
            if key_val is not None and key_end is None and key_val < p:  # closed before p?
                idx = np.flatnonzero((dep == 1) & (s > key_val - off) & (s < loc))
                if len(idx):
                    key_end = off + int(s[idx[0]]) + 1
            if level == 1:
                found_key += 1
                key_val = j if c == 123 else None
            elif key_val is not None and p > key_val and (key_end is None or p < key_end):
                found_mem += 1
                mem_val = j if c == 123 else None
        # where the values found so far end
        if key_val is not None and key_end is None and key_val < off + n:
            idx = np.flatnonzero((dep == 1) & (s > key_val - off))
            if len(idx):
                key_end = off + int(s[idx[0]]) + 1
        if mem_val is not None and mem_end is None and mem_val < off + n:
            idx = np.flatnonzero((dep == 2) & (s > mem_val - off))
            if len(idx):
                mem_end = off + int(s[idx[0]]) + 1
        if len(dep):
            depth = int(dep[-1])
        parity = (parity + len(q)) & 1
        off += n
    f.seek(0)
    if depth != 0 or parity or found_key > 1 or found_mem > 1:
        return maxd, None, False
    if mem_val is not None and (mem_end is None or key_end is None or mem_end > key_end):
        return maxd, None, False
    span = (mem_val, mem_end) if mem_val is not None else None
    return maxd, span, True
