"""Reading an OpenLABEL file for the import: streamed with ijson, bounded by :mod:`aveas_format.safeio`.

:func:`_stream_doc` reads everything under ``openlabel`` except the frames whole and hands the
frames out one at a time (a file of millions of boxes never exists as one dict);
:func:`_load_doc` reads a file whole (``load_json`` with the same limits), the fallback for files
the structural pre-scan does not take and for files with Python's JSON extensions (``NaN``,
``Infinity``: :class:`_NotStrictJSON`); :func:`_check_stream` parses a whole file without building
anything, to report its JSON error where one exists.
"""

from __future__ import annotations

import io
import os
import re
from contextlib import closing
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.errors import FormatError, RecordingIOError

try:  # the fast path of the frames (extra ``fast``)
    import orjson
except ImportError:  # pragma: no cover - exercised by a test that hides it
    orjson = None
from aveas_format.safeio import (MAX_BULK_JSON_BYTES, MAX_JSON_DEPTH, MAX_STREAMED_JSON_BYTES, CountingReader,
                                 check_json_size, load_json, scan_json_member, stream_json_error)


#: the compact forms: name suffix -> (module, what to install)
COMPRESSED = {".gz": "gzip", ".zst": "zstandard"}


def compression(path: Path) -> str | None:
    """``"gzip"`` / ``"zstandard"`` for a ``.json.gz`` / ``.json.zst`` file (by its name), else None."""
    return COMPRESSED.get(Path(path).suffix.lower())


class _Decompressed:
    """A file read through its decompressor, seekable as the readers here need it: forward by
    reading on, backward by starting over (each pass over the frames reads the file once)."""

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
            try:
                import zstandard
            except ImportError:
                from aveas_format.errors import MissingDependencyError

                raise MissingDependencyError("reading .zst needs zstandard: pip install "
                                             "'aveas-format[zstd]'") from None
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

    def __enter__(self) -> _Decompressed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _open(path: Path):
    """The file for reading: decompressed where its name says it is compressed."""
    kind = compression(path)
    return _Decompressed(Path(path), kind) if kind else open(path, "rb")  # noqa: SIM115


def _load_doc(path: Path) -> dict[str, Any]:
    try:
        if compression(path):
            with _open(path) as f:  # (at most one byte over the limit: load_json refuses it)
                raw = f.read(MAX_BULK_JSON_BYTES + 1)
        else:
            check_json_size(path, max_bytes=MAX_BULK_JSON_BYTES)  # (before reading it whole)
            raw = path.read_bytes()
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    doc = load_json(raw, path=path, max_bytes=MAX_BULK_JSON_BYTES)
    if not isinstance(doc, dict) or not isinstance(doc.get("openlabel"), dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    return doc["openlabel"]


class _NotStrictJSON(Exception):
    """The file uses Python's JSON extensions (NaN, Infinity), which ``json.loads`` reads and the
    streaming parser refuses: read it whole instead (as before the import streamed)."""


def _stream_error(e: Exception, path: Path, consumed: int) -> Exception:
    arg = e.args[0] if e.args else ""
    msg = arg.decode("utf-8", "replace") if isinstance(arg, bytes) else str(arg)
    if "invalid char" in msg and re.search(r"NaN|Infinity", msg):
        return _NotStrictJSON()
    return stream_json_error(e, path=path, consumed=consumed)


def _check_stream(path: Path) -> None:
    """Parse the whole file without building anything: the file's JSON error, if it has one."""
    import ijson

    with _open(path) as f:
        r = CountingReader(f)
        try:
            for _ in ijson.basic_parse(r, use_float=True):
                pass
        except ijson.JSONError as e:
            raise _stream_error(e, path, r.pos) from None


def _open_checked(path: Path):
    """``(the file open for reading, whether its text starts with "{")``, its size checked first
    (the streamed reading's limit: a file read whole is held to :data:`MAX_BULK_JSON_BYTES`)."""
    check_json_size(path, max_bytes=MAX_STREAMED_JSON_BYTES)
    try:
        f = _open(path)
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    try:
        return f, f.read(4096).lstrip(b" \t\r\n").startswith(b"{")
    except BaseException:
        f.close()
        raise


class _Rescan(Exception):
    """The frames of a file read without the structural pre-scan (:func:`_stream_doc` with
    ``prescan=False``) are not as that path needs them (a block it cannot cut or parse, nesting
    near the limit, a member that repeats, broken JSON): read the file again with the pre-scan,
    which gives the exact result or error."""


def _stream_doc(path: Path, prescan: bool = True):
    """Open an OpenLABEL file for a streamed import: ``(ol, frames)`` with ``ol`` the object under
    ``openlabel`` without its frames (read whole: metadata, objects, coordinate systems, ...) and
    ``frames`` a function that yields ``(frame key, frame)`` one at a time in file order (ijson);
    ``frames`` is None where the file was read whole (no frames object, or a file the structural
    pre-scan does not take: then :func:`_load_doc`, the same limits and errors).

    The size limit is checked before reading; the nesting limit on the structural pre-scan
    (:func:`aveas_format.safeio.scan_json_member`, which also finds the byte range of the frames).
    Broken JSON and non-UTF-8 text give a :class:`FormatError` naming the file.

    ``prescan=False`` (needs orjson): no second pass over the frames' bytes — the structure is
    scanned up to where the frames start (:func:`_frames_without_prescan`); the frames' blocks
    verify their own (balanced, their depth, each parsed whole); the members after the frames are
    read when the frames are done (``ol`` is updated with them in place). Where that path cannot
    be sure, the frames raise :class:`_Rescan`: read the file again with ``prescan=True``."""
    import ijson

    if not prescan and orjson is not None:
        got = _frames_without_prescan(path)
        if got is not None:
            return got

    f, is_object = _open_checked(path)
    with f:
        if not is_object:  # empty, a BOM, UTF-16/32, not an object: read it whole
            return _load_doc(path), None
        depth, span, ok = scan_json_member(f, "openlabel", "frames")
    if not ok:  # broken (e.g. truncated: refused here in bounded memory) or a member repeats
        _check_stream(path)
    if not ok or depth == MAX_JSON_DEPTH:  # (at the limit: the exact check of load_json decides)
        return _load_doc(path), None
    if depth > MAX_JSON_DEPTH:
        raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=path)
    with _open(path) as f:
        r = CountingReader(f, (span[0], span[1], b"{}") if span else None)
        try:
            doc = dict(ijson.kvitems(r, "", use_float=True))
        except ijson.JSONError as e:
            raise _stream_error(e, path, r.pos) from None
    if not isinstance(doc.get("openlabel"), dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    ol = doc["openlabel"]
    if span is None:
        return ol, None

    def frames(columnar: bool = False, workers: int | None = 1, spill_to=None):
        start = span[0]
        if orjson is not None:
            start = yield from _fast_frames(path, span, columnar, workers, spill_to)
            if start is None:
                return
        with _open(path) as fr:
            rd = CountingReader(fr, start=start, stop=span[1])
            if start != span[0]:  # the rest of the frames after what the fast path took
                rd = _Prefixed(b"{", rd)
            try:
                yield from ijson.kvitems(rd, "", use_float=True)
            except ijson.JSONError as e:
                raise _stream_error(e, path, rd.pos) from None

    return ol, frames


def _frames_without_prescan(path: Path):
    """``(ol without the members after the frames, frames)`` as :func:`_stream_doc` gives them with
    ``prescan=False``, or None where the structure up to the frames does not allow it."""
    import ijson

    f, is_object = _open_checked(path)
    with f:
        if not is_object:
            return None
        depth, span, ok = scan_json_member(f, "openlabel", "frames", chunk=_HEAD_CHUNK, until_member=True)
        if not ok or span is None or span[1] is not None or depth >= MAX_JSON_DEPTH:
            return None  # (no frames, a small file scanned whole, a repeated member, broken, deep)
        start = span[0]
        ol: dict[str, Any] = {}
        r = _Suffixed(CountingReader(f, stop=start), b"{}}}")
        try:  # the members up to the frames (the document closed after the frames' "{}")
            for k, v in ijson.kvitems(r, "openlabel", use_float=True):
                ol[k] = v
        except ijson.JSONError:
            return None
        if "frames" not in ol or ol["frames"] != {}:
            return None

    def frames(columnar: bool = False, workers: int | None = 1, spill_to=None):
        from aveas_format.converters.openlabel.fastblock import block_depth

        generic = "objects" in ol
        tail: list[bytes] = []
        with _open(path) as f, _read_blocks(f, (start, None), columnar, workers, tail, spill_to) as blocks:
            f.seek(start + 1)
            for (_, cut), fast in blocks:
                if cut is None:  # no frame head in 4 blocks, no end of the frames
                    raise _Rescan
                if fast is not None:
                    depth = fast.depth
                elif not generic:  # (frames one at a time need the objects: after the frames here)
                    raise _Rescan
                else:
                    buf = b"{" + cut + b"}"
                    depth = block_depth(buf)
                    try:
                        fast = orjson.loads(buf) if depth is not None else None
                    except orjson.JSONDecodeError:
                        fast = None
                    if not isinstance(fast, dict):
                        raise _Rescan
                if depth + 2 >= MAX_JSON_DEPTH:  # (the frames are at depth 3: the exact check decides)
                    raise _Rescan
                if isinstance(fast, dict):
                    yield from fast.items()
                else:
                    yield COLUMNAR, fast
        after = _members_after_frames(tail[0])
        if {"metadata", "coordinate_systems"} & after.keys():  # (the import reads them first)
            raise _Rescan
        ol.update(after)

    return ol, frames


def _members_after_frames(tail: bytes) -> dict[str, Any]:
    """The members of ``openlabel`` after its frames from the bytes after the frames' closing
    brace (checked as the pre-scan checks the whole file: balanced, no repeated member, the
    nesting limit), or :class:`_Rescan`."""
    import io

    import ijson

    doc = b'{"openlabel":{"frames":{}' + tail
    depth, span, ok = scan_json_member(io.BytesIO(doc), "openlabel", "frames")
    if not ok or span is None or depth >= MAX_JSON_DEPTH:
        raise _Rescan
    try:
        got = dict(ijson.kvitems(io.BytesIO(doc), "", use_float=True))
    except ijson.JSONError:
        raise _Rescan from None
    out = dict(got.get("openlabel") or {})
    out.pop("frames", None)
    return out


#: bytes scanned at a time up to the frames (where the frames start in the first: the whole file)
_HEAD_CHUNK = 1 << 20
#: bytes of the frames parsed at a time by the fast path (their Python objects: ~9x that); by the
#: columnar path (:mod:`.fastblock`: Arrow columns, ~the bytes)
_BLOCK = 1 << 20
_COLUMNAR_BLOCK = 8 << 20
#: bytes before a block's end where a lazy cut looks for the last frame that starts in it
_CUT_WINDOW = 1 << 18
#: the key of a block of frames read into columns (:class:`.fastblock.FastBlock`) in ``frames()``
COLUMNAR = object()
_FRAME_HEAD = re.compile(rb'\s*"(?:[^"\\]|\\.)*"\s*:\s*\{\s*$')


def _fast_frames(path: Path, span: tuple[int, int], columnar: bool = False, workers: int | None = 1,
                 spill_to=None):
    """The frames cut into blocks of whole frames where a frame starts with ``"key":{
    "frame_properties"`` (this library's exports, and files laid out like them) and each block
    parsed with orjson; a generator returning None when it took all frames, else the file offset
    (at a frame boundary) from which the caller goes on with ijson — at the first block it cannot
    cut or parse (another layout, NaN, numbers orjson refuses: the exact error comes from ijson).
    ``columnar``: a block that :func:`.fastblock.read_block` takes is yielded whole as
    ``(COLUMNAR, FastBlock)`` (bigger blocks), read by ``workers`` processes (1: here; 0/None: one
    per core; :func:`aveas_format.parallel.map_ordered`: in file order, a few blocks in flight;
    ``spill_to``: :func:`_read_blocks`); the others as frames, parsed here."""
    if not columnar or span[1] - span[0] <= 2 * _COLUMNAR_BLOCK:  # (a small file: no processes)
        workers = 1
    with _open(path) as f:
        f.seek(span[0])
        if f.read(1) != b"{":
            return span[0]
        with _read_blocks(f, span, columnar, workers, spill_to=spill_to) as blocks:
            for (pos, cut), fast in blocks:
                if cut is None:  # no frame head in 4 blocks: another layout
                    return pos
                if fast is not None:
                    yield COLUMNAR, fast
                    continue
                try:
                    block = orjson.loads(b"{" + cut + b"}")
                except orjson.JSONDecodeError:
                    block = None
                if not isinstance(block, dict):
                    return pos
                yield from block.items()
    return None


def _read_blocks(f, span: tuple[int, int | None], columnar: bool, workers: int | None,
                 tail: list | None = None, spill_to=None):
    """``((offset, bytes), FastBlock or None)`` of each block of :func:`_cut_blocks`, in file
    order; with ``columnar`` the blocks read into columns by ``workers`` processes
    (:func:`aveas_format.parallel.map_ordered`; in worker processes Arrow's reader runs on one
    thread: the processes are the parallelism), else None each. With workers and a plain file
    the workers read their blocks' bytes themselves (the cuts found in a window before each:
    :func:`_cut_blocks`' ``lazy``; the bytes are read here only for a block the fast path
    refuses). ``spill_to``: asked as each block is sent, a directory where the worker writes the
    block's columns (:meth:`.fastblock.FastBlock.spill_to`: they are not sent back), or None.
    A context manager (closing it cancels the blocks in flight)."""
    from aveas_format.parallel import map_ordered, processes

    size = _COLUMNAR_BLOCK if columnar else _BLOCK
    lazy = columnar and workers != 1 and isinstance(f, io.BufferedReader) and hasattr(os, "pread")
    compiled = columnar and _file_size(f) >= _COMPILED_MIN
    read = partial(_read_cut, threads=workers == 1, path=f.name if lazy else None,
                   compiled=compiled) if columnar else _no_block
    if compiled:
        from aveas_format.converters.openlabel.fastblock import compiled_parser

        compiled_parser()  # (compiled or loaded here, once: forked workers inherit it)
    cuts = _cut_blocks(f, span, size, tail, lazy=lazy)
    if columnar and spill_to is not None and processes(workers) > 1:
        blocks = _cuts_only(map_ordered(partial(_read_cut_to, read=read), ((c, spill_to()) for c in cuts),
                                        workers=workers))
    else:
        blocks = map_ordered(read, cuts, workers=workers)
    return closing(_bytes_here(blocks, f) if lazy else blocks)


def _read_cut_to(item: tuple, read):
    """``read`` of a cut block in a worker (``item``: the block's ``(offset, cut)`` of
    :func:`_cut_blocks` and a directory or None), its columns written into the directory where
    there is one (as ``b<offset>.arrow``)."""
    block, directory = item
    blk = read(block)
    if blk is not None and directory is not None:
        blk.spill_to(Path(directory) / f"b{block[0]}.arrow")
    return blk


def _cuts_only(blocks):
    """The ``(cut, block)`` of :func:`_read_cut_to`'s results (closing it closes ``blocks``)."""
    try:
        for (cut, _), blk in blocks:
            yield cut, blk
    finally:
        blocks.close()


#: the file size from which the compiled block reader is used (loading numba and the reader from
#: its cache, ~0.4 s, pays from about 40k boxes on; smaller files: Arrow's reader)
_COMPILED_MIN = 48 << 20


def _file_size(f) -> int:
    """The size of the file under ``f`` (a plain or a decompressing reader; 0 where unknown)."""
    raw = getattr(f, "raw", f)
    try:
        return os.fstat(raw.fileno()).st_size
    except (OSError, AttributeError, ValueError, io.UnsupportedOperation):
        return 0


def _bytes_here(blocks, f):
    """The blocks of a lazy cut with their bytes, read here where the fast path refused one."""
    for (pos, cut), fast in blocks:
        if isinstance(cut, tuple):
            start, n = cut
            if fast is None:
                cut = os.pread(f.fileno(), n, start)
        yield (pos, cut), fast


def _cut_blocks(f, span: tuple[int, int | None], size: int, tail: list | None = None, lazy: bool = False):
    """``(offset, bytes)`` of the blocks of whole frames (the members between the braces of the
    frames, without the commas between blocks) from ``f``, read past the frames' ``{``; ``(offset,
    None)`` last where no frame head was found in 4 blocks (another layout). ``span[1]`` None: the
    end of the frames is not known — read to the end of the file, find it in the last block
    (:func:`_frames_end`) and append the bytes after the frames' closing brace to ``tail``.
    ``lazy`` (a plain file): a block is cut in a window of :data:`_CUT_WINDOW` bytes before its
    end and given as ``(offset, (start, length))`` for the reader to read; the last block, and
    any whose cut is not in its window, as bytes."""
    pos, end = span[0] + 1, (span[1] - 1 if span[1] is not None else 1 << 62)
    buf = b""
    while pos < end:
        if lazy and not buf and end - pos > 2 * size:
            w = min(_CUT_WINDOW, size)
            f.seek(pos + size - w)
            win = f.read(w)
            cut = _last_cut(win) if len(win) == w else None
            if cut is not None:
                n = size - w + cut
                yield (span[0] if pos == span[0] + 1 else pos), (pos, n)
                pos += n + 1
                continue
        if lazy and not buf:
            f.seek(pos)
        data = f.read(min(size, end - pos - len(buf)))
        buf += data
        last = not data or pos + len(buf) >= end
        if last and span[1] is None:
            close = _frames_end(buf)
            if close is None:
                yield pos, None
                return
            tail.append(buf[close + 1:])
            buf = buf[:close]
        cut = len(buf) if last else _last_cut(buf)
        if cut is None:
            if len(buf) > 4 * size:
                yield (span[0] if pos == span[0] + 1 else pos), None
                return
            continue
        yield (span[0] if pos == span[0] + 1 else pos), buf[:cut]
        pos += cut + 1  # past the comma between two frames
        buf = buf[cut + 1:]
        if last:
            break


def _read_cut(item: tuple[int, Any], threads: bool = True, path: str | None = None, compiled: bool = True):
    """A cut block into columns (:func:`.fastblock.read_block`, ``compiled``: the compiled reader
    where numba is there; runs in a worker process); its bytes read here from ``path`` where the
    cut gives ``(start, length)``."""
    from aveas_format.converters.openlabel.fastblock import read_block

    cut = item[1]
    if isinstance(cut, tuple):  # (read into this process's block buffer: no fresh pages per block)
        start, n = cut
        global _BUFFER
        if _BUFFER is None or len(_BUFFER) < n + 3:
            _BUFFER = np.empty(max(n + 3, _COLUMNAR_BLOCK + 3), np.uint8)
        b = _BUFFER[:n + 3]
        fd = os.open(path, os.O_RDONLY)
        try:
            if hasattr(os, "preadv"):
                got = os.preadv(fd, [memoryview(b)[1:n + 1]], start)
            else:  # (macOS before 11: one copy more)
                data = os.pread(fd, n, start)
                got = len(data)
                b[1:got + 1] = np.frombuffer(data, np.uint8)
        finally:
            os.close(fd)
        if got != n:  # (the file changed under the import: the parent reads the block, and fails)
            return None
        b[0], b[n + 1], b[n + 2] = 0x7B, 0x7D, 0
        return read_block(b, threads=threads, compiled=compiled)
    return None if cut is None else read_block(b"{" + cut + b"}", threads=threads, compiled=compiled)


#: a worker's buffer for the blocks it reads (:func:`_read_cut`)
_BUFFER = None


def _no_block(item: tuple[int, bytes | None]) -> None:
    return None


def _frames_end(buf: bytes) -> int | None:
    """The offset in ``buf`` (members of the frames from a frame boundary to the end of the file) of
    the frames' closing brace, None where the brackets outside strings do not close it."""
    from aveas_format.converters.openlabel.fastblock import _NotFast, _structure

    try:
        pos, depth, step, _ = _structure(b"{" + buf)
    except _NotFast:
        return None
    closes = pos[(depth == 1) & (step < 0)]
    return int(closes[0]) - 1 if len(closes) else None


def _last_cut(buf: bytes) -> int | None:
    """The offset of the comma before the last frame that starts in ``buf`` (None: none found)."""
    h = len(buf)
    while True:
        h = buf.rfind(b'"frame_properties"', 0, h)
        if h <= 0:
            return None
        c = buf.rfind(b",", 0, h)
        if c > 0 and _FRAME_HEAD.match(buf, c + 1, h):
            return c


class _Prefixed:
    """A reader that hands out ``head`` first, then what ``rd`` reads (``pos`` is the file's)."""

    def __init__(self, head: bytes, rd: CountingReader) -> None:
        self.head, self.rd = head, rd

    @property
    def pos(self) -> int:
        return self.rd.pos

    def read(self, n: int = -1) -> bytes:
        if n == 0:  # (ijson probes the type of the reader with read(0))
            return b""
        if self.head:
            h, self.head = self.head, b""
            return h
        return self.rd.read(n)


class _Suffixed:
    """A reader that hands out what ``rd`` reads, then ``tail``."""

    def __init__(self, rd: CountingReader, tail: bytes) -> None:
        self.rd, self.tail = rd, tail

    def read(self, n: int = -1) -> bytes:
        if n == 0:  # (ijson probes the type of the reader with read(0))
            return b""
        data = self.rd.read(n)
        if not data:
            data, self.tail = self.tail, b""
        return data
