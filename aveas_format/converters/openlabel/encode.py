"""The OpenLABEL frames as JSON bytes built from columns (the hot path of the export).

No dict per state: each part of an object's data (the box, the velocity, the lights, the road
facts, the extension's values...) is one column of JSON fragments, built for a chunk of rows at
once — numbers are formatted by one ``orjson.dumps`` of a numpy array (split per row), strings
through a cache of their distinct values, optional parts are empty fragments — and the fragments
are put together by Arrow (an element-wise join of each template's constants and columns: no
Python step per value or row). Only what is irregular by nature (interior
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
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.openlabel.profile import LONGITUDINAL, EXT, LIGHTS
from aveas_format.io.timemajor import chunk_bounds
from aveas_format.io.tablejson import json_safe

try:  # the fast JSON encoder (extra ``fast``); the standard library's otherwise
    import orjson
except ImportError:  # pragma: no cover - exercised by a test that hides it
    orjson = None

#: rows per chunk of the streamed frames (a chunk ends at a frame boundary)
CHUNK_ROWS = 16384


def dumps(v: Any) -> bytes:
    """Compact JSON of a Python value as :func:`~aveas_format.converters.openlabel.profile.json_safe`
    makes it JSON-safe (NaN/inf -> null, numpy scalars -> Python, bytes -> ``{"base64": ...}``)."""
    if orjson is not None:  # orjson does the same itself, without walking the value in Python
        return orjson.dumps(v, default=_clean_other, option=orjson.OPT_SERIALIZE_NUMPY)
    return json.dumps(json_safe(v), separators=(",", ":"), allow_nan=False).encode()


def _clean_other(v: Any) -> Any:
    """What orjson leaves to its ``default``: bytes and other numpy scalars, as ``json_safe``."""
    if isinstance(v, (bytes, bytearray, np.generic)):
        return json_safe(v)
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


_TRUE_FALSE = np.array([b"false", b"true"], dtype=object)
_EMPTY = pa.scalar(b"", pa.binary())


def _split(text: bytes, sep: bytes) -> pa.Array:
    """The pieces of ``text`` between ``sep`` as an Arrow binary array (split by Arrow)."""
    return pc.split_pattern(pa.array([text], pa.binary()), pattern=sep).flatten()


class _Layout:
    """The JSON text of ``m`` rows of one layout.

    A row is a sequence of segments: constant bytes, *values* (a column of JSON fragments, one
    per row: :meth:`floats`, :meth:`ints`, :meth:`text`, :meth:`booleans`), *joined lists*
    (:meth:`join`: items separated by commas, each item present where its mask is true). Rows
    with the same items present share a template (constants and columns constant over the rows
    inlined). Numbers are formatted by one call per kind (float, int) over all of the rows'
    numeric columns and split by Arrow; each group's template is joined element-wise by Arrow
    (``binary_join_element_wise``): no Python object per value, no Python step per row."""

    def __init__(self, m: int) -> None:
        self.m = m
        #: value token -> bytes (the same in every row) or a column: ("n", float64 or int64 array,
        #: 1-D, or 2-D: a vector's components), ("c", table of fragments, each row's index into
        #: it) or ("t", an object array of fragments)
        self._vals: list[Any] = []
        self._masks: list[np.ndarray] = []
        self._mask_ids: dict[bytes, int] = {}

    # ---- values ---------------------------------------------------------------------------
    def _number(self, a: Any, ints: bool) -> int:
        dtype = np.int64 if ints else np.float64
        if np.isscalar(a):
            self._vals.append(numbers(np.array([a], dtype=dtype))[0])
            return len(self._vals) - 1
        a = np.asarray(a, dtype=dtype)
        first = a[:1]
        # the same bits in every row (-0.0 is not 0.0: the round trip keeps the sign)
        if len(a) and ((a.view(np.int64) == first.view(np.int64)).all()
                       or (a.ndim == 1 and not ints and np.isnan(a).all())):
            self._vals.append(numbers(first)[0])  # constant over the rows: in the template
        else:
            self._vals.append(("n", a))
        return len(self._vals) - 1

    def floats(self, a: Any) -> int:
        """A float column (float64 values; NaN -> null), or one number for every row, or the
        rows of a matrix (one fragment ``a,b,c`` per row)."""
        return self._number(a, False)

    def ints(self, a: Any) -> int:
        return self._number(a, True)

    def text(self, values: Any) -> int:
        """A column of ready JSON fragments (bytes, one per row), or one bytes for every row."""
        self._vals.append(values if isinstance(values, bytes) else ("t", np.asarray(values, dtype=object)))
        return len(self._vals) - 1

    def coded(self, table: np.ndarray, codes: np.ndarray) -> int:
        """A column of fragments given as each row's index into ``table`` (an object array of bytes)."""
        self._vals.append(("c", table, np.asarray(codes, dtype=np.int64)))
        return len(self._vals) - 1

    def booleans(self, a: np.ndarray) -> int:
        return self.coded(_TRUE_FALSE, np.asarray(a, dtype=bool))

    # ---- structure ------------------------------------------------------------------------
    def mask(self, mask: np.ndarray | None) -> Any:
        """An item's presence: True (every row), False (none) or a mask index."""
        if mask is None:
            return True
        mask = np.asarray(mask, dtype=bool)
        if mask.all():
            return True
        if not mask.any():
            return False
        key = np.packbits(mask).tobytes()
        if key not in self._mask_ids:
            self._masks.append(mask)
            self._mask_ids[key] = len(self._masks) - 1
        return self._mask_ids[key]

    def join(self, head: bytes, items: list, tail: bytes, empty: bytes | None = None) -> tuple:
        """``head`` + the present items separated by commas + ``tail``; ``empty`` (when not None)
        instead where no item is present. ``items``: (mask index/True/False, segments)."""
        return ("join", head, [(p, segs) for p, segs in items if p is not False], tail, empty)

    # ---- text ---------------------------------------------------------------------------------
    def _groups(self) -> tuple[list[list[bool]], np.ndarray]:
        """The rows' groups: which masks each group's rows have, and each row's group."""
        m = self.m
        if not self._masks:
            return [[]], np.zeros(m, dtype=np.int64)
        bits = np.column_stack(self._masks)
        if bits.shape[1] < 63:
            code = bits.astype(np.int64) @ (np.int64(1) << np.arange(bits.shape[1], dtype=np.int64))
            shapes, inverse = np.unique(code, return_inverse=True)
            present = [[bool(c >> b & 1) for b in range(bits.shape[1])] for c in shapes.tolist()]
        else:
            shapes, inverse = np.unique(bits, axis=0, return_inverse=True)
            present = shapes.tolist()
        return present, inverse.reshape(-1).astype(np.int64)

    def _numbers_of(self, kind: str) -> list[int]:
        """The tokens of the numeric columns of ``kind`` (``"f"``: floats, ``"i"``: ints)."""
        return [k for k, v in enumerate(self._vals)
                if isinstance(v, tuple) and v[0] == "n" and v[1].dtype.kind == kind]

    def _fragments(self) -> list[Any]:
        """Each value as bytes (constant) or an Arrow binary array of the rows' fragments: the
        numbers of a kind formatted by one call and split by Arrow (no Python object per value)."""
        vals = list(self._vals)
        for kind in ("f", "i"):
            cols = [k for k in self._numbers_of(kind) if vals[k][1].ndim == 1]  # (vectors below)
            if not cols:
                continue
            mat = np.column_stack([vals[k][1] for k in cols])  # rows x columns, one formatting call
            lo, hi = (int(mat.min()), int(mat.max())) if kind == "i" and mat.size else (0, 1 << 62)
            if hi - lo < 65536:  # ids, counts, frames of a chunk: each distinct value's text once
                table = pa.array(numbers(np.arange(lo, hi + 1, dtype=np.int64)), pa.binary())
                for j, k in enumerate(cols):
                    vals[k] = table.take(pa.array(mat[:, j] - lo))
                continue
            flat = _split(_dump_array(np.ascontiguousarray(mat.reshape(-1)))[1:-1], b",")
            for j, k in enumerate(cols):
                vals[k] = flat.take(pa.array(np.arange(j, len(flat), len(cols))))
        for k, v in enumerate(vals):
            if isinstance(v, tuple):
                if v[0] == "n":  # (a vector's rows: "a,b,c" each)
                    a = np.ascontiguousarray(v[1], dtype=np.int64 if v[1].dtype.kind in "iub" else np.float64)
                    vals[k] = _split(_dump_array(a)[2:-2], b"],[") if len(a) else pa.array([], pa.binary())
                elif v[0] == "c":  # (a negative code: a row whose mask leaves the value out)
                    vals[k] = pa.array(v[1].tolist(), pa.binary()).take(pa.array(v[2], mask=v[2] < 0))
                else:
                    vals[k] = pa.array(v[1].tolist(), pa.binary())
        return vals

    def _joined(self, segments: list) -> pa.Array:
        """The text of each row (an Arrow binary array, in row order) of the segments (bytes,
        value tokens (ints), :meth:`join` tuples): each group's template joined element-wise by
        Arrow (no Python step per row)."""
        m = self.m
        if m == 0:
            return pa.array([], pa.binary())
        vals = self._fragments()
        present, inverse = self._groups()
        order = np.argsort(inverse, kind="stable")
        cuts = np.r_[0, np.cumsum(np.bincount(inverse, minlength=len(present)))]
        done = []
        for g, on in enumerate(present):
            idx = order[cuts[g]:cuts[g + 1]]
            if not len(idx):
                continue
            parts: list = []
            self._template(segments, on, parts)
            whole = len(idx) == m  # one layout for all rows: in order, no gather
            args: list = []
            for p in parts:  # (neighbouring constants as one)
                p = vals[p] if isinstance(p, int) else p
                if isinstance(p, bytes):
                    if args and isinstance(args[-1], bytes):
                        args[-1] += p
                    else:
                        args.append(p)
                else:
                    args.append(p if whole else p.take(pa.array(idx)))
            if len(args) == 1 and isinstance(args[0], bytes):  # (no value varies: the text itself)
                done.append(pa.array([args[0]] * len(idx), pa.binary()))
                continue
            done.append(pc.binary_join_element_wise(
                *(pa.scalar(a, pa.binary()) if isinstance(a, bytes) else a for a in args), _EMPTY))
        if len(done) == 1:
            return done[0]
        back = np.empty(m, np.int64)
        back[order] = np.arange(m)
        return pa.concat_arrays(done).take(pa.array(back))

    def rows(self, segments: list) -> np.ndarray:
        """The text of each row (an object array of bytes)."""
        return np.array(self._joined(segments).to_pylist(), dtype=object)

    def packed(self, segments: list) -> pa.Buffer:
        """The rows' text one after the other: one buffer (bytes-like)."""
        out = self._joined(segments)
        offsets = np.frombuffer(out.buffers()[1], np.int32, len(out) + 1, out.offset * 4) if len(out) else [0, 0]
        return out.buffers()[2][int(offsets[0]):int(offsets[-1])] if len(out) else pa.py_buffer(b"")

    def _template(self, segments: list, on: list[bool], parts: list) -> None:
        """The segments of a group of rows (``on``: which masks they have) as bytes and value
        tokens (ints), the joined lists resolved."""
        for seg in segments:
            if isinstance(seg, bytes):
                parts.append(seg)
            elif isinstance(seg, (int, np.integer)):
                parts.append(int(seg))
            else:
                _, head, items, tail, empty = seg
                chosen = [segs for p, segs in items if p is True or on[p]]
                if not chosen and empty is not None:
                    parts.append(empty)
                    continue
                parts.append(head)
                for k, segs in enumerate(chosen):
                    if k:
                        parts.append(b",")
                    self._template(segs, on, parts)
                parts.append(tail)


def _vector(lay: _Layout, parts: list, idx: np.ndarray) -> list:
    """Segments of a vector's components (arrays over all rows, or numbers) for the rows ``idx``:
    one fragment per row, or the vector in the template where it is the same in every row."""
    m = len(idx)
    return [lay.floats(np.column_stack([np.full(m, c, dtype=np.float64) if np.isscalar(c) else c[idx]
                                        for c in parts]))]


def _named(name: str, val: list, *, vec: bool = False, quoted: bool = False) -> list:
    """Segments of ``{"name":NAME,"val":V}`` (``[V]`` for a vector, ``"V"`` quoted)."""
    head = b'{"name":' + dumps(name) + b',"val":' + (b"[" if vec else b'"' if quoted else b"")
    return [head, *val, b"]}" if vec else b'"}' if quoted else b"}"]


def frame_chunks(frame_of_row: np.ndarray, times: np.ndarray, prepare, *,
                 chunk_rows: int = CHUNK_ROWS, part: tuple[int, int] | None = None) -> Iterator[Any]:
    """The members ``"k":{frame}`` of the ``frames`` object, comma-separated, in chunks of about
    ``chunk_rows`` rows (whole frames): ``frame_of_row`` = each state row's frame (an index into
    ``times``), ``prepare(rows)`` = the per-row inputs of the state rows ``rows`` (in that order;
    :func:`aveas_format.converters.openlabel.write.openlabel_chunks`), asked for one chunk at a
    time. ``part``: only the chunks ``[first, last)`` of :func:`~aveas_format.io.timemajor.chunk_bounds` (their text is the
    same as in the whole sequence: a comma before every chunk but the very first)."""
    order = np.argsort(frame_of_row, kind="stable")  # in a frame: the objects in the states' order
    if len(order) < 2**31:
        order = order.astype(np.int32)  # (half the memory: one index per state)
    fs = frame_of_row[order]
    ts = numbers(times)
    bounds = chunk_bounds(fs, chunk_rows)
    c0, c1 = part if part is not None else (0, len(bounds) - 1)
    for c in range(c0, c1):
        start, stop = bounds[c], bounds[c + 1]
        rows = order[start:stop]
        f = fs[start:stop]
        m = len(f)
        lo = np.flatnonzero(np.r_[True, f[1:] != f[:-1]])  # the first row of each frame
        # before each row its frame's head (a frame's first row) or a comma, after a frame's
        # last row "}}": fragments of the rows themselves (the chunk is written in one go)
        heads = [b'%s"%d":{"frame_properties":{"timestamp":%s},"objects":{'
                 % (b"" if c == 0 and j == 0 else b",", k, ts[k]) for j, k in enumerate(f[lo].tolist())]
        before = np.zeros(m, np.int64)
        before[lo] = np.arange(1, len(lo) + 1)
        after = np.zeros(m, np.int64)
        after[np.r_[lo[1:] - 1, m - 1]] = 1
        yield _objects_packed(prepare(rows), np.arange(m), (np.array([b",", *heads], dtype=object), before),
                              (_AFTER, after))


_AFTER = np.array([b"", b"}}"], dtype=object)


def _objects_packed(r: dict[str, Any], idx: np.ndarray, before: tuple, after: tuple) -> pa.Buffer:
    """``"uid":{"object_data":{...}}`` for the rows ``idx``, one after the other, each between
    a fragment ``before`` and one ``after`` (``(table, each row's index into it)``)."""
    m = len(idx)
    lay = _Layout(m)
    pid = r["pid"][idx]
    on = r["on"][idx]
    vec = [(True, _named("velocity", _vector(lay, r["vel"], idx), vec=True)),
           (True, _named("acceleration", _vector(lay, r["acc"], idx), vec=True))]
    if r["box_std"] is not None:
        vec.append((True, _named("bounding_box/ustddev", _vector(lay, r["box_std"], idx), vec=True)))
    if r["vel_std"] is not None:
        vec.append((lay.mask(r["vel_ok"][idx]),
                    _named("velocity/ustddev", _vector(lay, r["vel_std"], idx), vec=True)))
    if r["acc_std"] is not None:
        vec.append((lay.mask(r["acc_ok"][idx]),
                    _named("acceleration/ustddev", _vector(lay, r["acc_std"], idx), vec=True)))
    text, num, boolean = [], [], []
    if on.any():
        p_on = lay.mask(on)
        words = np.array([*texts(r["road_words"]), b""], dtype=object)
        text.append((p_on, _named("used_road_link", [lay.coded(words, r["road_code"][idx])])))
        if r["lane_id"] is not None:
            lid = r["lane_id"][idx]
            ok = on & np.isfinite(lid)
            text.append((lay.mask(ok), _named("open_drive/lane_id",
                                              [lay.ints(np.where(ok, lid, 0).astype(np.int64))], quoted=True)))
        vec.append((p_on, _named("open_drive/local_road_coordinates",
                                 _vector(lay, [r["road_s"], r["road_t"]], idx), vec=True)))
        facts = r["facts"]
        if facts is not None:
            lp = facts["lane_position"][idx]
            num.append((lay.mask(on & np.isfinite(lp)), _named("open_drive/lane_position", [lay.floats(lp)])))
            road_user = lay.mask(on & r["road_class"][idx])
            text.append((road_user, _named("road/classification",
                                           [lay.text(texts(facts["classification"][idx].tolist()))])))
            for side in ("left", "right"):
                for kind, key in (("legal", f"{side}_legal"), ("physical", f"{side}_phys")):
                    num.append((road_user, _named(f"road/number_lanes/{side}/{kind}",
                                                  [lay.ints(facts[key][idx])])))
    for c, name in LIGHTS.items():
        a = r["lights"].get(c)
        if a is not None:
            a = a[idx]
            boolean.append((lay.mask(np.isfinite(a)), _named(name, [lay.booleans(a >= 0.5)])))
    _irregular(r, idx, pid, lay, vec, num, boolean)
    segments = [lay.coded(*before), b'"', lay.ints(pid), b'":{"object_data":{"cuboid":[{"name":"bounding_box","val":[',
                *_vector(lay, r["box"], idx), b"]", *_extension(r, idx, lay), b"}],",
                lay.join(b'"vec":[', vec, b"]"), b",", lay.join(b'"boolean":[', boolean, b"]"), b",",
                lay.join(b'"num":[', num, b"]"), b",", lay.join(b'"text":[', text, b"]"), b"}}",
                lay.coded(*after)]
    return lay.packed(segments)


def _irregular(r: dict[str, Any], idx: np.ndarray, pid: np.ndarray, lay: _Layout, vec: list,
               num: list, boolean: list) -> None:
    """Interior signals and ``impact`` attributes: by (participant, time), only in the rows that
    have them (each a ready fragment of comma-separated list items)."""
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
                    bl.append({"name": LONGITUDINAL, "val": bool(irow[c] >= 0.5)})
            for c, name in (("steering_angle", "interior/steering_angle"),
                            ("steering_angle_std", "interior/steering_angle/ustddev"),
                            ("brake_pedal", "interior/brake_pedal"),
                            ("accelerator_pedal", "interior/accelerator_pedal"),
                            ("gear", "interior/gear")):
                if irow.get(c) is not None:
                    nl.append({"name": name, "val": irow[c] if c == "gear" else float(irow[c])})
            b_int[j] = b",".join(dumps(x) for x in bl)
            n_int[j] = b",".join(dumps(x) for x in nl)
        imp = impact.get(key) if impact else None
        if imp:
            items = []
            for k in ("gttc", "pret", "thw"):
                if imp.get(f"{k}/values"):
                    items.append({"name": f"impact/{k}/object_ids", "val": imp[f"{k}/object_ids"]})
                    items.append({"name": f"impact/{k}/values", "val": imp[f"{k}/values"]})
            v_imp[j] = b",".join(dumps(x) for x in items)
    for target, frags in ((vec, v_imp), (boolean, b_int), (num, n_int)):
        a = np.array(frags, dtype=object)
        target.append((lay.mask(a != b""), [lay.text(a)]))


def _extension(r: dict[str, Any], idx: np.ndarray, lay: _Layout) -> list:
    """Segments of ``,"aveas_format":{...}`` where the row has extension values (the states'
    columns the profile lacks, placeholders of null profile columns, exact values), else none."""
    ext = r["ext"]
    if ext is None:
        return []
    members: list = []
    ix = pa.array(idx)

    def member(c: str, token: int, mask: np.ndarray | None) -> None:
        members.append((lay.mask(mask), [b'"' + c.encode() + b'":', token]))

    for c, col in ext["columns"].items():
        valid, token = _column_fragments(col.take(ix), lay)
        member(c, token, valid)
    for c, isnull in ext["nullable"].items():
        member(c, lay.text(b"null"), isnull[idx])
    for c, vals in ext["exact"].items():
        v = vals[idx]
        member(c, lay.floats(v), ~np.isnan(v))
    if not members:
        return []
    return [lay.join(b',"' + EXT.encode() + b'":{', members, b"}", empty=b"")]


def _column_fragments(col: pa.ChunkedArray | pa.Array, lay: _Layout) -> tuple[np.ndarray, int]:
    """A states column's values as a value of ``lay`` (``(valid, token)``): numbers vectorised,
    other types through their Python values (as the extension block has them)."""
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
            return valid, lay.floats(a.astype(np.float64))  # float32 as its float64 value
        return valid, lay.ints(a)
    if pa.types.is_boolean(t):
        return valid, lay.booleans(col.fill_null(False).to_numpy(zero_copy_only=False))
    return valid, lay.text([dumps(v) if v is not None else b"" for v in col.to_pylist()])


__all__ = ["CHUNK_ROWS", "dumps", "frame_chunks", "numbers", "texts"]
