"""Hardened readers for untrusted input: one XML parser factory, bounded JSON (whole and streamed),
ZIP member checks.

Recordings and source files arrive from many partners and ``validate`` runs on submissions nobody
has looked at yet (docs/security.md). Every reader of the package parses XML through
:func:`xml_parser` / :func:`iterparse` (no DTD loading, no external entities, no network, libxml2's
default limits against entity-expansion bombs and huge trees), JSON through :func:`load_json`
(size and nesting limits) and ZIP archives through :func:`check_zip_member` (no absolute or ``..``
names, bounded decompressed size and ratio).
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path, PurePosixPath
from typing import IO, Any

from lxml import etree

from aveas_format.errors import FormatError, RecordingIOError

#: recording.json and other metadata files
MAX_JSON_BYTES = 64 * 1024 * 1024
#: OpenLABEL and other bulk JSON inputs read whole
MAX_BULK_JSON_BYTES = 4 * 1024 * 1024 * 1024
#: bulk JSON read as a stream (OpenLABEL frames: memory grows with the states kept, not with the
#: text; an hour of a busy highway is ~10 GB, ~0.7 bytes of memory per byte of it)
MAX_STREAMED_JSON_BYTES = 32 * 1024 * 1024 * 1024
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


def xml_source(source: Any, what: str = "map") -> tuple[bytes, str | None]:
    """The bytes of an XML document given as a path, bytes or XML text, and its path for messages
    (None unless read from a file); a missing or unreadable file is a :class:`RecordingIOError`
    naming it (``what`` in the message: ``map file not found``)."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source), None
    if isinstance(source, str) and source.lstrip().startswith("<"):
        return source.encode("utf-8"), None
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        try:
            return path.read_bytes(), str(path)
        except FileNotFoundError:
            raise RecordingIOError(f"{what} file not found", path=path) from None
        except OSError as e:
            raise RecordingIOError(f"cannot read {what}: {e.strerror or e}", path=path) from None
    raise TypeError(f"expected a path, bytes or XML text, not {type(source).__name__}")


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


def scan_json_member(f: IO[bytes], key: str, member: str, *, chunk: int = 1024 * 1024,
                     until_member: bool = False) -> tuple[int, tuple[int, int | None] | None, bool]:
    """A vectorised structural pass over the JSON text in the binary file ``f`` (read from its
    start in chunks; meant for text that a streaming parser checks anyway): returns
    ``(depth, span, ok)``. ``depth`` is the deepest nesting of containers, ``span`` the byte range
    ``[start, end)`` of the object value of ``doc[key][member]`` (None where there is none) and
    ``ok`` False where the structure is not as expected (unbalanced brackets or strings, ``key`` or
    ``member`` appearing twice): then use another reader. Memory: a few arrays of one chunk.
    ``until_member``: stop at the chunk where the member's value starts (``span`` is then
    ``(start, None)``, ``depth`` and ``ok`` are of the bytes scanned so far): a reader that
    verifies the member's value itself scans the rest (the OpenLABEL import's frames)."""
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
        if until_member and mem_val is not None and mem_end is None:
            f.seek(0)
            return maxd, (mem_val, None), found_key == 1 and found_mem == 1
    f.seek(0)
    if depth != 0 or parity or found_key > 1 or found_mem > 1:
        return maxd, None, False
    if mem_val is not None and (mem_end is None or key_end is None or mem_end > key_end):
        return maxd, None, False
    span = (mem_val, mem_end) if mem_val is not None else None
    return maxd, span, True
