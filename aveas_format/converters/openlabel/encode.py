"""The OpenLABEL frames as JSON bytes built from columns (the hot path of the export).

No dict per state: each part of an object's data (the box, the velocity, the lights, the road
facts, the extension's values...) is one column of JSON fragments, built for a chunk of rows at
once — numbers are formatted by one ``orjson.dumps`` of a numpy array (split per row), strings
through a cache of their distinct values, optional parts are empty fragments — and the fragments
are concatenated element-wise (numpy object arrays). Only what is irregular by nature (interior
signals, ``impact`` attributes, extension columns of nested types) goes through a Python value per
row, and only in the rows that have it.

:func:`frame_chunks` yields the members of the ``frames`` object in frame order, a chunk of about
:data:`CHUNK_ROWS` rows at a time, so that an export never holds the document (only the
recording's columns and one chunk of text). Without orjson (``pip install aveas-format[fast]``)
the same values come from the standard library's encoder, about 2x slower.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from itertools import repeat
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.openlabel.profile import _LONGITUDINAL, EXT, LIGHTS, _clean

try:  # the fast JSON encoder (extra ``fast``); the standard library's otherwise
    import orjson
except ImportError:  # pragma: no cover - exercised by a test that hides it
    orjson = None

#: rows per chunk of the streamed frames (a chunk ends at a frame boundary)
CHUNK_ROWS = 16384


def dumps(v: Any) -> bytes:
    """Compact JSON of a Python value as :func:`~aveas_format.converters.openlabel.profile._clean`
    makes it JSON-safe (NaN/inf -> null, numpy scalars -> Python, bytes -> ``{"base64": ...}``)."""
    if orjson is not None:  # orjson does the same itself, without walking the value in Python
        return orjson.dumps(v, default=_clean_other, option=orjson.OPT_SERIALIZE_NUMPY)
    return json.dumps(_clean(v), separators=(",", ":"), allow_nan=False).encode()


def _clean_other(v: Any) -> Any:
    """What orjson leaves to its ``default``: bytes and other numpy scalars, as ``_clean``."""
    if isinstance(v, (bytes, bytearray, np.generic)):
        return _clean(v)
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")


def _dump_array(a: np.ndarray) -> bytes:
    if orjson is not None:
        return orjson.dumps(a, option=orjson.OPT_SERIALIZE_NUMPY)
    b = json.dumps(a.tolist(), separators=(",", ":")).encode()
    if a.dtype.kind == "f":
        b = b.replace(b"-Infinity", b"null").replace(b"Infinity", b"null").replace(b"NaN", b"null")
    return b


def numbers(a: np.ndarray) -> list[bytes]:
    """JSON numbers of a 1-D array (float64 or int64; NaN -> null), or of each row of a 2-D array
    joined by commas: one bytes per row."""
    a = np.ascontiguousarray(a, dtype=np.int64 if a.dtype.kind in "iub" else np.float64)
    if len(a) == 0:
        return []
    b = _dump_array(a)
    return b[1:-1].split(b",") if a.ndim == 1 else b[2:-2].split(b"],[")


def texts(values: list) -> list[bytes]:
    """JSON strings of ``str(v)`` per value (each distinct value encoded once)."""
    cache: dict[Any, bytes] = {}
    return [cache[v] if v in cache else cache.setdefault(v, dumps(str(v))) for v in values]


def _stack(parts: list, idx: np.ndarray) -> np.ndarray:
    """The rows ``idx`` of a vector given as its components (arrays over all rows, or a number)."""
    return np.column_stack([np.full(len(idx), c, dtype=np.float64) if np.isscalar(c) else c[idx]
                            for c in parts])


def _join(pieces: list, m: int) -> list[bytes]:
    """Per row the concatenation of the pieces (a bytes: the same in every row; a list: one per row)."""
    return list(map(b"".join, zip(*[repeat(p, m) if isinstance(p, bytes) else p for p in pieces])))


def _item(name: str, vals: list[bytes], mask: np.ndarray | None = None, *, vec: bool = False) -> list[bytes]:
    """``,{"name":NAME,"val":V}`` per row (``[V]`` for a vector), empty where ``mask`` is False."""
    fmt = b',{"name":' + dumps(name).replace(b"%", b"%%") + (b',"val":[%s]}' if vec else b',"val":%s}')
    if mask is None:
        return [fmt % v for v in vals]
    return [fmt % v if ok else b"" for v, ok in zip(vals, mask.tolist())]


def _list(items: list[list[bytes]], m: int) -> list[bytes]:
    """The inner text of a JSON list per row from its items (each starting with a comma)."""
    if not items:
        return [b""] * m
    return [s[1:] for s in _join(items, m)]


def _column_fragments(col: pa.ChunkedArray | pa.Array) -> tuple[np.ndarray, list[bytes]]:
    """A states column's values as JSON fragments (``(valid, json)``): numbers vectorised, other
    types through their Python values (as the extension block has them)."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_dictionary(col.type):
        col = col.cast(col.type.value_type)
    valid = col.is_valid().to_numpy(zero_copy_only=False)
    t = col.type
    if pa.types.is_floating(t) or pa.types.is_integer(t):
        fill = 0 if pa.types.is_integer(t) else math.nan
        a = col.fill_null(fill).to_numpy(zero_copy_only=False)
        if pa.types.is_floating(t):
            a = a.astype(np.float64)  # float32 as its float64 value (what to_pylist gives)
        return valid, numbers(a)
    if pa.types.is_boolean(t):
        a = col.fill_null(False).to_numpy(zero_copy_only=False)
        return valid, [b"true" if v else b"false" for v in a.tolist()]
    return valid, [dumps(v) if v is not None else b"" for v in col.to_pylist()]


def frame_chunks(rows: dict[str, Any], *, chunk_rows: int = CHUNK_ROWS) -> Iterator[bytes]:
    """The members ``"k":{frame}`` of the ``frames`` object, comma-separated, in chunks of about
    ``chunk_rows`` rows (``rows``: the per-row inputs prepared by the writer, see
    :func:`aveas_format.converters.openlabel.write._frame_inputs`)."""
    fr = rows["frame_of_row"]
    order = np.argsort(fr, kind="stable")  # in a frame: the objects in the states' order
    fs = fr[order]
    ts = numbers(rows["times"])
    n = len(order)
    start, first = 0, True
    while start < n:
        stop = min(start + chunk_rows, n)
        stop = int(np.searchsorted(fs, fs[stop - 1], side="right"))
        idx = order[start:stop]
        objs = _objects_text(rows, idx)
        f = fs[start:stop]
        cuts = np.flatnonzero(np.diff(f)) + 1
        lo = np.r_[0, cuts]
        hi = np.r_[cuts, len(f)]
        parts = []
        for a, b in zip(lo.tolist(), hi.tolist()):
            k = int(f[a])
            parts.append(b'"%d":{"frame_properties":{"timestamp":%s},"objects":{%s}}'
                         % (k, ts[k], b",".join(objs[a:b])))
        yield (b"" if first else b",") + b",".join(parts)
        first = False
        start = stop


def _objects_text(r: dict[str, Any], idx: np.ndarray) -> list[bytes]:
    """``"uid":{"object_data":{...}}`` for the rows ``idx``."""
    m = len(idx)
    pid = r["pid"][idx]
    on = r["on"][idx]
    vec = [_join([b',{"name":"velocity","val":[', numbers(_stack(r["vel"], idx)),
                  b']},{"name":"acceleration","val":[', numbers(_stack(r["acc"], idx)), b"]}"], m)]
    if r["box_std"] is not None:
        vec.append(_item("bounding_box/ustddev", numbers(_stack(r["box_std"], idx)), vec=True))
    if r["vel_std"] is not None:
        vec.append(_item("velocity/ustddev", numbers(_stack(r["vel_std"], idx)), r["vel_ok"][idx], vec=True))
    if r["acc_std"] is not None:
        vec.append(_item("acceleration/ustddev", numbers(_stack(r["acc_std"], idx)), r["acc_ok"][idx], vec=True))
    text, num, boolean = [], [], []
    if on.any():
        text.append(_item("used_road_link", texts([r["road_id"][i] for i in idx.tolist()]), on))
        if r["lane_id"] is not None:
            lid = r["lane_id"][idx]
            ok = on & np.isfinite(lid)
            text.append(_item("open_drive/lane_id", texts(np.where(ok, lid, 0).astype(np.int64).tolist()), ok))
        vec.append(_item("open_drive/local_road_coordinates",
                         numbers(np.column_stack([r["road_s"][idx], r["road_t"][idx]])), on, vec=True))
        facts = r["facts"]
        if facts is not None:
            lp = facts["lane_position"][idx]
            num.append(_item("open_drive/lane_position", numbers(lp), on & np.isfinite(lp)))
            road_user = on & r["road_class"][idx]
            text.append(_item("road/classification", texts(facts["classification"][idx].tolist()), road_user))
            for side in ("left", "right"):
                for kind, key in (("legal", f"{side}_legal"), ("physical", f"{side}_phys")):
                    num.append(_item(f"road/number_lanes/{side}/{kind}", numbers(facts[key][idx]), road_user))
    for c, name in LIGHTS.items():
        a = r["lights"].get(c)
        if a is not None:
            a = a[idx]
            boolean.append(_item(name, [b"true" if v else b"false" for v in (a >= 0.5).tolist()],
                                 np.isfinite(a)))
    _irregular(r, idx, pid, vec, num, boolean)
    return _join([b'"', numbers(pid), b'":{"object_data":{"cuboid":[{"name":"bounding_box","val":[',
                  numbers(_stack(r["box"], idx)), b"]", _extension(r, idx), b'}],"vec":[', _list(vec, m),
                  b'],"boolean":[', _list(boolean, m), b'],"num":[', _list(num, m),
                  b'],"text":[', _list(text, m), b"]}}"], m)


def _irregular(r: dict[str, Any], idx: np.ndarray, pid: np.ndarray, vec: list, num: list,
               boolean: list) -> None:
    """Interior signals and ``impact`` attributes: by (participant, time), only in the rows that
    have them."""
    interior, impact = r["interior"], r["impact"]
    if not interior and not impact:
        return
    m = len(idx)
    b_int, n_int, v_imp = [b""] * m, [b""] * m, [b""] * m
    t = r["t"][idx].tolist()
    for j, key in enumerate(zip(pid.tolist(), t)):
        irow = interior.get(key) if interior else None
        if irow:
            bl, nl = [], []
            for c in ("automation_longitudinal_p", "automation_lateral_p"):
                # the profile's lateral flag carries the longitudinal name (quirk)
                if irow.get(c) is not None:
                    bl.append({"name": _LONGITUDINAL, "val": bool(irow[c] >= 0.5)})
            for c, name in (("steering_angle", "interior/steering_angle"),
                            ("steering_angle_std", "interior/steering_angle/ustddev"),
                            ("brake_pedal", "interior/brake_pedal"),
                            ("accelerator_pedal", "interior/accelerator_pedal"),
                            ("gear", "interior/gear")):
                if irow.get(c) is not None:
                    nl.append({"name": name, "val": irow[c] if c == "gear" else float(irow[c])})
            b_int[j] = b"".join(b"," + dumps(x) for x in bl)
            n_int[j] = b"".join(b"," + dumps(x) for x in nl)
        imp = impact.get(key) if impact else None
        if imp:
            items = []
            for k in ("gttc", "pret", "thw"):
                if imp.get(f"{k}/values"):
                    items.append({"name": f"impact/{k}/object_ids", "val": imp[f"{k}/object_ids"]})
                    items.append({"name": f"impact/{k}/values", "val": imp[f"{k}/values"]})
            v_imp[j] = b"".join(b"," + dumps(x) for x in items)
    vec.append(v_imp)
    boolean.append(b_int)
    num.append(n_int)


def _extension(r: dict[str, Any], idx: np.ndarray) -> list[bytes] | bytes:
    """``,"aveas_format":{...}`` per row where the row has extension values (the states' columns
    the profile lacks, placeholders of null profile columns, exact values), else empty."""
    ext = r["ext"]
    if ext is None:
        return b""
    m = len(idx)
    pieces: list = []
    ix = pa.array(idx)

    def member(c: str, vals: list[bytes], mask: np.ndarray) -> list[bytes]:
        fmt = b'"' + c.encode().replace(b"%", b"%%") + b'":%s,'
        return [fmt % v if ok else b"" for v, ok in zip(vals, mask.tolist())]

    for c, col in ext["columns"].items():
        valid, frag = _column_fragments(col.take(ix))
        pieces.append(member(c, frag, valid))
    for c, isnull in ext["nullable"].items():
        pieces.append(member(c, [b"null"] * m, isnull[idx]))
    for c, vals in ext["exact"].items():
        v = vals[idx]
        pieces.append(member(c, numbers(v), ~np.isnan(v)))
    if not pieces:
        return b""
    head = b',"' + EXT.encode() + b'":{'
    return [head + s[:-1] + b"}" if s else b"" for s in _join(pieces, m)]


__all__ = ["CHUNK_ROWS", "dumps", "frame_chunks", "numbers", "texts"]
