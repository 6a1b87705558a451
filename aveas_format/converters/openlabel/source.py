"""Reading an OpenLABEL file for the import: its members besides the frames whole, its frames in
blocks of whole frames, bounded by :mod:`aveas_format.safeio`.

:func:`open_frames` checks the size, scans the structure up to where ``openlabel.frames`` starts
(:func:`~aveas_format.safeio.scan_json_member`: the nesting limit, a member that repeats) and reads
the members before the frames (the *head*); :class:`Frames` then cuts the frames into blocks of
whole frames (:func:`cuts`) and, once the last block is read, the members after them (the *tail*,
checked like a whole file). A block is cut before a frame that starts with ``"key":{
"frame_properties"`` (this library's exports and files laid out like them: found in a window
before the block's end, without reading the block here), else at the last frame boundary found by
a structural index of the block's bytes (:func:`_boundary`: quotes, brackets and commas outside
strings). A cut of the first kind is proven by decoding the block (:class:`WrongCut` where a
nested member was laid out like a frame head: the reader cuts again from there by structure).

Broken JSON and non-UTF-8 text are a :class:`FormatError` naming the file and the byte; a file that
uses Python's JSON extensions (``NaN``, ``Infinity``: :class:`ReadWhole`), that is no object at
its top level, or whose ``openlabel``/``frames`` repeat is read whole (:func:`load_document`, the
limits of :func:`~aveas_format.safeio.load_json`). ``.json.gz`` and ``.json.zst`` are read through
their decompressor (:mod:`aveas_format.safeio.compressed`).
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.safeio import (MAX_BULK_JSON_BYTES, MAX_JSON_DEPTH, MAX_STREAMED_JSON_BYTES, check_json_size,
                                 load_json, scan_json_member)
from aveas_format.safeio.compressed import compression, open_file

#: bytes of frames per block (a block's Python objects while it is decoded: ~3x that)
BLOCK = 8 << 20
#: bytes before a block's end in which a cut looks for the last frame head
CUT_WINDOW = 1 << 18
_FRAME_HEAD = re.compile(rb'\s*"(?:[^"\\]|\\.)*"\s*:\s*\{\s*$')
_EXTENSIONS = re.compile(rb"-?(NaN|Infinity)")


class ReadWhole(Exception):
    """A file the block-wise import does not take, known to be read whole (:func:`load_document`)
    as ``json.loads`` reads it: Python's JSON extensions (NaN, Infinity), which the decoder
    refuses, or ``openlabel``/``frames`` repeated after the frames."""


class WrongCut(Exception):
    """A block cut before a frame head does not decode: a nested member looked like a frame head
    (or the JSON is broken). ``offset``: where the block starts (a frame boundary)."""

    def __init__(self, offset: int) -> None:
        super().__init__(offset)
        self.offset = offset


def load_document(path: Path) -> dict[str, Any]:
    """The object under ``openlabel`` of a file read whole (:func:`~aveas_format.safeio.load_json`:
    :data:`MAX_BULK_JSON_BYTES`, the nesting limit)."""
    if compression(path):
        with open_file(path) as f:  # (at most one byte over the limit: load_json refuses it)
            raw = f.read(MAX_BULK_JSON_BYTES + 1)
    else:
        check_json_size(path, max_bytes=MAX_BULK_JSON_BYTES)
        try:
            raw = path.read_bytes()
        except OSError as e:
            raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    doc = load_json(raw, path=path, max_bytes=MAX_BULK_JSON_BYTES)
    if not isinstance(doc, dict) or not isinstance(doc.get("openlabel"), dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    return doc["openlabel"]


def broken(e: Exception, data: bytes, offset: int, path: Path | None) -> Exception:
    """The error for msgspec's error ``e`` decoding ``data`` (which starts at byte ``offset`` of
    the file): :class:`ReadWhole` at a NaN or Infinity, else a :class:`FormatError` naming
    the file and the byte."""
    msg = str(e)
    at = re.search(r"\(byte (\d+)\)", msg)
    pos = int(at[1]) if at else None
    if pos is not None and _EXTENSIONS.match(data, pos):
        return ReadWhole("NaN or Infinity (Python's JSON extensions)")
    if "UTF-8" in msg or "utf-8" in msg:
        return FormatError(f"not UTF-8 text (in the bytes after byte {offset:,})", path=path)
    head = re.sub(r"\s*\(byte \d+\)", "", msg).removeprefix("JSON is malformed: ")
    where = f" at byte {offset + pos:,}" if pos is not None else f" (after byte {offset:,})"
    return FormatError(f"broken JSON: {head}{where}", path=path)


@dataclass
class Frames:
    """An OpenLABEL file opened for a block-wise import (:func:`open_frames`): ``head`` the members
    of ``openlabel`` before the frames, ``start`` where the frames' ``{`` is; ``tail`` the members
    after them once :func:`cuts` has read the last block."""

    path: Path
    head: dict[str, Any]
    start: int
    size: int
    tail: dict[str, Any] | None = None

    @property
    def compressed(self) -> bool:
        return compression(self.path) is not None

    def document(self) -> dict[str, Any]:
        """``openlabel`` without its frames: the head with the tail's members."""
        return {**self.head, **(self.tail or {})}


def open_frames(path: Path) -> Frames | None:
    """The file opened for a block-wise import, or None where it is to be read whole: no frames,
    no object at the top level (empty, a BOM, UTF-16/32), ``openlabel`` or ``frames`` twice
    before the frames, nesting at the limit before them (a file smaller than a chunk of the
    pre-scan: anywhere in it)."""
    size = check_json_size(path, max_bytes=MAX_STREAMED_JSON_BYTES)
    with open_file(path) as f:
        if not f.read(4096).lstrip(b" \t\r\n").startswith(b"{"):
            return None
        depth, span, ok = scan_json_member(f, "openlabel", "frames", until_member=True)
        if not ok or depth >= MAX_JSON_DEPTH or span is None:
            if depth > MAX_JSON_DEPTH and ok:
                raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=path)
            return None  # (no frames object, a repeated member, nesting at the limit: read whole)
        start = span[0]
        f.seek(0)
        head = _decode(f.read(start) + b"{}}}", path)
    ol = head.get("openlabel") if isinstance(head, dict) else None
    if not isinstance(ol, dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    ol.pop("frames", None)
    return Frames(Path(path), ol, start, size)


def _decode(data: bytes, path: Path, offset: int = 0) -> Any:
    try:
        return msgspec.json.decode(data)
    except msgspec.DecodeError as e:
        raise broken(e, data, offset, path) from None
    except RecursionError:
        raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=path) from None


def read_tail(fr: Frames, tail: bytes, offset: int) -> None:
    """The members after the frames (``tail``: the bytes after their closing brace, at byte
    ``offset``), checked as the pre-scan checks a whole file: the nesting limit, ``openlabel`` and
    ``frames`` once (else :class:`ReadWhole`, as ``json.loads`` reads repeated members)."""
    doc = b'{"openlabel":{"frames":{}' + tail
    depth, _, ok = scan_json_member(io.BytesIO(doc), "openlabel", "frames")
    if depth > MAX_JSON_DEPTH:
        raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=fr.path)
    got = _decode(doc, fr.path, offset - 25)
    if not ok:
        raise ReadWhole("'openlabel' or 'frames' appears twice")
    fr.tail = {k: v for k, v in got["openlabel"].items() if k != "frames"}


def cuts(fr: Frames, f, size: int = BLOCK, lazy: bool = False, exact_from: int | None = None):
    """``(offset, bytes, kind)`` of the blocks of whole frames of ``f`` (the members between the
    frames' braces, without the commas between blocks): ``kind`` ``"head"`` (cut before a frame
    head: proven by decoding the block; ``(start, length)`` instead of the bytes where ``lazy``, a
    plain file the reader reads itself) or ``"structure"`` (cut by the structural index); last
    ``"tail"`` (the bytes after the frames, for :func:`read_tail`) or ``"broken"`` (an error
    message: the file ends inside the frames). Both come in order, after the blocks they follow,
    so that a wrong cut before them is found first. ``exact_from``: every cut by structure from
    this offset (a frame boundary) on."""
    pos = fr.start + 1 if exact_from is None else exact_from
    f.seek(pos)
    buf = b""
    while True:
        if lazy and not buf and exact_from is None and fr.size - pos > 2 * size:
            w = min(CUT_WINDOW, size)
            f.seek(pos + size - w)
            cut = _head_cut(f.read(w))
            if cut is not None:
                n = size - w + cut
                yield pos, (pos, n), "head"
                pos += n + 1
                continue
        if lazy and not buf:
            f.seek(pos)
        data = f.read(size)
        buf += data
        cut = None if exact_from is not None or not data else _head_cut(buf)
        if cut is not None:  # (the block and the rest apart before the block is decoded)
            block, buf = buf[:cut], buf[cut + 1:]
            yield pos, block, "head"
            del block
            pos += cut + 1
            continue
        kind, at = _boundary(buf)
        if kind == "close":  # the frames end here: the last block, then the tail
            if buf[:at].strip():
                yield pos, buf[:at], "structure"
            rest = [buf[at + 1:]]
            while data := f.read(1 << 20):
                rest.append(data)
            yield pos + at + 1, b"".join(rest), "tail"
            return
        if not data:
            yield pos, f"broken JSON: the file ends inside the frames (after byte {pos:,})", "broken"
            return
        if kind == "cut":
            block, buf = buf[:at], buf[at + 1:]
            yield pos, block, "structure"
            del block
            pos += at + 1


def _head_cut(buf: bytes) -> int | None:
    """The offset of the comma before the last frame head (``,"key":{"frame_properties"``) in
    ``buf`` (None: none found)."""
    h = len(buf)
    while True:
        h = buf.rfind(b'"frame_properties"', 0, h)
        if h <= 0:
            return None
        c = buf.rfind(b",", 0, h)
        if c > 0 and _FRAME_HEAD.match(buf, c + 1, h):
            return c


def _boundary(buf: bytes) -> tuple[str | None, int]:
    """Where the frames close in ``buf`` (members of the frames from a frame boundary on):
    ``("close", offset)``; else the last comma between two frames, ``("cut", offset)``; else
    ``(None, 0)``. A structural index: the quotes, brackets and commas outside strings (a quote
    after an odd run of backslashes is inside a string)."""
    a = np.frombuffer(buf, np.uint8)
    f = a | 0x20  # '[' -> '{', ']' -> '}'
    idx = np.flatnonzero((a == 34) | (a == 44) | (f == 0x7B) | (f == 0x7D))
    k = a[idx]
    isq = k == 34
    if buf.find(b"\\") >= 0:
        qpos = idx[isq]
        esc = np.zeros(len(qpos), bool)
        for i in np.flatnonzero(a[np.maximum(qpos - 1, 0)] == 92).tolist():
            j = int(qpos[i]) - 1
            while j >= 0 and buf[j] == 92:
                j -= 1
            esc[i] = (int(qpos[i]) - 1 - j) % 2 == 1
        keep = np.ones(len(idx), bool)
        keep[np.flatnonzero(isq)[esc]] = False
        idx, k, isq = idx[keep], k[keep], isq[keep]
    outside = ~isq & ~(np.cumsum(isq, dtype=np.uint8) & 1).astype(bool)
    pos, kind = idx[outside], k[outside]
    step = np.where(kind == 44, 0, np.where((kind | 0x20) == 0x7B, 1, -1))
    level = np.cumsum(step)
    close = np.flatnonzero((step < 0) & (level == -1))
    if len(close):
        return "close", int(pos[close[0]])
    commas = pos[(step == 0) & (level == 0)]
    return ("cut", int(commas[-1])) if len(commas) else (None, 0)
