"""A block of OpenLABEL frames into box columns: typed decoding with msgspec (the import's one decoder).

:func:`decode_block` takes the bytes of whole frames (``{"key":{...},...}``) and decodes them into
Structs mirroring frames -> objects -> ``object_data`` (members the import does not read are
skipped, as the profile allows). Attribute items are typed by their name (a tagged union of the
profile's names: :data:`~.profile.FRAME_ATTRIBUTES`, the interior signals, and the names the
profile has that the import does not read, whose values are skipped): a block that names another
attribute, or holds values of other types, is decoded in the *lenient* layout instead (any name,
values kept as raw JSON and decoded per attribute for the whole block at once). The attributes are
found by name in any kind (``boolean``, ``num``, ``text``, ``vec``; the first item of a name, as
the profile reads it) and turned into columns for the whole block at once (no Python step per
value: adding an attribute is one line in :data:`~.profile.FRAME_ATTRIBUTES`).

The result (:class:`Block`, plain data: it is what a worker process sends back) holds per frame its
key, timestamp, transforms and objects, and per box (an object with a cuboid) its object, the
cuboid placed in the root frame (:func:`~.geometry.place`), the attributes' columns, the
``aveas_format`` extension's members as Arrow arrays, its interior signals and what the checks of
the source found.
"""

from __future__ import annotations

import io
from decimal import Decimal
from itertools import chain, repeat
from operator import attrgetter, contains, is_not, itemgetter, methodcaller
from types import SimpleNamespace
from typing import Any, Union

import msgspec
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv

from aveas_format.converters.labels import implausible_size
from aveas_format.converters.common.coordinate_systems import CoordinateSystems
from aveas_format.converters.openlabel.geometry import place
from aveas_format.converters.openlabel.profile import (EXT, FRAME_ATTRIBUTES, INTERIOR_ATTRIBUTES, LONGITUDINAL,
                                                       MANDATORY_FRAME_ATTRIBUTES, UNREAD_ATTRIBUTES, attributes_of,
                                                       enum_value, first_value, pmf_bad)
from aveas_format.errors import FormatError

_NULL = msgspec.Raw(b"null")
_KINDS = ("boolean", "num", "text", "vec")
_RAW = msgspec.Raw
_Cuboid = msgspec.defstruct("Cuboid", [("val", _RAW, _NULL), ("name", Any, None), ("coordinate_system", Any, None),
                                       ("attributes", _RAW, _NULL), ("ext", _RAW, _NULL)], rename={"ext": EXT}, gc=False)
#: an attribute item of any name (the lenient layout)
_Item = msgspec.defstruct("Item", [("name", Any, None), ("val", _RAW, _NULL)], gc=False)
#: an attribute item of a name the profile has, by its name (the strict layout): its value where
#: the import reads it, else skipped
_NAMED = [msgspec.defstruct(f"Named{i}", [("val", _RAW, _NULL)] if read else [], tag=name, tag_field="name", gc=False)
          for i, (name, read) in enumerate([*((n, True) for n in (*FRAME_ATTRIBUTES, *INTERIOR_ATTRIBUTES)),
                                            *((n, False) for n in UNREAD_ATTRIBUTES)])]
_NAME_OF = {t: t.__struct_config__.tag for t in _NAMED}

_UNREAD = set(UNREAD_ATTRIBUTES)
#: OpenLABEL object_data kinds of labels without a 3D state (no ``cuboid``): what an object that has
#: only these carries is said when it is left out (``Block.shapes``)
SHAPES = ("bbox", "rbbox", "poly2d", "point2d", "binary", "image", "mat", "point3d", "poly3d", "mesh",
          "area_reference", "line_reference")


def _layout(item: Any) -> msgspec.json.Decoder:
    """The decoder of a block of frames (``item``: the attribute items' type)."""
    items = list[item] | item | None
    od = msgspec.defstruct("ObjectData", [("cuboid", list[_Cuboid] | _Cuboid | None, None),
                                          *((kind, items, None) for kind in _KINDS), ("type", Any, None),
                                          *((kind, _RAW, _NULL) for kind in SHAPES)], gc=False)
    oif = msgspec.defstruct("ObjectInFrame", [("object_data", od | None, None)], gc=False)
    frame = msgspec.defstruct("Frame", [("objects", dict[str, oif] | None, None),
                                        ("frame_properties", _RAW, _NULL)], gc=False)
    return msgspec.json.Decoder(dict[str, frame])


_STRICT, _LENIENT = _layout(Union[tuple(_NAMED)]), _layout(_Item)
_ANY = msgspec.json.Decoder()


class _Stamp(msgspec.Struct, gc=False):
    timestamp: Any = None


#: a frame's timestamp, a JSON number kept exact (epoch seconds with nine decimals: a float64 is
#: off by up to 119 ns), the rest of ``frame_properties`` skipped
_STAMP = msgspec.json.Decoder(_Stamp, float_hook=Decimal)


def _stamp(raw: msgspec.Raw) -> Any:
    try:
        return _STAMP.decode(raw).timestamp
    except msgspec.ValidationError:  # (frame_properties absent or not an object)
        return None
_CUBOIDS = msgspec.json.Decoder(list[list[float]])
_VECTORS = msgspec.json.Decoder(list[list[float | None] | None])
_NUMBERS = msgspec.json.Decoder(list[float | None])
_OBJECT_DATA, _CUBOID, _TYPE, _NAME, _VAL, _EXT = (attrgetter(a) for a in
                                                   ("object_data", "cuboid", "type", "name", "val", "ext"))
_EMPTY = SimpleNamespace(cuboid=None, boolean=None, num=None, text=None, vec=None, type=None,
                         **dict.fromkeys(SHAPES, _NULL))


class Block:
    """What :func:`decode_block` made of a block of frames (module docstring): ``keys``, ``stamps``,
    ``props`` (frame index -> its ``frame_properties``, only frames with ``transforms``), ``uids``
    and ``frame_len`` (the objects of each frame, flat), ``frame_of_slot``, per box ``cols``
    (``slot``: the box's object in ``uids``) and ``ext`` (member -> (values, present)),
    ``interior`` ((slot, signals)), ``types`` (object -> type given inside a frame), ``found``
    ((code, attribute, box, count)), ``lenient`` (decoded in the lenient layout), ``shapes``
    (object -> the :data:`SHAPES` kinds it has where it has no cuboid), ``subtypes`` (object -> its
    box's text attribute ``type``)."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


def joined(raws: Any) -> bytes:
    """The JSON array of raw JSON values."""
    return b"[" + b",".join(raws) + b"]"


def decode_block(buf: bytes, offset: int = 0, systems: CoordinateSystems | None = None) -> Block:
    """The frames of ``buf`` (a JSON object of whole frames; ``offset``: where it starts in the
    file, for errors) as a :class:`Block`, the cuboids placed in the root frame of ``systems``
    (the file's coordinate systems). Broken JSON raises :class:`msgspec.DecodeError` (the reader
    locates it). A block the strict layout refuses (another attribute name, values of other
    types, an attribute list holding numbers, a frame that is no object...) is decoded in the
    lenient layout, what is no object dropped (``Block.lenient``)."""
    lenient = False
    try:
        try:
            frames = _STRICT.decode(buf)
        except msgspec.ValidationError:
            lenient = True
            frames = _LENIENT.decode(msgspec.json.encode(_tidied(_ANY.decode(buf))))
    except RecursionError:
        raise FormatError(f"JSON nested too deep (in the frames after byte {offset:,})") from None
    keys = list(frames)
    objs = [fr.objects or {} for fr in frames.values()]
    uids = list(chain.from_iterable(objs))
    frame_len = np.fromiter(map(len, objs), np.int32, len(objs))
    props = [p if isinstance(p, dict) else {} for p in map(_ANY.decode, map(attrgetter("frame_properties"),
                                                                          frames.values()))]
    props_of = {j: p for j, p in enumerate(props) if p.get("transforms")}
    ods = list(map(_OBJECT_DATA, chain.from_iterable(map(dict.values, objs))))
    if None in ods:
        ods = [_EMPTY if od is None else od for od in ods]
    all_types = list(map(_TYPE, ods))
    cubs = _bounding_boxes(list(map(_CUBOID, ods)))
    has = np.fromiter(map(is_not, cubs, repeat(None)), bool, len(cubs))
    slot = np.flatnonzero(has).astype(np.int32)
    shapes = _shapes(uids, ods, np.flatnonzero(~has).tolist()) if not has.all() else {}
    if not has.all():
        ods, cubs = [ods[i] for i in slot.tolist()], [cubs[i] for i in slot.tolist()]
    frame_of_slot = np.repeat(np.arange(len(keys), dtype=np.int32), frame_len)

    def where(i: int) -> str:
        return f"frame {keys[frame_of_slot[slot[i]]]} object {uids[slot[i]]}"

    cub = _cuboids(cubs, where)
    systems = systems or CoordinateSystems(None)
    edges: dict[int, dict] = {}
    resolved: dict[tuple, tuple] = {}
    unknown: dict[str, int] = {}

    def resolve(i: int) -> tuple:
        j, name = int(frame_of_slot[slot[i]]), cub["cs"][i]
        key = (name, j if j in props_of else -1)
        if key not in resolved:
            if j not in edges:
                edges[j] = systems.frame_edges(props_of.get(j, {}).get("transforms"))
            resolved[key] = systems.resolve(name, edges[j])
            if name is not None and name in systems.unknown:
                unknown.setdefault(name, i)
        return resolved[key]

    cols = {"slot": slot, **place(cub["v"], cub["nval"], cub["cs"], resolve, where), "cub_ts": cub["cub_ts"]}
    subtypes = _subtypes(uids, slot, cubs)
    cols["bad"] = implausible_size(np.column_stack([cols["dl"], cols["dw"], cols["dh"]])) if len(cubs) \
        else np.zeros(0, bool)
    at = _Attributes(ods, lenient)
    cols.update(_attribute_columns(at, len(cubs)))
    types: dict[str, str] = {}
    if all_types.count(None) < len(all_types):  # (a type inside a frame's object_data: TUM Traffic)
        for u, t in zip(uids, all_types):
            if isinstance(t, str):
                types.setdefault(u, t)
    found = _findings(at) + [("source.openlabel.unknown_coordinate_system", name, i, 1) for name, i in unknown.items()]
    interior = [(int(slot[i]), irow) for i in at.boxes_with_prefix("interior/")
                if (irow := interior_signals(_box_attributes(ods[i])))]
    stamps = [_stamp(fr.frame_properties) if "timestamp" in p else None for fr, p in zip(frames.values(), props)]
    return Block(keys=keys, stamps=stamps, props=props_of, uids=uids,
                 frame_len=frame_len, frame_of_slot=frame_of_slot, cols=cols, ext=_extension(cubs),
                 interior=interior, types=types, found=found, lenient=lenient, shapes=shapes,
                 subtypes=subtypes)


def _subtypes(uids: list[str], slot: np.ndarray, cubs: list) -> dict[str, str]:
    """Per object of the block the text attribute ``type`` of its first box that has one there
    (a generic label's subtype: OSDaR's ``road_vehicle`` of type truck, :func:`~aveas_format.
    converters.labels.refine`); the attributes decoded only of each object's first box."""
    if list(map(attrgetter("attributes"), cubs)).count(_NULL) == len(cubs):  # (no cuboid attributes: an export)
        return {}
    first = dict(zip(map(uids.__getitem__, slot[::-1].tolist()), range(len(slot) - 1, -1, -1)))
    out: dict[str, str] = {}
    for u, i in first.items():
        raw = cubs[i].attributes
        if raw is _NULL or b'"type"' not in bytes(raw):
            continue
        try:
            at = _ANY.decode(raw)
        except msgspec.DecodeError:
            continue
        texts = at.get("text") if isinstance(at, dict) else None
        for it in texts if isinstance(texts, list) else [texts]:
            if isinstance(it, dict) and it.get("name") == "type" and isinstance(it.get("val"), str):
                out[u] = it["val"]
                break
    return out


def _shapes(uids: list[str], ods: list, rows: list[int]) -> dict[str, set[str]]:
    """Per object of the boxes ``rows`` (without a cuboid) the kinds of :data:`SHAPES` it carries
    there (only objects without a box are reported: the kinds are what their report says)."""
    out: dict[str, set[str]] = {}
    for i in rows:
        od = ods[i]
        kinds = {k for k in SHAPES if (v := getattr(od, k)) is not _NULL and bytes(v) != b"null"}
        out.setdefault(uids[i], set()).update(kinds)
    return out


def _bounding_boxes(cubs: list) -> list:
    """:func:`_bounding_box` of each box's cuboids: at once where each has a list whose first is
    the ``bounding_box`` with a value (the profile's layout)."""
    if cubs and set(map(type, cubs)) == {list} and 0 not in map(len, cubs):
        first = list(map(itemgetter(0), cubs))
        if list(map(_NAME, first)).count("bounding_box") == len(first) and _NULL not in map(_VAL, first):
            return first
    return list(map(_bounding_box, cubs))


def _bounding_box(cubs: Any) -> Any:
    """The cuboid named ``bounding_box``, else the first (a single cuboid object: TUM Traffic);
    None where there is none or it has no ``val``."""
    if not cubs:
        return None
    if not isinstance(cubs, list):
        cub = cubs
    else:
        cub = cubs[0] if cubs[0].name == "bounding_box" else next(
            (c for c in cubs if c.name == "bounding_box"), cubs[0])
    return None if cub.val == _NULL else cub


def _tidied(frames: Any) -> dict:
    """Frames decoded without types, with what the typed layout cannot hold dropped as the profile
    reads it: a frame, object or ``object_data`` that is no object, list items that are no objects
    (a single item object as a list of one)."""
    if not isinstance(frames, dict):
        raise FormatError("'openlabel.frames' is not an object")
    out = {}
    for k, fr in frames.items():
        fr = fr if isinstance(fr, dict) else {}
        objs = fr.get("objects") or {}
        if not isinstance(objs, dict):
            raise FormatError(f"frame {k}: 'objects' is not an object")
        tidy = {}
        for u, oif in objs.items():
            od = oif.get("object_data") if isinstance(oif, dict) else None
            if not isinstance(od, dict):
                tidy[u] = {}
                continue
            od = {c: (v if isinstance(v, dict) or c not in ("cuboid", *_KINDS) else
                      [x for x in v if isinstance(x, dict)] if isinstance(v, list) else None)
                  for c, v in od.items() if c in ("cuboid", "type", *_KINDS, *SHAPES)}
            tidy[u] = {"object_data": od}
        out[k] = {"objects": tidy, "frame_properties": fr.get("frame_properties")}
    return out


def _cuboids(cubs: list, where) -> dict[str, np.ndarray]:
    """The cuboids' values (``v``: n x 9 where all have 9, else n x 10, NaN after the ``nval``
    given), coordinate systems
    (``cs``: None for the root) and per-box timestamps (``cub_ts``: the ASAM example's cuboid
    attribute ``timestamp``, NaN where absent)."""
    n = len(cubs)
    raws = list(map(_VAL, cubs))
    v = vals = _matrix(raws)
    if v is None:
        try:
            vals = _CUBOIDS.decode(joined(raws))
        except msgspec.ValidationError:
            i = next(i for i, r in enumerate(raws) if not _numbers(r))
            raise FormatError(f"{where(i)}: cuboid val holds non-numbers: "
                              f"{bytes(raws[i])[:80].decode(errors='replace')}") from None
    nval = np.fromiter(map(len, vals), np.int8, n) if v is None else np.full(n, v.shape[1], np.int8)
    if n and (nval == 9).all():  # (the profile's: no quaternion, no tenth value)
        v = np.array(vals, float) if v is None else v
    else:
        v = np.full((n, max(10, int(nval.max(initial=0)))), np.nan)
        for i, x in enumerate(vals):
            v[i, :len(x)] = x
        v = v[:, :10]
    cs = list(map(attrgetter("coordinate_system"), cubs))
    cs = np.array([c or None for c in cs], object) if cs.count(None) < n else np.full(n, None, object)
    cub_ts = np.full(n, np.nan)
    attrs = list(map(attrgetter("attributes"), cubs))
    if attrs.count(_NULL) < n:
        for i, a in enumerate(attrs):
            if a != _NULL:
                t = first_value(attributes_of(_ANY.decode(a)), "timestamp")
                if isinstance(t, (int, float)) and not isinstance(t, bool):
                    cub_ts[i] = float(t)
    return {"v": v, "nval": nval, "cs": cs, "cub_ts": cub_ts}


_ROWS = bytes.maketrans(b"|", b"\n")  # (the raw values joined by "|" -> CSV rows)


def _matrix(raws: list) -> np.ndarray | None:
    """The raw values (valid JSON) as the rows of a matrix where all are lists of ``k`` numbers,
    parsed at once as CSV rows (Arrow's: correctly rounded as msgspec's), else None (also where
    msgspec's float differs: an integer ``-0``, a number out of range)."""
    text = b"|".join(raws)
    skeleton = text.translate(None, b"0123456789.-+eE \t\r\n")  # (of n lists of k numbers: "[,,]|[,,]")
    k = skeleton.find(b"]")
    if not raws or skeleton != b"|".join([b"[" + b"," * (k - 1) + b"]"] * len(raws)):
        return None
    rows = text.translate(_ROWS, b"[] \t\r\n") + b"\n"
    opts = pcsv.ReadOptions(use_threads=False, block_size=len(rows) + 1, autogenerate_column_names=True)
    try:
        v = np.column_stack([c.to_numpy() for c in pcsv.read_csv(io.BytesIO(rows), opts, convert_options=(
            pcsv.ConvertOptions(column_types={f"f{i}": pa.float64() for i in range(k)}))).columns])
    except pa.ArrowInvalid:  # (an empty list)
        return None
    ok = len(v) == len(raws) and np.isfinite(v).all()
    return v if ok and not (np.signbit(v[v == 0]).any() and (b"-0," in rows or b"-0\n" in rows)) else None


def _numbers(raw: msgspec.Raw) -> bool:
    try:
        _CUBOIDS.decode(b"[" + raw + b"]")
        return True
    except msgspec.ValidationError:
        return False


class _Attributes:
    """The attribute items of ``n`` boxes by name: :meth:`first` gives the boxes that have a name
    and the raw value of its first item (kinds in the order boolean, num, text, vec). Where every box lists the same names in the same order (an export: the
    common case) a name's values are a stride of the items, else the items are grouped by name."""

    def __init__(self, ods: list, lenient: bool) -> None:
        self.n = n = len(ods)
        self.lenient = lenient
        self.where: dict[str, tuple] = {}  # name -> (the items of each box) or (boxes, raw values)
        for kind in _KINDS:
            lists = list(map(attrgetter(kind), ods))
            if not any(lists):  # (no item of the kind in the block: boolean in an export)
                continue
            if set(map(type, lists)) != {list}:
                lists = [x if isinstance(x, list) else [x] if x is not None else [] for x in lists]
            lens = list(map(len, lists))
            if not max(lens, default=0):
                continue
            flat = list(chain.from_iterable(lists))
            key, k = list(map(_NAME if lenient else type, flat)), lens[0]  # (strict layout: a type is a name)
            names = key[:k] if lenient else list(map(_NAME_OF.__getitem__, key[:k]))
            if min(lens) == k and key == key[:k] * n and all(isinstance(nm, str) for nm in names):  # (one order)
                for pos, nm in enumerate(names):
                    if nm not in _UNREAD:
                        self.where.setdefault(nm, (flat[pos::k],))
                continue
            self._grouped(flat, key if lenient else list(map(_NAME_OF.__getitem__, key)), np.repeat(np.arange(n), lens))

    def _grouped(self, flat: list, names: list, box: np.ndarray) -> None:
        try:
            enc = pc.dictionary_encode(pa.array(names, pa.string()))
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # (names that are no text: never read)
            enc = pc.dictionary_encode(pa.array([v if isinstance(v, str) else None for v in names], pa.string()))
        codes = enc.indices.fill_null(-1).to_numpy(zero_copy_only=False)
        order = np.argsort(codes, kind="stable")  # (by name, then in file order: by box)
        bounds = np.searchsorted(codes[order], np.arange(len(enc.dictionary) + 1))
        for k, name in enumerate(enc.dictionary.to_pylist()):
            if name in _UNREAD:
                continue
            sel = order[bounds[k]:bounds[k + 1]]
            b, first = np.unique(box[sel], return_index=True)
            got = (b, list(map(_VAL, map(flat.__getitem__, sel[first].tolist()))))
            if name in self.where:  # (an earlier kind's item first, in the boxes that have one)
                merged = dict(zip(got[0].tolist(), got[1]))
                before = self.first(name)
                merged.update(zip(before[0].tolist(), before[1]))
                keys = sorted(merged)
                got = (np.asarray(keys, np.int64), [merged[i] for i in keys])
            self.where[name] = got

    def first(self, name: str) -> tuple[np.ndarray, list]:
        """``(boxes that have the name, the value of its first item in each)``."""
        w = self.where.get(name)
        if w is None:
            return np.zeros(0, np.int64), []
        if len(w) == 1:  # (the values of a stride, once)
            self.where[name] = w = (np.arange(self.n), list(map(_VAL, w[0])))
        return w

    def boxes_with_prefix(self, prefix: str) -> list[int]:
        return sorted(set(chain.from_iterable(self.first(nm)[0].tolist() for nm in self.where
                                              if nm.startswith(prefix))))


def _attribute_columns(at: _Attributes, n: int) -> dict[str, np.ndarray]:
    """The columns of :data:`~.profile.FRAME_ATTRIBUTES` (NaN or None where a box has no value),
    ``has:NAME`` (the box has a non-null value) for each vector, the road (``road_id``: the text
    of ``used_road_link``, else ``open_drive/road_id``, where the box also has road coordinates;
    ``lane_id`` as an integer, None where not one) and the flags ``hv`` (a velocity), ``hacc`` (a
    finite acceleration), ``hr`` (road coordinates)."""
    cols: dict[str, np.ndarray] = {}
    for name, (shape, target) in FRAME_ATTRIBUTES.items():
        boxes, vals = at.first(name)
        if shape == "vector":
            whole = len(boxes) == n
            table = _vectors(vals)
            if table is not None:  # (one length: a matrix)
                cols[f"has:{name}"] = np.ones(n, bool) if whole else np.isin(np.arange(n), boxes)
                for col, e in target.items():
                    if whole and e < table.shape[1]:
                        cols[col] = table[:, e].copy()
                    else:
                        cols[col] = a = np.full(n, np.nan)
                        if e < table.shape[1]:
                            a[boxes] = table[:, e]
                continue
            vals = _vector_values(vals)
            cols[f"has:{name}"] = has = np.zeros(n, bool)
            has[boxes] = np.fromiter(map(is_not, vals, repeat(None)), bool, len(vals))
            for col, e in target.items():
                cols[col] = a = np.full(n, np.nan)
                a[boxes] = [np.nan if v is None or len(v) <= e or v[e] is None else v[e] for v in vals]
        elif shape == "number":
            cols[target] = a = np.full(n, np.nan)
            a[boxes] = _number_values(vals)
        else:
            vals = _ANY.decode(joined(vals)) if vals else []
            if shape == "flag":
                cols[target] = a = np.full(n, np.nan)
                a[boxes] = [np.nan if v is None else float(bool(v)) for v in vals]
            else:
                cols[target] = a = np.full(n, None, object)
                a[boxes] = vals
    road, alt = cols.pop("road_link"), cols.pop("road_alt")
    road = np.where(np.equal(road, None), alt, road)
    given = ~np.equal(road, None)
    on = given & cols["has:open_drive/local_road_coordinates"]
    cols["road_s"] = np.where(given, cols["road_s"], np.nan)
    cols["road_t"] = np.where(given, cols["road_t"], np.nan)
    cols["road_id"] = _each(str, np.where(on, road, None))
    cols["lane_id"] = _each(_lane, np.where(given, cols.pop("lane_code"), None))
    cols["hv"], cols["hr"] = cols["has:velocity"], on
    cols["hacc"] = np.isfinite(cols["au"]) & np.isfinite(cols["av"])
    return cols


def _vectors(raws: list) -> np.ndarray | None:
    """The raw values as the rows of a matrix where all are lists of numbers of one length (a value
    that every box repeats decoded once), else None."""
    if not raws:
        return None
    try:
        if raws[-1] == raws[0] and raws.count(raws[0]) == len(raws):
            row = _CUBOIDS.decode(b"[" + raws[0] + b"]")[0]
            return np.tile(np.asarray(row, float), (len(raws), 1))
        if (m := _matrix(raws)) is not None:
            return m
        vals = _CUBOIDS.decode(joined(raws))
    except msgspec.ValidationError:
        return None
    return np.array(vals, float).reshape(len(vals), -1) if len(set(map(len, vals))) == 1 else None


def _vector_values(raws: list) -> list:
    """Raw values as lists of floats (None: null or no list; NaN for an element that is no number)."""
    if not raws:
        return []
    try:
        return _VECTORS.decode(joined(raws))
    except msgspec.ValidationError:  # (no list, or elements that are no numbers)
        return [[_float(x) for x in v] if isinstance(v, list) else None if v is None else []
                for v in _ANY.decode(joined(raws))]


def _number_values(raws: list) -> list[float]:
    if not raws:
        return []
    try:
        return [np.nan if x is None else x for x in _NUMBERS.decode(joined(raws))]
    except msgspec.ValidationError:
        return [_float(x) for x in _ANY.decode(joined(raws))]


def _float(x: Any) -> float:
    try:
        return float(x) if x is not None and not isinstance(x, (list, dict)) else np.nan
    except (TypeError, ValueError):
        return np.nan


def _each(fn, values: np.ndarray) -> np.ndarray:
    """``fn`` of each value that is not None (an object array), each distinct value once."""
    out = np.full(len(values), None, object)
    idx = np.flatnonzero(~np.equal(values, None))
    if not len(idx):
        return out
    vals = values[idx].tolist()
    try:
        enc = pa.array(vals, pa.string()).dictionary_encode()  # (texts, the profile's: at once)
        out[idx] = np.array([fn(v) for v in enc.dictionary.to_pylist()], object)[enc.indices.to_numpy()]
        return out
    except (pa.ArrowInvalid, pa.ArrowTypeError):
        pass
    done: dict = {}
    for i, v in zip(idx.tolist(), vals):
        try:
            out[i] = done[v] if v in done else done.setdefault(v, fn(v))
        except TypeError:  # (unhashable)
            out[i] = fn(v)
    return out


def _lane(v: Any) -> int | None:
    """A lane id as an integer (an enum text of aveas-openlabel read as its value), else None."""
    try:
        return int(str(enum_value(v)))
    except ValueError:
        return None


#: the Arrow type of the extension's members of the last block
_EXT_TYPE: dict[str, pa.DataType] = {}


def _extension(cubs: list) -> dict[str, tuple[pa.Array, np.ndarray]]:
    """The ``aveas_format`` items of the boxes' cuboids: per member its values (Arrow, types
    inferred; null where missing) and where the member is present."""
    raws = list(map(_EXT, cubs))
    if raws.count(_NULL) == len(raws):
        return {}
    items = _ANY.decode(joined(raws))
    items = [e if isinstance(e, dict) else {} for e in items] if set(map(type, items)) != {dict} else items
    try:  # (all members as one struct: null where missing or null, told apart where there are nulls)
        sa = None
        known = _EXT_TYPE.get("type")  # (the type of the last block: no inference)
        if known is not None:
            try:
                sa = pa.array(items, known)
            except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
                pass
        # (as many values as members, a value only where its member is: every member given a
        # value, and no other, so present where valid; else the types inferred, the nulls told apart)
        given = sum(map(len, items))
        if not (full := sa is not None and _valid(sa) == given):
            sa = pa.array(items)
            _EXT_TYPE["type"] = sa.type
            full = _valid(sa) == given
        return {f.name: (sa.field(i), (sa.field(i).is_valid().to_numpy(zero_copy_only=False) if full else
                                       np.fromiter(map(contains, items, repeat(f.name)), bool, len(items)))
                         if sa.field(i).null_count else np.ones(len(items), bool))
                for i, f in enumerate(sa.type)}
    except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
        pass
    out = {}
    for c in dict.fromkeys(chain.from_iterable(items)):
        present = np.fromiter(map(contains, items, repeat(c)), bool, len(items))
        try:
            out[c] = (pa.array(list(map(methodcaller("get", c), items)), from_pandas=False), present)
        except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
            raise FormatError(f"the {EXT} member {c!r} of the boxes mixes values of several types") from None
    return out


def _valid(sa: pa.StructArray) -> int:
    """The number of values of the struct's members (not null)."""
    return sum(len(sa) - f.null_count for f in sa.flatten())


def _box_attributes(od: Any) -> dict[str, list[dict[str, Any]]]:
    """One box's attribute items by name, their values decoded (as :func:`~.profile.attributes_of`)."""
    items = {kind: [{"name": _NAME_OF.get(type(it)) or it.name, "val": _ANY.decode(getattr(it, "val", _NULL))}
                    for it in (x if isinstance(x, list) else [x] if x is not None else [])]
             for kind in _KINDS if (x := getattr(od, kind)) is not None}
    return attributes_of(items)


def interior_signals(attrs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """The interior signals of a box (the lateral automated-control flag carries the longitudinal
    name in ``aveas-openlabel``'s files: a second longitudinal item is the lateral one)."""
    lon_items = attrs.get(LONGITUDINAL) or []
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
                    ("accelerator_pedal", "interior/accelerator_pedal"), ("gear", "interior/gear")):
        val = first_value(attrs, name)
        if val is not None:
            irow[c] = val
    return irow


def _findings(at: _Attributes) -> list[tuple[str, str, int, int]]:
    """The checks of the source on a block's attributes: PMF attributes (``*/uncertainties``) that
    do not sum to 1, and boxes without a mandatory attribute of the profile (kept by the reader
    for files that claim it). Per finding ``(code, attribute, first box, count)``."""
    out = []
    for name in at.where:
        if name.endswith("/uncertainties"):
            boxes, vals = at.first(name)
            vals = _ANY.decode(joined(vals))
            bad = np.fromiter(map(pmf_bad, vals), bool, len(vals))
            if bad.any():
                out.append(("source.openlabel.pmf_sum", name, int(boxes[np.argmax(bad)]), int(bad.sum())))
    for name in MANDATORY_FRAME_ATTRIBUTES:
        has = np.zeros(at.n, bool)
        has[at.first(name)[0]] = True
        if not has.all():
            out.append(("source.openlabel.missing_attribute", name, int(np.argmin(has)), int((~has).sum())))
    return out
