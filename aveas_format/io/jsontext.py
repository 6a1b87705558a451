"""JSON text of columns, a chunk of rows at once: the hot path of a streamed JSON export.

No dict per row: each part of a row's JSON is a column of fragments built for all rows at once —
numbers formatted by one ``orjson.dumps`` of a numpy array (split per row), strings through a
cache of their distinct values, optional items present where their mask says — and the
fragments are put together by Arrow (:class:`Layout`: an element-wise join of each template's
constants and columns, no Python step per value or row). Without orjson (``pip install
aveas-format[fast]``) the same values come from the standard library's encoder, about 2x slower.
(The OpenLABEL export's frames: :mod:`aveas_format.converters.openlabel.encode`.)
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.io.tablejson import json_safe

try:  # the fast JSON encoder (extra ``fast``); the standard library's otherwise
    import orjson
except ImportError:  # pragma: no cover - exercised by a test that hides it
    orjson = None


def dumps(v: Any) -> bytes:
    """Compact JSON of a Python value as :func:`~aveas_format.io.tablejson.json_safe`
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


class Layout:
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

    def arrow(self, col: pa.ChunkedArray | pa.Array) -> tuple[np.ndarray, int]:
        """An Arrow column as a value (``(valid, token)``): numbers vectorised (float32 as its
        float64 value), other types through their Python values (:func:`dumps`)."""
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
                return valid, self.floats(a.astype(np.float64))  # float32 as its float64 value
            return valid, self.ints(a)
        if pa.types.is_boolean(t):
            return valid, self.booleans(col.fill_null(False).to_numpy(zero_copy_only=False))
        return valid, self.text([dumps(v) if v is not None else b"" for v in col.to_pylist()])

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


__all__ = ["Layout", "dumps", "numbers", "orjson", "texts"]
