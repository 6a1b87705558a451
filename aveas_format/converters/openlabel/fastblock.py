"""A block of OpenLABEL frames into box columns without a Python object per value (the import's
fast path).

:func:`read_block` takes the bytes of a block of whole frames (``{"key":{...},...}``, as
:func:`~.stream._fast_frames` cuts them) and:

1. indexes its structure with numpy: the quotes that are not escaped, the brackets outside strings
   and their depth (a cumulative sum); the boxes are the objects one level under a frame's
   ``objects`` member, each with its byte span;
2. parses the *skeleton* with orjson — the block with every box replaced by its row number — which
   checks the structure around the boxes and gives the frame keys, ``frame_properties`` and, per
   frame, the object uids (with the JSON semantics of repeated keys);
3. parses the boxes' spans, joined as newline-delimited JSON, with Arrow's C++ JSON reader against
   the AVEAS profile's layout (:data:`BOX_SCHEMA`: the cuboid with its ``aveas_format`` extension
   item, the ``boolean``/``num``/``text``/``vec`` attribute lists);
4. takes the attributes the import reads by name, in bulk (:class:`ArrowAttributes`), into the same
   columns :func:`~.columns.block_columns` builds from parsed boxes.

Where numba is installed, :func:`read_block` first hands the block to the compiled reader
(:mod:`._jitblock`, via :func:`compiled_parser`): one validating pass over the bytes gives the same
columns through the same by-name selection (:class:`ArrowAttributes` built from its arrays,
:func:`_read_block_jit`) at about a third of the cost per box; Arrow's reader takes the blocks it
refuses.

It verifies what it assumes and returns None where a block does not fit (a box without the
profile's ``bounding_box`` cuboid first, a rotated or non-root cuboid, a value of another type than
the profile's, an unexpected member, a ``null`` in a box, a repeated object uid in a frame,
``interior/`` attributes, NaN...): the caller then parses that block with orjson and the generic
path (:mod:`.columns`), which gives the same columns and the exact error where there is one.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.openlabel.columns import block_findings, vector_columns
from aveas_format.converters.openlabel.profile import EXT, LIGHTS, _enum_value

try:
    import orjson
except ImportError:  # pragma: no cover - the fast path needs the [fast] extra
    orjson = None


def _attr(val: pa.DataType) -> pa.DataType:
    return pa.list_(pa.struct([("name", pa.string()), ("val", val)]))


#: the kinds of attributes in the order :func:`~.profile._first` searches them, with their value type
KINDS = (("boolean", pa.bool_()), ("num", pa.float64()), ("text", pa.string()),
         ("vec", pa.list_(pa.float64())))
#: the layout of one box (an object in a frame) of the AVEAS profile; the extension item's members
#: are inferred (they are this library's state columns)
BOX_SCHEMA = pa.schema([("object_data", pa.struct([
    ("cuboid", pa.list_(pa.struct([("name", pa.string()), ("val", pa.list_(pa.float64())),
                                   ("coordinate_system", pa.string())]))),
    *((kind, _attr(t)) for kind, t in KINDS)]))])
#: the attributes the import reads, with the kind the profile gives them (found in another kind:
#: the generic path reads the block)
READ_KIND = {"velocity": "vec", "acceleration": "vec", "bounding_box/ustddev": "vec",
             "velocity/ustddev": "vec", "acceleration/ustddev": "vec",
             "open_drive/local_road_coordinates": "vec", "used_road_link": "text",
             "open_drive/road_id": "text", "open_drive/lane_id": "text", "open_drive/lane_position": "num",
             **{name: "boolean" for name in LIGHTS.values()}}

#: bytes of boxes per Arrow parse task: a block is one task (A/B on the sample, load 8: best of 3
#: 1.28 s; 1.38 s with 1 MiB tasks, 1.52 s with 512 KiB — threads within a block do not pay here)
ARROW_BLOCK = 1 << 22
_OBJECTS_KEY = b'"objects"'
_NEWLINES = bytes.maketrans(b"\r\n", b"  ")


class _NotFast(Exception):
    """The block does not fit the fast path: the generic path reads it."""


def _structure(buf: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(positions, depths, kinds, quote positions)`` of the brackets outside strings (depth after an
    opening bracket, before a closing one; 1 = the block's own braces) and the unescaped quotes."""
    a = np.frombuffer(buf, np.uint8)
    f = a | 0x20  # '[' -> '{', ']' -> '}'
    idx = np.flatnonzero((a == 34) | (f == 0x7B) | (f == 0x7D))
    k = a[idx]
    isq = k == 34
    if buf.find(b"\\") >= 0:  # quotes after an odd run of backslashes are inside strings
        qpos = idx[isq]
        prev = np.flatnonzero(a[np.maximum(qpos - 1, 0)] == 92)
        esc = np.zeros(len(qpos), bool)
        for i in prev.tolist():
            j, run = int(qpos[i]) - 1, 0
            while j >= 0 and buf[j] == 92:
                run, j = run + 1, j - 1
            esc[i] = run % 2 == 1
        if esc.any():
            drop = np.flatnonzero(isq)[esc]
            keep = np.ones(len(idx), bool)
            keep[drop] = False
            idx, k, isq = idx[keep], k[keep], isq[keep]
    instr = (np.cumsum(isq, dtype=np.uint8) & 1).astype(bool)  # (opening quote: 1; closing: 0)
    if instr[-1:].any():
        raise _NotFast
    if buf.find(b"\n") >= 0 or buf.find(b"\r") >= 0:  # a raw line break in a string: broken JSON
        nl = np.flatnonzero((a == 10) | (a == 13))
        if (np.searchsorted(idx[isq], nl) & 1).any():
            raise _NotFast
    br = ~isq & ~instr
    pos, kb = idx[br], k[br]
    step = np.where((kb | 0x20) == 0x7B, np.int8(1), np.int8(-1))
    depth = np.cumsum(step, dtype=np.int32)
    depth[step < 0] += 1
    return pos, depth, step, idx[isq]


def _box_spans(buf: bytes, structure: tuple | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The byte spans ``[start, end)`` of the objects directly under a frame's ``objects`` member
    (``structure``: :func:`_structure` of ``buf`` where the caller has it)."""
    pos, depth, step, quotes = structure or _structure(buf)
    if not _closed(depth, step) or step[0] != 1:
        raise _NotFast
    # the containers one level under a frame (its members' values): which are "objects"
    c3 = np.flatnonzero((depth == 3) & (step > 0))
    qi = np.searchsorted(quotes, pos[c3])  # the key's closing quote is quotes[qi - 1]
    is_obj = np.zeros(len(c3), bool)
    for i, (q, p) in enumerate(zip(qi.tolist(), pos[c3].tolist())):
        if q >= 2 and buf[quotes[q - 2]:quotes[q - 1] + 1] == _OBJECTS_KEY \
                and not buf[quotes[q - 1] + 1:p].strip(b" \t\r\n:"):
            is_obj[i] = True
    opens = np.flatnonzero((depth == 4) & (step > 0))
    closes = np.flatnonzero((depth == 4) & (step < 0))
    if len(opens) != len(closes):
        raise _NotFast
    owner = np.searchsorted(c3, opens) - 1  # the depth-3 container each depth-4 one is in
    if (owner < 0).any():
        raise _NotFast
    sel = is_obj[owner] & (np.frombuffer(buf, np.uint8)[pos[opens]] == 0x7B)
    if not is_obj.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # an array value under "objects" (or anything but objects) is not a box: the generic path
    if not (is_obj[owner] <= sel).all():
        raise _NotFast
    return pos[opens][sel], pos[closes][sel] + 1


class FastBlock:
    """A block of frames read by :func:`read_block`: ``frames`` as ``(key, frame)`` with each
    frame's ``objects`` mapping uid -> row, the rows' columns (:func:`box_columns`) and what the
    checks of the source found (:func:`~.columns.block_findings`, the profile's mandatory
    attributes included: the caller keeps those for files that claim the profile). numpy arrays,
    lists of numbers and the frames' skeleton: cheap to hand back from a worker process."""

    def __init__(self, frames: list, cols: dict[str, np.ndarray], ext: dict[str, tuple],
                 found: list[tuple[str, str, int, int]], depth: int) -> None:
        self.frames, self.cols, self.ext, self.found = frames, cols, ext, found
        #: the deepest nesting of containers in the block (its own braces: 1)
        self.depth = depth
        #: the block's size in bytes (:func:`read_block`; for the reader's estimate of the rows)
        self.nbytes = 0
        #: where the worker that read it spilled its columns (:func:`.spill.write_rows`; ``cols``
        #: and ``ext`` then empty), else None
        self.spilled: tuple[str, int, int] | None = None

    def spill_to(self, path: Path) -> None:
        """The columns and extension members written to ``path`` (:func:`.spill.write_rows`) and
        dropped here, where they can be spilled exactly."""
        from aveas_format.converters.openlabel.spill import write_rows

        got = write_rows(path, self.cols, self.ext)
        if got is not None:
            self.spilled, self.cols, self.ext = got, {}, {}


def read_block(buf: bytes | np.ndarray, threads: bool = True, compiled: bool = True) -> FastBlock | None:
    """The block ``buf`` (``{"key":{frame},...}``; or as a uint8 array followed by one NUL byte:
    :func:`padded`) as a :class:`FastBlock`, or None where it does not fit the fast path (see the
    module's doc). ``threads``: Arrow's reader on its thread pool. With ``compiled``, where numba
    is installed (:func:`aveas_format.numeric.kernel_backend`), the compiled reader
    (:mod:`._jitblock`) reads the block, Arrow's reader where that one does not take it."""
    if orjson is None:
        return None
    try:
        parse = compiled_parser() if compiled else None
        blk = None
        if parse is not None:
            blk = _read_block_jit(buf if isinstance(buf, np.ndarray) else padded(buf), parse)
        if blk is None:
            blk = _read_block(buf[:-1].tobytes() if isinstance(buf, np.ndarray) else buf, threads)
        if blk is not None:
            blk.nbytes = len(buf)
        return blk
    except (_NotFast, pa.ArrowInvalid, pa.ArrowTypeError, orjson.JSONDecodeError, KeyError, IndexError,
            TypeError, ValueError):
        return None


def padded(buf: bytes) -> np.ndarray:
    """``buf`` as the compiled reader takes it: uint8, one NUL byte after it; writable, as the
    worker processes' block buffer is (numba compiles a reader per argument type: one type, one
    compile)."""
    out = np.empty(len(buf) + 1, np.uint8)
    out[:-1] = np.frombuffer(buf, np.uint8)
    out[-1] = 0
    return out


_LOCAL = threading.local()


def compiled_parser():
    """The compiled reader where the numba path runs, else None: ``parse(b)`` of a :func:`padded`
    block gives :func:`._jitblock.parse_block`'s status, depth and arrays, the used rows only
    (views of this thread's scratch arrays, reused by the next call). numba and the reader are
    imported, and compiled or loaded from numba's cache, on the first call in a process."""
    from aveas_format.numeric import kernel_backend

    try:
        if kernel_backend() != "numba":
            return None
    except (ValueError, ImportError):  # (a kernel asked for that is not there: Arrow's reader)
        return None
    from aveas_format.converters.openlabel import _jitblock as jb

    _compiled_once(jb)

    def parse(b: np.ndarray) -> tuple:
        sc = getattr(_LOCAL, "scratch", None) or jb.scratch(len(b))
        r = jb.parse_block(b, *sc)
        _LOCAL.scratch = r[8:]
        status, depth, nb, ni, ne, nn, ns, nt = r[:8]
        boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff, _, _ = r[8:]
        return (status, depth, boxes[:nb], items[:ni], ext[:ne], nbuf[:noff[nn]], noff[:nn + 1],
                sbuf[:soff[ns]], soff[:ns + 1], tbuf[:toff[nt]], toff[:nt + 1])

    return parse


#: a block of one box: what :func:`_compiled_once` reads to compile the reader's functions
_SMALL = (b'{"0":{"frame_properties":{"timestamp":0.0},"objects":{"1":{"object_data":{"cuboid":'
          b'[{"name":"bounding_box","val":[0,0,0,0,0,0,1,1,1],"aveas_format":{"vx":1.0}}],'
          b'"vec":[{"name":"velocity","val":[1.0,0,0,0,0,0]}]}}}}}')
_READY = False


def _compiled_once(jb) -> None:
    """The compiled reader's functions compiled, or loaded from numba's cache, once per process
    (called before the import forks its workers, :func:`.stream._read_blocks`: they inherit
    them; before, only the module was loaded there and each worker compiled on its first block,
    ~30 s and ~900 MB each at once on a fresh install) and by one process at a time (an
    exclusive lock on a file in the temporary directory, where ``fcntl`` is there: processes
    starting together — two imports, spawned workers — the first compiles and caches them, the
    others wait and load them, ~0.2 s)."""
    global _READY
    if _READY:
        return
    import tempfile

    def compile_() -> None:
        b = padded(_SMALL)
        r = jb.parse_block(b, *jb.scratch(len(b)))
        if r[0] == 0:  # (the skeleton's and the attributes' functions too)
            jb.skeleton(b[:-1], r[8][:r[2]])
            jb.first_items(r[9][:r[3]], np.zeros(8, np.int64), np.zeros(1, np.int64), int(r[2]))

    try:
        import fcntl
    except ImportError:
        fcntl = None
    lock = Path(tempfile.gettempdir()) / f"aveas-format-jitblock-{getattr(os, 'getuid', lambda: 0)()}.lock"
    try:
        f = open(lock, "a") if fcntl is not None else None
    except OSError:
        f = None
    try:
        if f is not None:
            fcntl.flock(f, fcntl.LOCK_EX)
        compile_()
    finally:
        if f is not None:
            f.close()  # (the lock goes with the file)
    _READY = True


def block_depth(buf: bytes) -> int | None:
    """The deepest nesting of containers in a block of frames ``{...}`` (its own braces: 1), None
    where its strings or brackets do not balance."""
    try:
        _, depth, step, _ = _structure(buf)
    except _NotFast:
        return None
    return int(depth.max()) if _closed(depth, step) else None


def _closed(depth: np.ndarray, step: np.ndarray) -> bool:
    """Whether the brackets of :func:`_structure` make one container: never below its own level,
    closed by the last one."""
    return bool(len(depth)) and depth.min() >= 1 and depth[-1] == 1 and step[-1] == -1


def _read_block(buf: bytes, threads: bool = True) -> FastBlock | None:
    structure = _structure(buf)
    starts, ends = _box_spans(buf, structure)
    n = len(starts)
    if n == 0:
        return None
    sl, el = starts.tolist(), ends.tolist()
    frames = _skeleton(_skeleton_bytes(buf, sl, el), n)
    if frames is None:
        return None
    if b"\n" in buf or b"\r" in buf:  # (outside strings: _structure checked) whitespace
        buf = buf.translate(_NEWLINES)
    boxes = b"\n".join([buf[s:e] for s, e in zip(sl, el)])
    if b"null" in boxes:  # (a null member would read as an absent one)
        return None
    if not boxes.isascii():
        boxes.decode("utf-8")  # (UnicodeDecodeError is a ValueError: the generic path names it)
    import pyarrow.json as pj

    table = pj.read_json(pa.py_buffer(boxes), read_options=pj.ReadOptions(use_threads=threads, block_size=ARROW_BLOCK),
                         parse_options=pj.ParseOptions(explicit_schema=BOX_SCHEMA,
                                                       unexpected_field_behavior="infer"))
    if table.num_rows != n:
        return None
    cols, ext, at = box_columns(table)
    return FastBlock(frames, cols, ext, block_findings(at, profile=True), int(structure[1].max()))


def _skeleton_bytes(buf: bytes, sl: list[int], el: list[int]) -> bytes:
    """The block ``buf`` with its boxes (spans ``sl``, ``el``) replaced by their row numbers."""
    parts, prev = [], 0
    for r, (s, e) in enumerate(zip(sl, el)):
        parts += (buf[prev:s], b"%d" % r)
        prev = e
    parts.append(buf[prev:])
    return b"".join(parts)


def _skeleton(skel: Any, n: int) -> list | None:
    """``(key, frame)`` of a block's skeleton ``skel`` (its ``n`` boxes replaced by their row
    numbers: :func:`_skeleton_bytes`), parsed by orjson (which checks everything around the
    boxes); None where a uid is repeated in a frame or a frame key in the block (the generic
    path: JSON's semantics)."""
    block = orjson.loads(skel)
    if not isinstance(block, dict):
        return None
    frames, seen = [], 0
    for k, fr in block.items():
        if not isinstance(fr, dict):
            return None
        objs = fr.get("objects")
        if objs is not None:
            if not isinstance(objs, dict) or set(map(type, objs.values())) - {int}:
                return None
            seen += len(objs)
        frames.append((k, fr))
    rows = [r for _, fr in frames for r in (fr.get("objects") or {}).values()]
    return frames if seen == n and rows == list(range(n)) else None


# ------------------------------------------------------------------------------------------------

class ArrowAttributes:
    """The attribute items of a block's boxes by kind (Arrow lists of ``{name, val}``), read by name
    as :class:`~.columns._Attributes` does: per box the first item of a name (kinds in the order
    boolean, num, text, vec)."""

    def __init__(self, parts: dict[str, tuple[np.ndarray, np.ndarray, list[str], pa.Array]], n: int) -> None:
        """``parts``: per kind (in :data:`KINDS`' order) ``(box of each item, code of its name,
        the names, values)``, the items in box order."""
        self.n = n
        self.kinds: dict[str, tuple[np.ndarray, np.ndarray, pa.Array, dict[str, int]]] = {}
        self.code_of: dict[str, None] = {}
        for kind, (parent, codes, names, vals) in parts.items():
            self.kinds[kind] = (parent, codes, vals, {s: i for i, s in enumerate(names)})
            self.code_of.update(dict.fromkeys(names))
        for name, kind in READ_KIND.items():  # an attribute the import reads, in another kind
            if any(name in codes for k, (_, _, _, codes) in self.kinds.items() if k != kind):
                raise _NotFast

    @classmethod
    def from_object_data(cls, od: pa.StructArray, n: int) -> ArrowAttributes:
        """From the ``object_data`` column of Arrow's reader (:data:`BOX_SCHEMA`)."""
        parts = {}
        for kind, _ in KINDS:
            lists = od.field(kind)
            if lists.null_count == len(lists) or len(lists.values) == 0:
                continue
            items = lists.flatten()
            names = items.field("name")
            if items.null_count or names.null_count:
                raise _NotFast
            enc = names.dictionary_encode()
            parts[kind] = (pc.list_parent_indices(lists).to_numpy(), enc.indices.to_numpy(),
                           enc.dictionary.to_pylist(), items.field("val"))
        return cls(parts, n)

    def _first_in(self, kind: str, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(boxes, item index)`` of the first item of ``name`` per box in ``kind``."""
        parent, codes, _, code_of = self.kinds[kind]
        sel = np.flatnonzero(codes == code_of[name])
        boxes = parent[sel]
        if len(boxes) > 1 and not (boxes[1:] > boxes[:-1]).all():  # a name twice in a box
            boxes, first = np.unique(boxes, return_index=True)
            sel = sel[first]
        return boxes, sel

    def first_items(self, name: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """Per kind holding ``name``: ``(kind, boxes, item indices)``, the boxes of an earlier kind
        taken out of the later ones."""
        out, taken = [], np.zeros(self.n, bool)
        for kind, (_, _, _, code_of) in self.kinds.items():
            if name in code_of:
                boxes, sel = self._first_in(kind, name)
                fresh = ~taken[boxes]
                boxes, sel = boxes[fresh], sel[fresh]
                taken[boxes] = True
                out.append((kind, boxes, sel))
        return out

    def first(self, name: str) -> tuple[np.ndarray, list]:
        """``(boxes that have the name, the first such item's value per box)`` (Python values: for
        the few checks that read them, e.g. the PMFs)."""
        parts = self.first_items(name)
        if not parts:
            return np.zeros(0, np.int64), []
        boxes = np.concatenate([b for _, b, _ in parts])
        vals = [v for kind, _, sel in parts for v in self.kinds[kind][2].take(pa.array(sel)).to_pylist()]
        order = np.argsort(boxes, kind="stable")
        return boxes[order], [vals[i] for i in order.tolist()]

    def first_boxes(self, name: str) -> np.ndarray:
        """The boxes that have an item of ``name`` (in no particular order)."""
        parts = self.first_items(name)
        return np.concatenate([b for _, b, _ in parts]) if parts else np.zeros(0, np.int64)

    def boxes_with(self, names: list[str]) -> np.ndarray:
        found = [b for nm in names for _, b, _ in self.first_items(nm)]
        return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)

    def values(self, name: str) -> tuple[np.ndarray, pa.Array] | None:
        """``(boxes, values)`` of the first item of ``name`` per box (its kind is the profile's)."""
        kind = READ_KIND[name]
        if kind not in self.kinds or name not in self.kinds[kind][3]:
            return None
        boxes, sel = self._first_in(kind, name)
        return boxes, self.kinds[kind][2].take(pa.array(sel))

    def vector(self, name: str, elems: tuple[int, ...]) -> tuple[np.ndarray, list[np.ndarray]]:
        """As :meth:`~.columns._Attributes.vector`: ``(has a non-null value, per element the value
        or NaN)``."""
        n = self.n
        has = np.zeros(n, bool)
        cols = [np.full(n, np.nan) for _ in elems]
        got = self.values(name)
        if got is None:
            return has, cols
        boxes, vals = got
        has[boxes[vals.is_valid().to_numpy(zero_copy_only=False)]] = True
        lens = pc.list_value_length(vals).fill_null(0).to_numpy()
        offs = vals.offsets.to_numpy()[:-1]  # (into .values, whatever the array's offset)
        flat = vals.values.fill_null(np.nan).to_numpy(zero_copy_only=False)
        for c, e in zip(cols, elems):
            m = lens > e
            c[boxes[m]] = flat[offs[m] + e]
        return has, cols

    def texts(self, name: str) -> np.ndarray:
        """Per box the first text of ``name`` (None where absent) as an object array."""
        return _texts(self.n, self.values(name))

    def floats(self, name: str) -> np.ndarray:
        """Per box the first number / boolean of ``name`` as a float (NaN where absent or null)."""
        out = np.full(self.n, np.nan)
        got = self.values(name)
        if got is not None:
            boxes, vals = got
            if pa.types.is_boolean(vals.type):
                vals = pc.cast(vals, pa.float64())
            out[boxes] = vals.fill_null(np.nan).to_numpy(zero_copy_only=False)
        return out


def _texts(n: int, got: tuple[np.ndarray, pa.Array] | None) -> np.ndarray:
    """The texts ``got`` = ``(boxes, values)`` per box of ``n`` (None elsewhere) as an object array
    (each distinct text one Python string)."""
    out = np.full(n, None, object)
    if got is not None:
        boxes, vals = got
        enc = vals.dictionary_encode()
        distinct = np.empty(len(enc.dictionary) + 1, object)
        distinct[:-1] = enc.dictionary.to_pylist()
        out[boxes] = distinct[enc.indices.fill_null(-1).to_numpy()]
    return out


#: the kinds' codes (:data:`KINDS`' order: the compiled reader's)
KIND_CODE = {kind: k for k, (kind, _) in enumerate(KINDS)}


class CompiledAttributes:
    """The compiled reader's attribute items (rows ``[box, kind, name, value, count]``) read by name
    as :class:`ArrowAttributes` reads them (the same methods, the same results), the first item of
    each name the import or its checks read found per box in one compiled pass
    (:func:`._jitblock.first_items`) instead of Arrow lists per kind."""

    def __init__(self, items: np.ndarray, names: np.ndarray, nums: np.ndarray, strs: pa.Array,
                 n: int) -> None:
        from aveas_format.converters.openlabel._jitblock import first_items

        self.n, self.items, self.nums, self.strs = n, items, nums, strs
        codes = _used_codes(items[:, 2], len(names))[0]
        index = dict(zip(names[codes].tolist(), codes.tolist()))
        self.code_of = dict.fromkeys(index)
        self.slot = {nm: k for k, nm in enumerate(
            nm for nm in index if nm in READ_KIND or nm.endswith("/uncertainties"))}
        slot_of_code = np.full(len(names), -1, np.int64)
        want = np.full(len(self.slot), -1, np.int64)
        for nm, k in self.slot.items():
            slot_of_code[index[nm]] = k
            if nm in READ_KIND:
                want[k] = KIND_CODE[READ_KIND[nm]]
        self.first_rows, mixed = first_items(items, slot_of_code, want, n)
        if mixed:  # (an attribute the import reads, in another kind: the generic path)
            raise _NotFast

    def _rows(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(boxes with an item of name, the row of its first item)``."""
        k = self.slot.get(name)
        if k is None:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        f = self.first_rows[k]
        boxes = np.flatnonzero(f >= 0)
        return boxes, f[boxes]

    def first(self, name: str) -> tuple[np.ndarray, list]:
        boxes, rows = self._rows(name)
        it = self.items[rows]
        vals = [None] * len(rows)
        for kind, get in (("boolean", lambda r: r[:, 3].astype(bool).tolist()),
                          ("num", lambda r: self.nums[r[:, 3]].tolist()),
                          ("text", lambda r: self.strs.take(pa.array(r[:, 3])).to_pylist()),
                          ("vec", lambda r: [self.nums[a:a + c].tolist() for a, c in r[:, 3:5].tolist()])):
            at = np.flatnonzero(it[:, 1] == KIND_CODE[kind])
            for i, v in zip(at.tolist(), get(it[at])):
                vals[i] = v
        return boxes, vals

    def first_boxes(self, name: str) -> np.ndarray:
        return self._rows(name)[0]

    def values(self, name: str) -> tuple[np.ndarray, pa.Array] | None:
        boxes, rows = self._rows(name)
        if not len(boxes):
            return None
        ref = self.items[rows, 3]
        kind = READ_KIND[name]
        if kind == "text":
            return boxes, self.strs.take(pa.array(ref))
        return boxes, pa.array(ref.astype(bool) if kind == "boolean" else self.nums[ref])

    def vector(self, name: str, elems: tuple[int, ...]) -> tuple[np.ndarray, list[np.ndarray]]:
        n = self.n
        has = np.zeros(n, bool)
        cols = [np.full(n, np.nan) for _ in elems]
        boxes, rows = self._rows(name)
        has[boxes] = True
        ref, count = self.items[rows, 3], self.items[rows, 4]
        for c, e in zip(cols, elems):
            m = count > e
            c[boxes[m]] = self.nums[ref[m] + e]
        return has, cols

    def texts(self, name: str) -> np.ndarray:
        return _texts(self.n, self.values(name))

    floats = ArrowAttributes.floats


def _ext_reps(cub: pa.StructArray) -> dict[str, tuple]:
    """The extension items (``aveas_format`` of the cuboids; no nulls in the block, so a null is an
    absent member) as :func:`~.columns.ext_rep` columns."""
    from aveas_format.converters.openlabel.columns import _MISSING

    names = [cub.type.field(i).name for i in range(cub.type.num_fields)]
    if EXT not in names:
        return {}
    ext = cub.field(EXT)
    if not pa.types.is_struct(ext.type):
        raise _NotFast
    out: dict[str, tuple] = {}
    absent_box = ~ext.is_valid().to_numpy(zero_copy_only=False)
    for i in range(ext.type.num_fields):
        name = ext.type.field(i).name
        col = ext.field(i)
        present = col.is_valid().to_numpy(zero_copy_only=False) & ~absent_box
        if pa.types.is_floating(col.type):
            out[name] = ("f", col.fill_null(np.nan).to_numpy(zero_copy_only=False).astype(float),
                         present, np.zeros(len(col), bool))
        elif pa.types.is_null(col.type):
            continue
        elif pa.types.is_nested(col.type):
            raise _NotFast  # (lists or objects in the extension item: the generic path)
        else:
            vals = np.empty(len(col), object)
            vals[:] = col.to_pylist()
            vals[~present] = _MISSING
            out[name] = ("o", vals)
    return out


def box_columns(table: pa.Table) -> tuple[dict[str, np.ndarray], dict[str, tuple], ArrowAttributes]:
    """``(columns, ext columns, attributes)`` of a block's boxes, as
    :func:`~.columns.block_columns` and :func:`~.columns.ext_chunk` give them for the same boxes
    (the sizes are the columns ``dl``, ``dw``, ``dh``)."""
    n = table.num_rows
    if table.schema.names != ["object_data"]:
        raise _NotFast
    od = table.column("object_data").combine_chunks()
    if od.null_count or od.type.num_fields != len(BOX_SCHEMA.field("object_data").type):
        raise _NotFast  # (an inferred member of object_data: a type, a bbox...)
    cubl = od.field("cuboid")
    if cubl.null_count or (pc.list_value_length(cubl).to_numpy() < 1).any():
        raise _NotFast
    cub = pc.list_element(cubl, 0)
    if cub.null_count:
        raise _NotFast
    known = {"name", "val", "coordinate_system", EXT}
    if {cub.type.field(i).name for i in range(cub.type.num_fields)} - known:
        raise _NotFast  # (cuboid attributes, e.g. a per-box timestamp: the generic path)
    if cub.field("coordinate_system").null_count != n or \
            not pc.all(pc.equal(cub.field("name"), "bounding_box")).as_py():
        raise _NotFast
    val = cub.field("val")
    if val.null_count or (pc.list_value_length(val).to_numpy() != 9).any():
        raise _NotFast
    if val.flatten().null_count:
        raise _NotFast
    cols = _cuboid_columns(val.flatten().to_numpy(zero_copy_only=False).reshape(n, 9))
    at = ArrowAttributes.from_object_data(od, n)
    return _attribute_columns(at, cols), _ext_reps(cub), at


def _cuboid_columns(V: np.ndarray) -> dict[str, np.ndarray]:
    """The columns of the boxes' cuboids (``V``: their 9 values per row, not rotated)."""
    if (V[:, 3] != 0.0).any() or (V[:, 4] != 0.0).any():
        raise _NotFast  # (a rotated box: placed one at a time by the generic path)
    n = len(V)
    return {"px": V[:, 0].copy(), "py": V[:, 1].copy(), "pz": V[:, 2] - V[:, 8] / 2.0, "yaw": V[:, 5].copy(),
            "dl": V[:, 6].copy(), "dw": V[:, 7].copy(), "dh": V[:, 8].copy(),
            "csroot": np.full(n, None, object), "cub_ts": np.full(n, np.nan)}


def _attribute_columns(at: ArrowAttributes, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``cols`` with the columns the import reads from the boxes' attributes."""
    n = at.n
    if any(nm.startswith("interior/") for nm in at.code_of):
        raise _NotFast  # (the interior rows read the items as dicts: the generic path)
    hv, has_lrc, (rs, rt) = vector_columns(at, cols)
    road = at.texts("used_road_link")
    if "open_drive/road_id" in at.code_of:
        alt = at.texts("open_drive/road_id")
        road = np.where(np.equal(road, None), alt, road)
    has_road = ~np.equal(road, None)
    on = has_road & has_lrc
    cols["road_s"] = np.where(has_road, rs, np.nan)
    cols["road_t"] = np.where(has_road, rt, np.nan)
    cols["lane_position"] = at.floats("open_drive/lane_position")
    for c, name in LIGHTS.items():
        cols[c] = at.floats(name)
    road_id = np.full(n, None, object)
    road_id[on] = road[on]
    cols["road_id"] = road_id
    lane_id = np.full(n, None, object)
    got = at.values("open_drive/lane_id") if "open_drive/lane_id" in at.code_of else None
    if got is not None:  # (each distinct text converted once: Arrow's dictionary of them)
        boxes, vals = got
        enc = vals.dictionary_encode()
        conv = np.empty(len(enc.dictionary) + 1, object)  # (the last: a null text)
        conv[:-1] = [_lane_int(v) for v in enc.dictionary.to_pylist()]
        codes = enc.indices.fill_null(-1).to_numpy()
        ok = (codes >= 0) & has_road[boxes]
        lane_id[boxes[ok]] = conv[codes[ok]]
    cols["lane_id"] = lane_id
    cols["hv"], cols["hr"] = hv, on
    return cols


def _lane_int(v: str) -> Any:
    try:
        return int(str(_enum_value(v)))
    except ValueError:
        return None


# ------------------------------------------------------------------------------------------------
# the compiled reader's arrays into the same columns

def _packed(data: np.ndarray, offs: np.ndarray) -> pa.Array:
    """The packed texts of :func:`._jitblock.parse_block` as an Arrow string array."""
    return pa.Array.from_buffers(pa.large_string(), len(offs) - 1, [None, pa.py_buffer(offs), pa.py_buffer(data)])


def _read_block_jit(b: np.ndarray, parse) -> FastBlock | None:
    """The block ``b`` (:func:`padded`) read by the compiled parser ``parse``
    (:func:`compiled_parser`), or None (not the profile's layout, broken: the other paths read it
    or name the error). Nothing it returns refers to the parser's scratch arrays."""
    from aveas_format.converters.openlabel._jitblock import skeleton

    if b.max(initial=0) > 127:
        b[:-1].tobytes().decode("utf-8")  # (UnicodeDecodeError is a ValueError: the generic path names it)
    status, depth, boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff = parse(b)
    n = len(boxes)
    if status or not n:
        return None
    frames = _skeleton(memoryview(skeleton(b[:-1], boxes)), n)
    if frames is None:
        return None
    ntext = _packed(nbuf, noff)
    nums = pc.cast(ntext, pa.float64()).to_numpy(zero_copy_only=False)
    names = np.asarray(_packed(tbuf, toff).to_pylist(), object)
    strs = _packed(sbuf, soff)
    cols = _cuboid_columns(nums[boxes[:, 2, None] + np.arange(9)])
    at = CompiledAttributes(items, names, nums, strs, n)
    cols = _attribute_columns(at, cols)
    return FastBlock(frames, cols, _ext_columns(ext, n, nums, ntext, names, strs),
                     block_findings(at, profile=True), int(depth))


def _ext_columns(ext: np.ndarray, n: int, nums: np.ndarray, ntext: pa.Array, names: np.ndarray,
                 strs: pa.Array) -> dict[str, tuple]:
    """The extension items' members (rows ``[box, key, kind, value]`` of the compiled parser) as
    :func:`~.columns.ext_rep` columns: as a JSON parser gives them — a number with a fraction or
    an exponent a float, else an int; ``("f", ...)`` where every value of a key is a float."""
    from aveas_format.converters.openlabel import _jitblock as jb
    from aveas_format.converters.openlabel.columns import _MISSING

    if not len(ext):
        return {}
    keys, code = _used_codes(ext[:, 1], len(names))
    out: dict[str, tuple] = {}
    for c, key in enumerate(names[keys].tolist()):
        rows = np.flatnonzero(code == c)  # (in box order)
        bx, kind, ref = ext[rows, 0], ext[rows, 2], ext[rows, 3]
        if len(bx) > 1 and not (bx[1:] > bx[:-1]).all():
            raise _NotFast  # (a key twice in one extension item: JSON's last one wins, the generic path)
        present = np.zeros(n, bool)
        present[bx] = True
        if (kind == jb.E_FLOAT).all():
            vals = np.full(n, np.nan)
            vals[bx] = nums[ref]
            out[key] = ("f", vals, present, np.zeros(n, bool))
            continue
        vals = np.full(n, _MISSING, object)
        # (numpy arrays of scalars into the object array: Python bools, strs, floats and ints,
        # as a JSON parser gives them)
        for k, get in ((jb.E_TRUE, lambda r: True), (jb.E_FALSE, lambda r: False),
                       (jb.E_STR, lambda r: strs.take(pa.array(r)).to_numpy(zero_copy_only=False)),
                       (jb.E_FLOAT, lambda r: nums[r]),
                       # (an integer beyond int64: ArrowInvalid, the generic path)
                       (jb.E_INT, lambda r: pc.cast(ntext.take(pa.array(r)), pa.int64()).to_numpy())):
            m = kind == k
            if m.any():
                vals[bx[m]] = get(ref[m])
        out[key] = ("o", vals)
    return out


def _used_codes(codes: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(the codes < n that occur, ascending; each code's index among them)`` (as ``np.unique``
    with ``return_inverse``, without sorting)."""
    present = np.zeros(n, bool)
    present[codes] = True
    index = np.cumsum(present) - 1
    return np.flatnonzero(present), index[codes]
