"""Reading an OpenLABEL file for the import: streamed with ijson, bounded by :mod:`aveas_format.safeio`.

:func:`_stream_doc` reads everything under ``openlabel`` except the frames whole and hands the
frames out one at a time (a file of millions of boxes never exists as one dict);
:func:`_load_doc` reads a file whole (``load_json`` with the same limits), the fallback for files
the structural pre-scan does not take and for files with Python's JSON extensions (``NaN``,
``Infinity``: :class:`_NotStrictJSON`); :func:`_check_stream` parses a whole file without building
anything, to report its JSON error where one exists.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.safeio import (MAX_BULK_JSON_BYTES, MAX_JSON_DEPTH, CountingReader, check_json_size,
                                 load_json, scan_json_member, stream_json_error)


def _load_doc(path: Path) -> dict[str, Any]:
    try:
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

    with open(path, "rb") as f:
        r = CountingReader(f)
        try:
            for _ in ijson.basic_parse(r, use_float=True):
                pass
        except ijson.JSONError as e:
            raise _stream_error(e, path, r.pos) from None


def _stream_doc(path: Path):
    """Open an OpenLABEL file for a streamed import: ``(ol, frames)`` with ``ol`` the object under
    ``openlabel`` without its frames (read whole: metadata, objects, coordinate systems, ...) and
    ``frames`` a function that yields ``(frame key, frame)`` one at a time in file order (ijson);
    ``frames`` is None where the file was read whole (no frames object, or a file the structural
    pre-scan does not take: then :func:`_load_doc`, the same limits and errors).

    The size limit is checked before reading; the nesting limit on the structural pre-scan
    (:func:`aveas_format.safeio.scan_json_member`, which also finds the byte range of the frames).
    Broken JSON and non-UTF-8 text give a :class:`FormatError` naming the file."""
    import ijson

    check_json_size(path, max_bytes=MAX_BULK_JSON_BYTES)
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    with f:
        head = f.read(4096).lstrip(b" \t\r\n")
        if not head.startswith(b"{"):  # empty, a BOM, UTF-16/32, not an object: read it whole
            return _load_doc(path), None
        depth, span, ok = scan_json_member(f, "openlabel", "frames")
    if not ok:  # broken (e.g. truncated: refused here in bounded memory) or a member repeats
        _check_stream(path)
    if not ok or depth == MAX_JSON_DEPTH:  # (at the limit: the exact check of load_json decides)
        return _load_doc(path), None
    if depth > MAX_JSON_DEPTH:
        raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=path)
    with open(path, "rb") as f:
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

    def frames():
        with open(path, "rb") as fr:
            rd = CountingReader(fr, start=span[0], stop=span[1])
            try:
                yield from ijson.kvitems(rd, "", use_float=True)
            except ijson.JSONError as e:
                raise _stream_error(e, path, rd.pos) from None

    return ol, frames
