"""The frames of an OpenLABEL file into per-box columns, and the geometry of generic files.

:class:`_FrameRows` takes the frames one ``(key, frame)`` at a time (streamed, or from a parsed
dict) and keeps per box the values of one state in numpy column chunks: the box centre and yaw in
the root coordinate system, the profile's velocity, acceleration, uncertainty, road, light and
interior attributes, and the box's ``aveas_format`` extension item; :meth:`_FrameRows.finish`
sorts them by frame into :class:`_FrameData`.

Generic files place cuboids in any coordinate system: :class:`_Frames` chains them to the root
through ``coordinate_systems`` ``pose_wrt_parent`` and per-frame ``frame_properties.transforms``
(:func:`_pose`: ``matrix4x4``, quaternion or Euler angles); :func:`_utm_crs` reads a UTM root's
zone from its name.
"""

from __future__ import annotations

import math
import os
import re
from collections import defaultdict
from itertools import chain, compress, repeat
from operator import is_not
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.converters.openlabel.columns import (_MISSING, as_obj, block_columns, block_findings, box_parts,
                                                       ext_chunk, split_boxes)
from aveas_format.converters.openlabel.profile import (LIGHTS, _LONGITUDINAL, _attrs,
                                                       _first)
from aveas_format.converters.openlabel.spill import read_rows
from aveas_format.errors import FormatError
from aveas_format.numeric import release_free_memory


# -- geometry of generic files -------------------------------------------------------------------

def _quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) or 1.0
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def _euler_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """ZYX (yaw, pitch, roll) — OpenLABEL's default sequence."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


def _axis_rotation(axis: str, angle: float) -> np.ndarray:
    c, s_ = math.cos(angle), math.sin(angle)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s_], [0, s_, c]])
    if axis == "Y":
        return np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
    return np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])


def _pose(tf: dict[str, Any] | list | None, where: str = "a transform") -> np.ndarray | None:
    """A 4x4 matrix of an OpenLABEL pose/transform: ``matrix4x4`` (row-major), or ``quaternion``
    (x, y, z, w) / ``euler_angles`` (values in the order of ``sequence``, default ZYX, i.e.
    (rz, ry, rx)) with ``translation``. One that does not read as such (16 numbers, 4 of the
    quaternion, 3 of the translation...) is a :class:`FormatError` naming ``where``."""
    if tf is None:
        return None
    try:
        m = _pose_matrix(tf)
    except (TypeError, ValueError, KeyError, IndexError, AttributeError) as e:
        raise FormatError(f"OpenLABEL: {where} is no readable pose ({type(e).__name__}: {e}): "
                          f"{str(tf)[:120]}") from None
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise FormatError(f"OpenLABEL: {where} is no finite 4x4 pose: {str(tf)[:120]}")
    return m


def _pose_matrix(tf: dict[str, Any] | list) -> np.ndarray:
    if isinstance(tf, list):
        tf = {"matrix4x4": tf}
    m = np.eye(4)
    if tf.get("matrix4x4") is not None:
        return np.asarray(tf["matrix4x4"], float).reshape(4, 4)
    if tf.get("quaternion") is not None:
        m[:3, :3] = _quat_matrix(*tf["quaternion"])
    elif tf.get("euler_angles") is not None:
        seq = str(tf.get("sequence") or "ZYX").upper()
        R = np.eye(3)
        for axis, angle in zip(seq, tf["euler_angles"]):
            R = R @ _axis_rotation(axis, float(angle))
        m[:3, :3] = R
    if tf.get("translation") is not None:
        m[:3, 3] = np.asarray(tf["translation"], float)[:3]
    return m


#: coordinate-system types that are a world frame (preferred as the root of a chain)
_WORLD_TYPES = ("geo_utm", "geo_wgs84", "scene_cs")


class _Frames:
    """The coordinate systems of a file: static poses (``pose_wrt_parent``, ``X_parent = P X``)
    and, per frame, ``frame_properties.transforms`` (``transform_src_to_dst``). :meth:`resolve`
    finds the transform of a coordinate system into the root: a breadth-first search over both
    (a frame's transforms first, either direction), to the reachable root of the highest rank (a
    geo or scene coordinate system, else the root of its own tree)."""

    def __init__(self, cs: dict[str, Any] | None) -> None:
        self.cs = cs if isinstance(cs, dict) else {}
        self.parent = {k: (v or {}).get("parent") or None for k, v in self.cs.items()}
        self.static = {k: _pose((v or {}).get("pose_wrt_parent"), f"the pose_wrt_parent of coordinate system {k}")
                       for k, v in self.cs.items()}
        self.kind = {k: str((v or {}).get("type") or "") for k, v in self.cs.items()}
        self.children: dict[str, list[str]] = defaultdict(list)
        for k, p in self.parent.items():
            if p:
                self.children[p].append(k)
        self.unknown: set[str] = set()

    def root_of(self, name: str | None) -> str | None:
        seen = set()
        while name and self.parent.get(name) and name not in seen:
            seen.add(name)
            name = self.parent[name]
        return name

    @staticmethod
    def frame_edges(transforms: Any) -> dict[str, list[tuple[str, np.ndarray]]]:
        """The transforms of a frame as edges ``src -> [(dst, 4x4 X_dst = T X_src)]``, both ways."""
        edges: dict[str, list[tuple[str, np.ndarray]]] = defaultdict(list)
        for tf in (transforms or {}).values() if isinstance(transforms, dict) else ():
            if not (isinstance(tf, dict) and tf.get("src") and tf.get("dst")):
                continue
            m = _pose(tf.get("transform_src_to_dst"), f"the transform {tf['src']} -> {tf['dst']}")
            if m is None:
                continue
            src, dst = str(tf["src"]), str(tf["dst"])
            edges[src].append((dst, m))
            try:
                edges[dst].append((src, np.linalg.inv(m)))
            except np.linalg.LinAlgError:
                pass
        return edges

    def resolve(self, name: str | None, edges: dict[str, list] | None = None
                ) -> tuple[np.ndarray, str | None, bool]:
        """``(4x4 name -> root, root, whether a frame transform is on the path)``. A name that is
        not among ``coordinate_systems`` and has no frame transform is taken as the root."""
        if not name:
            return np.eye(4), None, False
        edges = edges or {}
        if name not in self.cs and name not in edges:
            self.unknown.add(name)
            return np.eye(4), name, False
        best: dict[str, tuple[np.ndarray, bool]] = {name: (np.eye(4), False)}
        queue = [name]
        while queue:
            n = queue.pop(0)
            m, used = best[n]
            steps = [(d, t, True) for d, t in edges.get(n, ())]
            p = self.parent.get(n)
            if p:
                steps.append((p, self.static.get(n) if self.static.get(n) is not None else np.eye(4), False))
            for c in self.children.get(n, ()):
                st = self.static.get(c)
                steps.append((c, np.linalg.inv(st) if st is not None else np.eye(4), False))
            for d, t, frame in steps:
                if d not in best:
                    best[d] = (t @ m, used or frame)
                    queue.append(d)
        own_root = self.root_of(name)
        roots = [n for n in best if not self.parent.get(n)]

        def rank(r: str) -> tuple:
            kind = self.kind.get(r, "")
            return (kind.startswith("geo"), kind == "scene_cs", r == own_root,
                    -list(best).index(r))

        root = max(roots, key=rank) if roots else own_root
        m, used = best.get(root, (np.eye(4), False))
        return m, root, used

    def to_root(self, name: str | None, transforms: dict[str, Any] | None) -> np.ndarray:
        return self.resolve(name, self.frame_edges(transforms))[0]


def _utm_crs(name: str, cs_type: str | None) -> str | None:
    """EPSG code of a UTM coordinate system named like ``utm-30t`` / ``UTM32N`` (band letters C-M
    are southern, N-X northern; no letter = northern)."""
    mt = re.search(r"utm[-_ ]?(\d{1,2})\s*([c-xC-X])?(?![a-zA-Z])", name or "", re.I)
    if not mt:
        return None
    zone = int(mt[1])
    south = bool(mt[2]) and mt[2].upper() < "N"
    return f"EPSG:{32700 + zone if south else 32600 + zone}"


# -- the frames: one at a time into column chunks ------------------------------------------------


#: boxes per block converted to columns at once (:func:`.columns.block_columns`)
_CHUNK = 4096
_FLOAT_COLS = ("cub_ts", "px", "py", "pz", "yaw", "dl", "dw", "dh", "vu", "vv", "yr", "au", "av",
               "x_std", "y_std", "z_std", "heading_std", "vu_std", "vv_std", "yr_std", "au_std",
               "av_std", "road_s", "road_t", "lane_position", *LIGHTS)
_OBJ_COLS = ("csroot", "road_id", "lane_id")


def _rep_list(rep: tuple) -> list:
    if rep[0] == "o":
        return rep[1].tolist()
    _, fv, pr, nl = rep
    return [(None if b else v) if p else _MISSING for v, p, b in zip(fv.tolist(), pr, nl)]


def _rep_take(rep: tuple, idx: np.ndarray) -> tuple:
    return (rep[0], *(a[idx] for a in rep[1:]))


def _rep_concat(reps: list[tuple]) -> tuple:
    if all(r[0] == "f" for r in reps):
        return ("f", *(np.concatenate([r[i] for r in reps]) for i in (1, 2, 3)))
    return ("o", np.concatenate([r[1] if r[0] == "o" else as_obj(_rep_list(r)) for r in reps]))


class _FrameData:
    """What :class:`_FrameRows` collected, in sorted frame order."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


class _ColumnStore:
    """The boxes' columns appended block by block: numbers straight into one array per column,
    allocated for the rows expected (:meth:`expect`; grown by doubling where more come — pages
    untouched until written cost nothing), so that a block's arrays are freed as soon as they are
    copied (their memory serves the next block) and no column is concatenated at the end; object
    columns, and a column whose type changes, kept in chunks."""

    def __init__(self) -> None:
        self.n = self.cap = self.hint = 0
        self.arrays: dict[str, np.ndarray] = {}
        self.chunks: dict[str, list[np.ndarray]] = {}

    def expect(self, rows: int) -> None:
        self.hint = max(self.hint, rows)

    def append(self, ch: dict[str, np.ndarray]) -> None:
        m = len(next(iter(ch.values())))
        end = self.n + m
        if end > self.cap:
            self.cap = max(end, 2 * self.cap, self.hint)
            for c, a in self.arrays.items():
                self.arrays[c] = grown = np.empty(self.cap, a.dtype)
                grown[:self.n] = a[:self.n]
        for c, a in ch.items():
            arr = self.arrays.get(c)
            if arr is not None and arr.dtype == a.dtype:
                arr[self.n:end] = a
            elif not self.n and a.dtype != object:
                self.arrays[c] = arr = np.empty(self.cap, a.dtype)
                arr[:end] = a
            else:
                if arr is not None:  # (another type than before: chunks, numpy's promotion at the end)
                    self.chunks[c] = [self.arrays.pop(c)[:self.n]]
                self.chunks.setdefault(c, []).append(a)
        self.n = end

    def names(self) -> list[str]:
        return [*self.arrays, *self.chunks]

    def pop(self, c: str) -> np.ndarray:
        """The column ``c`` whole (handed over: the store forgets it)."""
        if c in self.arrays:
            return self.arrays.pop(c)[:self.n]
        return np.concatenate(self.chunks.pop(c))


#: about this many boxes at a time in :meth:`_FrameRows._first_seen`
_SEEN_GROUP = 1 << 20


class _FrameRows:
    """The frames of an OpenLABEL file, one ``(key, frame)`` at a time in any order: per box the
    values of one state in column chunks (numpy), per frame its key, timestamp and object ids.
    :meth:`finish` sorts the rows by frame key (numerically where digits, as the dict path always
    did) and, where a key repeats, keeps the last frame of that key (as ``json.loads`` does)."""

    def __init__(self, objects: Any, cs: _Frames, path: Path | None) -> None:
        self.objects, self.cs, self.path = objects, cs, path
        self.keys: list = []  # per frame occurrence (file order)
        self.stamps: list = []
        #: the objects' indices (into ``uid_index``) of every frame occurrence, flat in parts, and
        #: how many each frame has
        self.uid_parts: list[np.ndarray] = []
        self.frame_len: list[int] = []
        self.uid_index: dict[str, int] = {}
        # the boxes of the frames not yet converted: per object in a frame its frame, uid, value
        self.p_j: list[int] = []
        self.p_u: list[str] = []
        self.p_oif: list[Any] = []
        self.p_edges: dict[int, tuple[dict, dict]] = {}  # frame -> (its transforms, resolve cache)
        self.columns = _ColumnStore()
        self.ext_chunks: list[tuple[int, dict[str, tuple]]] = []
        self.interior: list[tuple[int, str, dict]] = []
        self._need_size: dict[str, bool] = {}
        #: object type given inside a frame's object_data (TUM Traffic), by object
        self.frame_types: dict[str, str] = {}
        #: objects whose static cuboid (object_data of ``objects``) lies in a coordinate system
        #: that a frame's transforms move (KITTI's ego car in vehicle-iso8855): one box per frame
        self.static_cuboids = _static_cuboids(objects)
        self.moving_static: set[str] = set()
        #: check the profile's mandatory attributes of each box (files that claim the profile)
        self.profile = False
        #: what the frames' checks found: (code, attribute or coordinate system) ->
        #: [first frame key, first object uid, count]
        self.found: dict[tuple[str, str], list] = {}
        #: the import's parts (:class:`.parts.Parts`: an import that writes its recording itself)
        #: spill the rows (:class:`.spill.RowSpill`) from the first block where the file's size
        #: says many, or once the rows held reach that many (a file read frame by frame)
        self.parts = None
        self.spill = None
        self._spill_off = False  # (a block the spill could not hold: in memory from there on)

    def _needs_size(self, u: str) -> bool:
        need = self._need_size.get(u)
        if need is None:
            try:
                obj = self.objects.get(u) or {}
                need = _first(_attrs(obj.get("object_data")), "dimensions/size") is None
            except Exception:  # noqa: BLE001 - a damaged object: keep the sizes (they are unused)
                need = True
            self._need_size[u] = need
        return need

    def add(self, k: Any, fr: Any) -> None:
        """One frame: its key, timestamp and objects; its boxes wait for :meth:`_flush`."""
        j = len(self.keys)
        fr = fr if isinstance(fr, dict) else {}
        ts = _frame_timestamp(fr)
        self.keys.append(k)
        self.stamps.append(ts)
        ui = self.uid_index
        fobjs = fr.get("objects") or {}
        if not isinstance(fobjs, dict):
            raise FormatError(f"frame {k}: 'objects' is not an object", path=self.path)
        if not fobjs.keys() <= ui.keys():
            for u in fobjs:
                ui.setdefault(u, len(ui))
        self.uid_parts.append(np.fromiter(map(ui.__getitem__, fobjs), np.int32, len(fobjs)))
        self.frame_len.append(len(fobjs))
        fp = fr.get("frame_properties")
        edges = self.cs.frame_edges(fp.get("transforms") if isinstance(fp, dict) else None)
        self.p_edges[j] = (edges, {})
        self.p_j.extend(repeat(j, len(fobjs)))
        self.p_u.extend(fobjs)
        self.p_oif.extend(fobjs.values())
        if edges and self.static_cuboids:
            boxed = {u for u, oif in fobjs.items() if box_parts(oif)[1] is not None}
            for u, cub, intervals in self.static_cuboids:
                if u in boxed or not _in_intervals(k, intervals):
                    continue
                _, _, moving = self._resolve(cub.get("coordinate_system"), j)
                if moving:  # the static cuboid, placed by this frame's transforms
                    ui.setdefault(u, len(ui))
                    self.uid_parts[-1] = np.append(self.uid_parts[-1], ui[u])
                    self.frame_len[-1] += 1
                    self.moving_static.add(u)
                    self.p_j.append(j)
                    self.p_u.append(u)
                    self.p_oif.append({"object_data": {"cuboid": [cub]}})
        if len(self.p_j) >= _CHUNK:
            self._flush()

    def _resolve(self, csname: Any, j: int, uid: str | None = None) -> tuple[np.ndarray, str | None, bool]:
        edges, cache = self.p_edges[j]
        key = str(csname) if csname else ""
        if key not in cache:
            cache[key] = self.cs.resolve(key or None, edges)
            if key in self.cs.unknown:
                self._found("source.openlabel.unknown_coordinate_system", key, self.keys[j], uid, 1)
        return cache[key]

    def _found(self, code: str, what: str, frame: Any, uid: str | None, count: int) -> None:
        f = self.found.get((code, what))
        if f is None:
            self.found[(code, what)] = [frame, uid, count]
        else:
            f[2] += count

    def _check_block(self, found: list[tuple[str, str, int, int]], js: list[int], us: list[str]) -> None:
        """A block's :func:`block_findings` (box indices into ``js``/``us``), located."""
        for code, name, i, count in found:  # (missing attributes kept for files that claim the
            self._found(code, name, self.keys[js[i]], us[i], count)  # profile: in finish)

    def _flush(self) -> None:
        """The waiting boxes into one chunk of columns (:func:`.columns.block_columns`)."""
        if not self.p_j:
            self.p_edges = {}
            return
        ods, cubs = split_boxes(self.p_oif)
        types = list(map(dict.get, ods, repeat("type")))
        if any(isinstance(t, str) for t in types):  # a type inside a frame's object_data (TUM)
            for u, t in zip(self.p_u, types):
                if isinstance(t, str) and u not in self.frame_types:
                    self.frame_types[u] = t
        has = list(map(is_not, cubs, repeat(None)))
        if all(has):
            js, us = self.p_j, self.p_u
        else:
            js, us = list(compress(self.p_j, has)), list(compress(self.p_u, has))
            ods, cubs = list(compress(ods, has)), list(compress(cubs, has))
        self.p_j, self.p_u, self.p_oif = [], [], []
        if not js:
            self.p_edges = {}
            return
        keys = self.keys

        def place(i: int) -> tuple:
            j, u = js[i], us[i]
            return _box_in_root(cubs[i], lambda name: self._resolve(name, j, u), keys[j], u, self.path)

        ch, ext, at = block_columns(ods, cubs, place)
        self._keep(ch, ext_chunk(ext), block_findings(at, True), js, us)
        inames = [nm for nm in at.code_of if nm.startswith("interior/")]
        if inames:
            for i in at.boxes_with(inames).tolist():
                irow = _interior_row(_attrs(ods[i]))
                if irow:
                    self.interior.append((js[i], us[i], irow))
        self.p_edges = {}

    def _keep(self, ch: dict[str, np.ndarray], ext: dict[str, tuple],
              found: list[tuple[str, str, int, int]], js: Any, us: list[str],
              uidx: np.ndarray | None = None, spilled: tuple | None = None) -> None:
        """A block's columns (boxes of frames ``js``, objects ``us``: their indices ``uidx`` where
        the caller has them) and what its checks found (:func:`block_findings`), kept;
        ``spilled``: the columns written into the spill by the worker that read the block
        (:meth:`.fastblock.FastBlock.spill_to`: ``ch`` empty; only while there is a spill)."""
        ui = self.uid_index
        ch["uidx"] = uidx if uidx is not None else np.fromiter(map(ui.__getitem__, us), np.int32, len(us))
        ch["occ"] = np.asarray(js, np.int64)
        self._check_block(found, js, us)
        # a spill begins where the file's size says many rows (the columnar blocks: at the first),
        # else once the rows held reach the threshold (those moved into it)
        if self.spill is None and self.parts is not None and not self._spill_off \
                and self.parts.spills(max(self.columns.hint, self.columns.n + len(us))):
            self._spill_held()
        if spilled is not None:
            self.spill.adopt(spilled, ch["uidx"], ch["occ"])
        else:
            self._store(ch, ext)

    def _store(self, ch: dict[str, np.ndarray], ext: dict[str, tuple]) -> None:
        """A block's rows (with their ``uidx``) into the spill while there is one, else into
        memory (:meth:`_hold`; a block Arrow cannot hold exactly ends the spill: all in memory
        from here)."""
        if self.spill is not None:
            if self.spill.append(ch, ext):
                return
            self._unspill()
        self._hold(ch, ext)

    def _hold(self, ch: dict[str, np.ndarray], ext: dict[str, tuple]) -> None:
        self.columns.append(ch)
        self.ext_chunks.append((len(ch["uidx"]), ext))

    def spill_target(self) -> str | None:
        """Where the worker reading the next block writes its columns (:func:`.stream._read_blocks`'
        ``spill_to``): the spill's directory while there is a spill, else None (sent back)."""
        return str(self.spill.dir) if self.spill is not None else None

    def _spill_held(self) -> None:
        """A spill begun, the rows held in memory so far moved into it block by block (a file
        read frame by frame: its rows are not estimated before the frames)."""
        held, chunks = self.columns, self.ext_chunks
        cols = {c: held.pop(c) for c in held.names()}
        self.columns, self.ext_chunks = _ColumnStore(), []
        self.columns.expect(held.hint)
        self.spill = self.parts.row_spill()
        off = 0
        for m, ext in chunks:
            self._store({c: a[off:off + m] for c, a in cols.items()}, ext)
            off += m

    def _unspill(self) -> None:
        """The spilled rows back into memory (and no spill from here on)."""
        spill, self.spill = self.spill, None
        self._spill_off = True
        spill.load_into(self._hold)

    def _sizes(self, rows: dict[str, np.ndarray], names: list[str]) -> dict[str, list]:
        """Per object without a static size (``objects`` known by now: a file may have them after
        its frames) the (length, width, height) of its boxes in the frames kept."""
        sizes: dict[str, list] = {}
        if not len(rows["uidx"]):
            return sizes
        need = np.fromiter(map(self._needs_size, names), bool, len(names))
        sel = np.flatnonzero(need[rows["uidx"]])
        if len(sel):
            ui = rows["uidx"][sel]
            order = np.argsort(ui, kind="stable")
            dims = np.column_stack([rows[c][sel[order]] for c in ("dl", "dw", "dh")]).tolist()
            uniq, first = np.unique(ui[order], return_index=True)
            bounds = [*first.tolist(), len(order)]
            for k, u in enumerate(uniq.tolist()):
                sizes[names[u]] = dims[bounds[k]:bounds[k + 1]]
        return sizes

    def add_columns(self, blk: Any) -> None:
        """A block of frames read into columns (:class:`.fastblock.FastBlock`: level boxes in the
        root frame, each object's uid once per frame, rows in file order; the caller took it only
        where no static cuboid needs the frames' transforms)."""
        self._flush()
        ui = self.uid_index
        j0 = len(self.keys)
        objs = [fr.get("objects") or {} for _, fr in blk.frames]
        self.keys.extend(k for k, _ in blk.frames)
        self.stamps.extend(_frame_timestamp(fr) for _, fr in blk.frames)
        us = list(chain.from_iterable(objs))
        if blk.spilled is not None and self.spill is None:  # (spilled by its worker, the spill
            blk.cols, blk.ext = read_rows(blk.spilled[0])  # ended since: back into memory)
            blk.spilled = None
        if not self.columns.cap and not self.columns.hint and blk.nbytes and self.path is not None:  # (the rows to expect)
            try:
                self.columns.expect(int(os.stat(self.path).st_size / blk.nbytes * len(us) * 1.2) + len(us))
            except OSError:
                pass
        for u in us:
            if u not in ui:
                ui[u] = len(ui)
        idx = np.fromiter(map(ui.__getitem__, us), np.int32, len(us))
        lens = np.fromiter(map(len, objs), np.int64, len(objs))
        self.uid_parts.append(idx)
        self.frame_len.extend(lens.tolist())
        if us:
            self._keep(blk.cols, blk.ext, blk.found, np.repeat(np.arange(j0, j0 + len(objs)), lens), us, idx,
                       blk.spilled)

    def _first_seen(self, rank_of: np.ndarray) -> np.ndarray:
        """The objects of the frames kept (``rank_of`` >= 0), in order of their first appearance
        in frame key order (then in the frame's order): per object the least (rank, place in its
        frame), about a million boxes at a time (no sort of all boxes)."""
        flen = np.asarray(self.frame_len, np.int64)
        ends = np.cumsum(flen)
        width = int(flen.max()) + 1 if len(flen) else 1
        none = np.iinfo(np.int64).max
        first = np.full(len(self.uid_index), none, np.int64)
        group: list[np.ndarray] = []
        e0 = size = 0
        for i, part in enumerate(self.uid_parts):
            group.append(part)
            size += len(part)
            if size < _SEEN_GROUP and i < len(self.uid_parts) - 1:
                continue
            idx = np.concatenate(group)
            frame = np.searchsorted(ends, np.arange(e0, e0 + size), side="right")
            key = rank_of[frame] * width + (np.arange(e0, e0 + size) - (ends[frame] - flen[frame]))
            kept = rank_of[frame] >= 0
            np.minimum.at(first, idx[kept], key[kept])
            e0 += size
            group, size = [], 0
        order = np.argsort(first, kind="stable")
        return order[first[order] < none]

    def finish(self, materialise: bool = False) -> _FrameData:
        """The frames in key order; with a spill, the rows stay on disk (``rows`` None: the
        import's parts read them) unless ``materialise``."""
        self._flush()
        if self.spill is not None and materialise:
            self._unspill()
        last: dict = {}
        for j, k in enumerate(self.keys):
            last[k] = j
        fkeys = sorted(last, key=lambda k: (int(k) if str(k).lstrip("-").isdigit() else 0, str(k)))
        rank_of = np.full(len(self.keys), -1, np.int64)
        for r, k in enumerate(fkeys):
            rank_of[last[k]] = r
        names = list(self.uid_index)
        objects = self.objects
        # the objects the frames list and the objects member does not, in order of appearance
        seen = {u: None for u in map(names.__getitem__, self._first_seen(rank_of).tolist()) if u not in objects}
        rows: dict[str, np.ndarray] = {}
        ext: dict[str, tuple] = {}
        has_vel, has_road = True, False
        store = self.columns
        if self.spill is not None:
            rows, sizes = None, {}
        elif store.n:
            rank = rank_of[store.pop("occ")]
            sel = np.flatnonzero(rank >= 0)
            sel = sel[np.argsort(rank[sel], kind="stable")]
            ident = len(sel) == len(rank) and bool((sel == np.arange(len(sel))).all())
            for c in store.names():  # one column at a time (a chunked one: its chunks freed)
                a = store.pop(c)
                rows[c] = a if ident else a[sel]
            self.columns = _ColumnStore()
            release_free_memory()  # (the chunks' pages back to the system)
            rows["rank"] = rank if ident else rank[sel]
            hv, hr = rows.pop("hv"), rows.pop("hr")
            has_vel, has_road = bool(hv.all()), bool(hr.any())
            keys = dict.fromkeys(c for _, reps in self.ext_chunks for c in reps)
            for c in keys:  # one member at a time, freeing its chunks (nothing kept twice)
                parts = [reps.pop(c, None) or ("f", np.full(m, np.nan), np.zeros(m, bool), np.zeros(m, bool))
                         for m, reps in self.ext_chunks]
                ext[c] = _rep_concat(parts) if ident else _rep_take(_rep_concat(parts), sel)
                del parts
            self.ext_chunks = []
            release_free_memory()
        else:
            rows = {c: np.asarray([]) for c in (*_FLOAT_COLS, *_OBJ_COLS)}
            rows["uidx"] = rows["rank"] = np.asarray([], np.int64)
        if rows is not None:
            sizes = self._sizes(rows, names)
        if not self.profile:
            self.found = {k: v for k, v in self.found.items() if k[0] != "source.openlabel.missing_attribute"}

        def interior(pid_of: dict, time_of: dict) -> dict[str, list]:
            out: dict[str, list] = defaultdict(list)
            keep = sorted((int(rank_of[j]), i) for i, (j, _, _) in enumerate(self.interior)
                          if rank_of[j] >= 0)
            for r, i in keep:
                _, u, irow = self.interior[i]
                if u not in pid_of:  # an object not imported (no road user)
                    continue
                out["participant_id"].append(pid_of[u])
                out["time"].append(time_of[fkeys[r]])
                for c in ("automation_longitudinal_p", "automation_lateral_p", "steering_angle",
                          "steering_angle_std", "brake_pedal", "accelerator_pedal", "gear"):
                    out[c].append(irow.get(c))
            return out

        return _FrameData(fkeys=fkeys, stamps={k: self.stamps[last[k]] for k in fkeys},
                          seen_in_frames=list(seen), uid_names=names, rows=rows, ext=ext,
                          sizes=sizes, interior=interior, has_vel=has_vel, has_road=has_road,
                          frame_types=self.frame_types, moving_static=sorted(self.moving_static),
                          unknown_cs=sorted(self.cs.unknown), found=self.found,
                          spill=self.spill, rank_of=rank_of, needs_size=self._needs_size,
                          sizes_of=lambda rows: self._sizes(rows, names))


def _frame_timestamp(fr: dict[str, Any]) -> Any:
    """``frame_properties.timestamp`` as written: a number (an integer text as an exact int), an
    ISO 8601 text; None where absent or unreadable. Its unit is resolved over all frames."""
    from aveas_format.converters.common.timestamps import timestamp_value

    fp = fr.get("frame_properties")
    return timestamp_value(fp.get("timestamp")) if isinstance(fp, dict) else None


def _box_in_root(cub: dict[str, Any], resolve, k: Any, u: str, path: Path | None
                 ) -> tuple[Any, float, tuple[float, float, float], float, str | None]:
    """The cuboid of object ``u`` in frame ``k`` in the root coordinate system:
    ``(centre, yaw, (length, width, height), ground z, root)``.

    ``resolve(coordinate_system)`` gives ``(4x4 -> root, root, moving)``. The cuboid's axes are
    read through its rotation and its coordinate system's transform: the axis nearest the root's
    vertical carries the height, the first other axis (the cuboid's x, unless x is the vertical)
    the length and the heading, the remaining one the width; the ground point lies half the box's
    vertical extent below its centre. So a camera-frame cuboid (KITTI's ``CAM_LEFT``: x right,
    y down, z forward; sizes along those axes) comes out with its height from y."""
    try:
        v = [float(a) for a in cub["val"]]
    except (TypeError, ValueError):
        raise FormatError(f"frame {k} object {u}: cuboid val holds non-numbers: "
                          f"{str(cub.get('val'))[:80]}", path=path) from None
    csname = cub.get("coordinate_system")
    if len(v) == 9 and v[3] == 0.0 and v[4] == 0.0 and not csname:
        # the common case (the AVEAS profile): a level box in the root frame
        return v[:3], v[5], (v[6], v[7], v[8]), v[2] - v[8] / 2.0, None
    if len(v) == 10:
        R = _quat_matrix(v[3], v[4], v[5], v[6])
        size = v[7:10]
    elif len(v) == 9:
        R = _euler_matrix(v[3], v[4], v[5])
        size = v[6:9]
    else:
        raise FormatError(f"frame {k} object {u}: cuboid with {len(v)} values (expected 9: x, y, z, "
                          "rx, ry, rz, sx, sy, sz or 10: x, y, z, qx, qy, qz, qw, sx, sy, sz)",
                          path=path)
    M, root, _ = resolve(csname)
    Rw = M[:3, :3] @ R
    pw = M[:3, :3] @ np.asarray(v[:3]) + M[:3, 3]
    up = np.abs(Rw[2, :])
    kv = int(np.argmax(up))
    kl, kw = (i for i in range(3) if i != kv)
    yaw = math.atan2(Rw[1, kl], Rw[0, kl])
    ground = float(pw[2] - 0.5 * float(up @ np.abs(np.asarray(size))))
    return pw, yaw, (size[kl], size[kw], size[kv]), ground, root


def _static_cuboids(objects: Any) -> list[tuple[str, dict[str, Any], list | None]]:
    """``(object, cuboid, frame intervals or None)`` of the objects with a cuboid in their static
    ``object_data`` in a named coordinate system."""
    out = []
    for u, obj in (objects.items() if isinstance(objects, dict) else ()):
        od = obj.get("object_data") if isinstance(obj, dict) else None
        cubs = od.get("cuboid") if isinstance(od, dict) else None
        cubs = [cubs] if isinstance(cubs, dict) else (cubs or [])
        cub = next((c for c in cubs if isinstance(c, dict) and c.get("val") is not None
                    and c.get("coordinate_system")), None)
        if cub is not None:
            fis = obj.get("frame_intervals")
            out.append((str(u), cub, fis if isinstance(fis, list) and fis else None))
    return out


def _in_intervals(k: Any, intervals: list | None) -> bool:
    if intervals is None:
        return True
    try:
        f = int(k)
    except (TypeError, ValueError):
        return True
    return any(isinstance(fi, dict) and int(fi.get("frame_start", f)) <= f <= int(fi.get("frame_end", f))
               for fi in intervals)


def _interior_row(attrs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The interior signals of a box (the lateral automated-control flag carries the longitudinal
    name in ``aveas-openlabel``'s files: a second longitudinal item is the lateral one)."""
    lon_items = attrs.get(_LONGITUDINAL) or []
    lat_items = attrs.get("interior/automated_control/lateral") or []
    irow = {}
    if lon_items:
        irow["automation_longitudinal_p"] = float(bool(lon_items[0].get("val")))
    if lat_items:
        irow["automation_lateral_p"] = float(bool(lat_items[0].get("val")))
    elif len(lon_items) > 1:
        irow["automation_lateral_p"] = float(bool(lon_items[1].get("val")))
    for c, name in (("steering_angle", "interior/steering_angle"),
                    ("steering_angle_std", "interior/steering_angle/ustddev"),
                    ("brake_pedal", "interior/brake_pedal"),
                    ("accelerator_pedal", "interior/accelerator_pedal"),
                    ("gear", "interior/gear")):
        val = _first(attrs, name)
        if val is not None:
            irow[c] = val
    return irow
