"""A block of OpenLABEL boxes into columns at once (the import's hot path).

:func:`block_columns` takes the boxes of a block of frames (a few thousand: their ``object_data``
and ``bounding_box`` cuboid) and builds the per-box columns :class:`~.frames._FrameRows` keeps
without a Python step per attribute per box: the attribute items of all boxes are flattened per
kind (``boolean``, ``num``, ``text``, ``vec``: C-level ``map``/``chain``), their names
dictionary-encoded by pyarrow, and each attribute the import reads is taken by name with one
numpy pass per block (the first item of a name per box, as :func:`~.profile._first` does); the
vectors (velocity, acceleration, ustddev) become 2-D float arrays in one conversion. Level boxes
in the root frame (the AVEAS profile: 9 values, no roll/pitch, no coordinate system) are placed
from one ``(n, 9)`` array; other cuboids (generic files: rotations, coordinate systems) go through
:func:`~.frames._box_in_root` one at a time, and so does anything a bulk conversion refuses
(ragged or non-numeric values: the same values and errors as box by box).
"""

from __future__ import annotations

from itertools import chain, repeat
from operator import is_, is_not, itemgetter, methodcaller
from typing import Any, Callable

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.openlabel.profile import EXT, LIGHTS, MANDATORY_FRAME_ATTRIBUTES, _enum_value

#: an extension value the box does not carry (``None`` is a value: null)
_MISSING = object()
_KINDS = ("boolean", "num", "text", "vec")
_NAN = float("nan")


def box_parts(oif: Any) -> tuple[dict, dict | None]:
    """``(object_data, bounding_box cuboid or None)`` of one object in a frame (the cuboid named
    ``bounding_box``, else the first; a single cuboid object as TUM Traffic writes it)."""
    if not isinstance(oif, dict):
        return {}, None
    od = oif.get("object_data") or {}
    if not isinstance(od, dict):
        return {}, None
    cubs = od.get("cuboid")
    if isinstance(cubs, dict):
        cub = cubs
    elif not cubs:
        return od, None
    else:
        c0 = cubs[0] if isinstance(cubs, (list, tuple)) else None
        if isinstance(c0, dict) and c0.get("name") == "bounding_box":
            cub = c0
        else:
            cub = next((c for c in cubs if isinstance(c, dict) and c.get("name") == "bounding_box"),
                       cubs[0])
    if not isinstance(cub, dict) or cub.get("val") is None:
        return od, None
    return od, cub


def split_boxes(oifs: list) -> tuple[list[dict], list[dict | None]]:
    """:func:`box_parts` of many objects: in bulk where every one is laid out as the profile's
    (``object_data`` with a ``cuboid`` list whose first item is the ``bounding_box`` with a
    ``val``), else one at a time."""
    if oifs:
        try:
            ods = list(map(itemgetter("object_data"), oifs))
            if set(map(type, ods)) == {dict}:
                cubl = list(map(itemgetter("cuboid"), ods))
                if set(map(type, cubl)) == {list}:
                    cubs = list(map(itemgetter(0), cubl))
                    if (set(map(type, cubs)) == {dict}
                            and set(map(itemgetter("name"), cubs)) == {"bounding_box"}
                            and None not in list(map(itemgetter("val"), cubs))):
                        return ods, cubs
        except (KeyError, TypeError, IndexError):
            pass
    parts = list(map(box_parts, oifs))
    return [p[0] for p in parts], [p[1] for p in parts]


def as_obj(lst: list) -> np.ndarray:
    """A 1-D object array of the values (lists stay elements)."""
    a = np.empty(len(lst), object)
    if not any(issubclass(t, (list, tuple, dict, np.ndarray)) for t in set(map(type, lst))):
        a[:] = lst
        return a
    for i, v in enumerate(lst):
        a[i] = v
    return a


def as_float(lst: list) -> np.ndarray:
    """float64 where every value converts (as ``np.asarray(values, float)`` would), else the values
    as an object array (converted, or refused with the same error, where the column is used)."""
    try:
        a = np.asarray(lst, float)
        if a.ndim == 1:
            return a
    except (TypeError, ValueError, OverflowError):
        pass
    return as_obj(lst)


def ext_rep(vals: list) -> tuple:
    """One extension column (values or ``_MISSING``): ``("f", values, present, null)`` where all
    present values are floats or null, else ``("o", object array)``."""
    n = len(vals)
    if set(map(type, vals)) <= {float, type(None), object}:
        present = np.fromiter(map(is_not, vals, repeat(_MISSING)), bool, n)
        null = np.fromiter(map(is_, vals, repeat(None)), bool, n)
        a = as_obj(vals)
        a[~present | null] = _NAN
        return ("f", a.astype(float), present, null)
    return ("o", as_obj(vals))


class _Attributes:
    """The attribute items of ``n`` boxes, by name: :meth:`first` gives per box the value of the
    first item of a name (kinds in the order boolean, num, text, vec; as ``_first(_attrs(od))``)."""

    def __init__(self, ods: list[dict]) -> None:
        n = self.n = len(ods)
        per_kind = []
        for kind in _KINDS:
            lists = list(map(methodcaller("get", kind), ods))
            if not any(lists):
                continue
            per_kind.append([x if isinstance(x, list) else [x] if isinstance(x, dict) else []
                             for x in lists])
        self.layout: dict[str, tuple[list, int, int]] | None = None
        if self._uniform(per_kind):
            return
        boxes, items = [], []
        for lists in per_kind:
            counts = np.fromiter(map(len, lists), np.int64, n)
            boxes.append(np.repeat(np.arange(n), counts))
            items.append(list(chain.from_iterable(lists)))
        self.box = np.concatenate(boxes) if boxes else np.zeros(0, np.int64)
        flat = list(chain.from_iterable(items))
        try:
            names = list(map(itemgetter("name"), flat))
        except (KeyError, TypeError):  # an item that is no object or has no name: skipped (as _attrs)
            flat = [it if isinstance(it, dict) else {} for it in flat]
            names = list(map(dict.get, flat, repeat("name")))
        try:
            enc = pc.dictionary_encode(pa.array(names, pa.string()))
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # names that are no text: never asked for
            enc = pc.dictionary_encode(pa.array([v if isinstance(v, str) else None for v in names],
                                                pa.string()))
        codes = enc.indices.fill_null(-1).to_numpy(zero_copy_only=False)
        self.code_of = {s: i for i, s in enumerate(enc.dictionary.to_pylist())}
        # the items grouped by name (in file order within a name): one sort per block
        self.order = np.argsort(codes, kind="stable")
        self.bounds = np.searchsorted(codes[self.order], np.arange(len(self.code_of) + 1))
        self.codes, self.flat = codes, flat

    def _uniform(self, per_kind: list[list[list]]) -> bool:
        """Where every box lists the same attribute names in the same order (a profile export:
        the common case), each name's values are a stride of the items: no encoding, no sort."""
        n = self.n
        layout: dict[str, tuple[list, int, int]] = {}
        for lists in per_kind:
            c = len(lists[0])
            if c == 0 or set(map(len, lists)) != {c}:
                return False
            flat = list(chain.from_iterable(lists))
            try:
                names = list(map(itemgetter("name"), flat))
            except (KeyError, TypeError):
                return False
            sig = names[:c]
            if names != sig * n or not all(isinstance(nm, str) for nm in sig):
                return False
            for pos, nm in enumerate(sig):
                layout.setdefault(nm, (flat, pos, c))  # the first kind and position of a name
        self.layout = layout
        self.code_of = dict.fromkeys(layout)
        return True

    def first(self, name: str) -> tuple[np.ndarray, list]:
        """``(boxes that have the name, the first such item's value per box)``."""
        if self.layout is not None:
            if name not in self.layout:
                return np.zeros(0, np.int64), []
            flat, pos, c = self.layout[name]
            items, boxes = flat[pos::c], np.arange(self.n)
        else:
            code = self.code_of.get(name)
            if code is None:
                return np.zeros(0, np.int64), []
            sel = self.order[self.bounds[code]:self.bounds[code + 1]]
            boxes = self.box[sel]
            if len(boxes) > 1 and not (boxes[1:] > boxes[:-1]).all():  # a name twice in a box
                boxes, first = np.unique(boxes, return_index=True)
                sel = sel[first]
            items = list(map(self.flat.__getitem__, sel.tolist()))
        try:
            return boxes, list(map(itemgetter("val"), items))
        except KeyError:
            return boxes, list(map(dict.get, items, repeat("val")))

    def first_boxes(self, name: str) -> np.ndarray:
        """The boxes that have an item of ``name``."""
        return self.first(name)[0]

    def boxes_with(self, names: list[str]) -> np.ndarray:
        """The boxes that have an item of any of ``names``, in order."""
        if self.layout is not None:
            return np.arange(self.n) if any(nm in self.layout for nm in names) else np.zeros(0, np.int64)
        codes = [self.code_of[nm] for nm in names if nm in self.code_of]
        return np.unique(self.box[np.isin(self.codes, codes)]) if codes else np.zeros(0, np.int64)

    def scalar(self, name: str, default: Any = None) -> list:
        """Per box the first value of ``name`` (``default`` where a box has none)."""
        out = [default] * self.n
        boxes, vals = self.first(name)
        if len(boxes):
            setter = out.__setitem__
            list(map(setter, boxes.tolist(), vals))
        return out

    def vector(self, name: str, elems: tuple[int, ...]) -> tuple[np.ndarray, list[np.ndarray]]:
        """``(whether a box's first value of name is not None, per element index the value or NaN
        where the vector is absent, empty, shorter or no list)``; values that do not convert in bulk
        are taken one by one (and converted where the column is used, as box by box)."""
        n = self.n
        has = np.zeros(n, bool)
        cols = [np.full(n, np.nan) for _ in elems]
        boxes, vals = self.first(name)
        if not len(boxes):
            return has, cols
        notnone = np.fromiter(map(is_not, vals, repeat(None)), bool, len(vals))
        has[boxes[notnone]] = True
        ok = set(map(type, vals)) == {list} and len(set(map(len, vals))) == 1
        if ok:
            try:
                a = np.fromiter(chain.from_iterable(vals), float).reshape(len(vals), -1)
            except (TypeError, ValueError, OverflowError):
                ok = False
        if ok:
            for c, e in zip(cols, elems):
                if a.shape[1] > e:
                    c[boxes] = a[:, e]
            return has, cols
        objs = [as_obj([_NAN] * n) for _ in elems]
        for b, v in zip(boxes.tolist(), vals):
            if v and isinstance(v, (list, tuple)):  # (another value: no vector, NaN)
                for o, e in zip(objs, elems):
                    if len(v) > e:
                        o[b] = v[e]
        return has, [as_float(o.tolist()) for o in objs]


def _lane_ids(lanes: list, roads: list) -> list:
    """``int(str(lane))`` (an enum text of aveas-openlabel read as its value) where a box has a
    lane and a road, else None; each distinct value converted once."""
    cache: dict = {}

    def conv(v: Any) -> Any:
        try:
            return int(str(_enum_value(v)))
        except ValueError:
            return None

    out = []
    for lane, road in zip(lanes, roads):
        if lane is None or road is None:
            out.append(None)
            continue
        try:
            r = cache[lane]
        except KeyError:
            r = cache[lane] = conv(lane)
        except TypeError:  # unhashable
            r = conv(lane)
        out.append(r)
    return out


def vector_columns(at: Any, cols: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The profile's vectors of a block's boxes into ``cols`` (velocity, acceleration, their and the
    box's 1-sigma) from ``at`` (:class:`_Attributes` or :class:`.fastblock.ArrowAttributes`):
    ``(has a velocity, has road coordinates, [road s, road t])``."""
    hv, (vu, vv, yr) = at.vector("velocity", (0, 1, 5))
    _, (au, av) = at.vector("acceleration", (0, 1))
    _, (xs, ys, zs, hs) = at.vector("bounding_box/ustddev", (0, 1, 2, 5))
    _, (vus, vvs, yrs) = at.vector("velocity/ustddev", (0, 1, 5))
    _, (aus, avs) = at.vector("acceleration/ustddev", (0, 1))
    has_lrc, st = at.vector("open_drive/local_road_coordinates", (0, 1))
    cols.update(vu=vu, vv=vv, yr=yr, au=au, av=av, x_std=xs, y_std=ys, z_std=zs, heading_std=hs,
                vu_std=vus, vv_std=vvs, yr_std=yrs, au_std=aus, av_std=avs)
    return hv, has_lrc, st


def block_columns(ods: list[dict], cubs: list[dict], place: Callable[[int], tuple]
                  ) -> tuple[dict[str, np.ndarray], list, _Attributes]:
    """``(columns, ext items, attributes)`` of the boxes ``cubs`` with their ``object_data`` ``ods``;
    ``place(i)`` is :func:`~.frames._box_in_root` of box ``i`` (the cuboids not placed in bulk).
    The columns are those of :data:`~.frames._FLOAT_COLS` and ``csroot``, ``road_id``, ``lane_id``,
    ``hv``, ``hr`` (the sizes are the columns ``dl``, ``dw``, ``dh``)."""
    n = len(cubs)
    cols: dict[str, np.ndarray] = {}
    # the cuboids: level boxes in the root frame in bulk, the others one at a time
    vals = list(map(itemgetter("val"), cubs))
    csn = list(map(methodcaller("get", "coordinate_system"), cubs))
    try:
        V = np.asarray(vals, float)
        bulk = V.ndim == 2 and V.shape[1] == 9
    except (TypeError, ValueError, OverflowError):
        bulk = False
    if bulk:
        simple = (V[:, 3] == 0.0) & (V[:, 4] == 0.0) & ~np.fromiter(map(bool, csn), bool, n)
    else:
        V, simple = np.full((n, 9), np.nan), np.zeros(n, bool)
    px, py, yaw = V[:, 0].copy(), V[:, 1].copy(), V[:, 5].copy()
    dl, dw, dh = V[:, 6].copy(), V[:, 7].copy(), V[:, 8].copy()
    ground = V[:, 2] - V[:, 8] / 2.0
    csroot = np.empty(n, object)
    for i in np.flatnonzero(~simple).tolist():
        pw, yw, dims, gz, root = place(i)
        px[i], py[i], yaw[i], ground[i] = pw[0], pw[1], yw, gz
        dl[i], dw[i], dh[i] = dims
        csroot[i] = root
    cols.update(px=px, py=py, pz=ground, yaw=yaw, dl=dl, dw=dw, dh=dh, csroot=csroot)

    # a per-box measurement time (the ASAM example's cuboid attribute "timestamp")
    cts = np.full(n, np.nan)
    cattrs = list(map(methodcaller("get", "attributes"), cubs))
    if any(cattrs):
        from aveas_format.converters.openlabel.profile import _attrs, _first

        for i, ca in enumerate(cattrs):
            if ca:
                t = _first(_attrs(ca), "timestamp")
                if isinstance(t, (int, float)):
                    cts[i] = float(t)
    cols["cub_ts"] = cts

    # the profile's attributes, by name
    at = _Attributes(ods)
    hv, has_lrc, (rs, rt) = vector_columns(at, cols)
    road = at.scalar("used_road_link")
    if "open_drive/road_id" in at.code_of:
        road = [r if r is not None else alt for r, alt in zip(road, at.scalar("open_drive/road_id"))]
    has_road = np.fromiter(map(is_not, road, repeat(None)), bool, n)
    on = has_road & has_lrc
    cols["road_s"] = np.where(has_road, rs, np.nan)
    cols["road_t"] = np.where(has_road, rt, np.nan)
    cols["lane_position"] = as_float(at.scalar("open_drive/lane_position", _NAN))
    for c, name in LIGHTS.items():
        cols[c] = np.asarray([_NAN if v is None else float(bool(v)) for v in at.scalar(name)], float) \
            if name in at.code_of else np.full(n, np.nan)
    road_id = np.empty(n, object)
    if on.any():
        strs: dict = {}
        for i in np.flatnonzero(on).tolist():
            r = road[i]
            try:
                road_id[i] = strs[r]
            except KeyError:
                road_id[i] = strs[r] = str(r)
            except TypeError:
                road_id[i] = str(r)
    cols["road_id"] = road_id
    cols["lane_id"] = as_obj(_lane_ids(at.scalar("open_drive/lane_id"), road)) \
        if "open_drive/lane_id" in at.code_of else np.full(n, None, object)
    cols["hv"], cols["hr"] = hv, on
    ext = list(map(methodcaller("get", EXT), cubs))
    return cols, ext, at


def ext_chunk(es: list) -> dict[str, tuple]:
    """The extension items of a block's boxes (a dict or None each) as columns (:func:`ext_rep`)."""
    es = [e if isinstance(e, dict) else {} for e in es]
    keys = dict.fromkeys(chain.from_iterable(es))
    return {c: ext_rep(list(map(methodcaller("get", c, _MISSING), es))) for c in keys}


def block_findings(at: Any, profile: bool) -> list[tuple[str, str, int, int]]:
    """The checks of the source on a block's attributes (:class:`_Attributes` or the fast path's
    ``ArrowAttributes``), in bulk: PMF attributes (``*/uncertainties``) that do not sum to 1, and
    (``profile``: files that claim it) boxes without a mandatory attribute. Per finding
    ``(code, attribute, first box, count)`` (box indices into the block: numbers only, so that a
    worker process hands them back cheaply)."""
    from aveas_format.schema.pmf import pmf_problems

    out = []
    for name in at.code_of:
        if not name.endswith("/uncertainties"):
            continue
        boxes, vals = at.first(name)
        try:
            lens = set(map(len, vals))
            m = np.fromiter(chain.from_iterable(vals), float).reshape(len(vals), -1) \
                if len(lens) == 1 else None
        except (TypeError, ValueError):
            m = None
        bad = pmf_problems(m) if m is not None else np.fromiter(map(_pmf_bad, vals), bool, len(vals))
        if bad.any():
            out.append(("source.openlabel.pmf_sum", name, int(boxes[np.argmax(bad)]), int(bad.sum())))
    if profile:
        for name in MANDATORY_FRAME_ATTRIBUTES:
            has = np.zeros(at.n, bool)
            has[at.first_boxes(name)] = True
            if not has.all():
                out.append(("source.openlabel.missing_attribute", name, int(np.argmin(has)),
                            int((~has).sum())))
    return out


def _pmf_bad(v: Any) -> bool:
    """Whether one PMF value is no vector of numbers summing to 1 (within the schema's tolerance)."""
    from aveas_format.schema.pmf import pmf_problems

    try:
        m = np.asarray([v], float)
    except (TypeError, ValueError):
        return True
    return m.ndim != 2 or bool(pmf_problems(m)[0])
