"""A block of OpenLABEL frames into box columns: typed decoding with msgspec (the import's one decoder).

:func:`decode_block` takes the bytes of whole frames (``{"key":{...},...}``) and decodes them into
Structs mirroring frames -> objects -> ``object_data`` (members the import does not read are
skipped, as the profile allows). The values are kept as raw JSON (``msgspec.Raw``) and decoded per
attribute for the whole block at once (one typed decode of all boxes' values of a name), so that no
Python object is made per number. The attributes read are those of
:data:`~.profile.FRAME_ATTRIBUTES` (one table: adding one is one line there), found by name in any
kind (``boolean``, ``num``, ``text``, ``vec``; the first item of a name, as the profile reads it).

The result (:class:`Block`, plain data: it is what a worker process sends back) holds per frame its
key, timestamp, transforms and objects, and per box (an object with a cuboid) its object, the
cuboid's values and coordinate system, the attributes' columns, the ``aveas_format`` extension's
members as Arrow arrays, its interior signals and what the checks of the source found.
"""

from __future__ import annotations

from itertools import chain, repeat
from operator import attrgetter, contains, is_not, itemgetter, methodcaller
from typing import Any

import msgspec
import numpy as np
import pyarrow as pa

from aveas_format.converters.labels import implausible_size
from aveas_format.converters.openlabel.geometry import CoordinateSystems, place
from aveas_format.converters.openlabel.profile import (EXT, FRAME_ATTRIBUTES, LONGITUDINAL,
                                                       MANDATORY_FRAME_ATTRIBUTES, attributes_of, enum_value,
                                                       first_value, pmf_bad)
from aveas_format.errors import FormatError

_RAW, _NULL = msgspec.Raw, msgspec.Raw(b"null")


class Cuboid(msgspec.Struct):
    val: msgspec.Raw = _NULL
    name: Any = None
    coordinate_system: Any = None
    attributes: msgspec.Raw = _NULL
    ext: msgspec.Raw = msgspec.field(default=_NULL, name=EXT)


class Item(msgspec.Struct):
    name: Any = None
    val: msgspec.Raw = _NULL


_Items = list[Item] | Item | None


class ObjectData(msgspec.Struct):
    cuboid: list[Cuboid] | Cuboid | None = None
    boolean: _Items = None
    num: _Items = None
    text: _Items = None
    vec: _Items = None
    type: Any = None


class ObjectInFrame(msgspec.Struct):
    object_data: ObjectData | None = None


class Frame(msgspec.Struct):
    objects: dict[str, ObjectInFrame] | None = None
    frame_properties: msgspec.Raw = _NULL


_FRAMES = msgspec.json.Decoder(dict[str, Frame])
_ANY = msgspec.json.Decoder()
_CUBOIDS = msgspec.json.Decoder(list[list[float]])
_VECTORS = msgspec.json.Decoder(list[list[float | None] | None])
_NUMBERS = msgspec.json.Decoder(list[float | None])
_KINDS = ("boolean", "num", "text", "vec")


class Block:
    """What :func:`decode_block` made of a block of frames (module docstring): ``keys``, ``stamps``,
    ``props`` (frame index -> its ``frame_properties``, only frames with ``transforms``), ``uids``
    and ``frame_len`` (the objects of each frame, flat), per box ``cols`` (``slot``: the box's
    object in ``uids``) and ``ext`` (member -> (values, present)), ``interior`` ((slot, signals)),
    ``types`` (object -> type given inside a frame), ``found`` ((code, attribute, box, count))."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


def joined(raws: Any) -> bytes:
    """The JSON array of raw JSON values."""
    return b"[" + b",".join(raws) + b"]"


def decode_block(buf: bytes, offset: int = 0, systems: CoordinateSystems | None = None) -> Block:
    """The frames of ``buf`` (a JSON object of whole frames; ``offset``: where it starts in the
    file, for errors) as a :class:`Block`, the cuboids placed in the root frame of ``systems``
    (the file's coordinate systems; :func:`~.geometry.place`). Broken JSON raises
    :class:`msgspec.DecodeError` (the reader locates it); a layout the typed decoding refuses (an
    attribute list holding numbers, a frame that is no object...) is read as the same values with
    what is no object dropped."""
    try:
        frames = _FRAMES.decode(buf)
    except msgspec.ValidationError:
        frames = _FRAMES.decode(msgspec.json.encode(_tidied(_ANY.decode(buf))))
    except RecursionError:
        raise FormatError(f"JSON nested too deep (in the frames after byte {offset:,})") from None
    keys = list(frames)
    objs = [fr.objects or {} for fr in frames.values()]
    uids = list(chain.from_iterable(objs))
    frame_len = np.fromiter(map(len, objs), np.int32, len(objs))
    props = list(map(_ANY.decode, map(attrgetter("frame_properties"), frames.values())))
    props = [p if isinstance(p, dict) else {} for p in props]
    ods = [o.object_data if o.object_data is not None else _EMPTY for o in chain.from_iterable(map(dict.values, objs))]
    cubs = list(map(_bounding_box, map(attrgetter("cuboid"), ods)))
    has = np.fromiter(map(is_not, cubs, repeat(None)), bool, len(cubs))
    slot = np.flatnonzero(has).astype(np.int32)
    if not has.all():
        ods, cubs = [ods[i] for i in slot.tolist()], [cubs[i] for i in slot.tolist()]
    frame_of_slot = np.repeat(np.arange(len(keys), dtype=np.int32), frame_len)

    def where(i: int) -> str:
        return f"frame {keys[frame_of_slot[slot[i]]]} object {uids[slot[i]]}"

    systems = systems or CoordinateSystems(None)
    cols = {"slot": slot}
    cub = _cuboids(cubs, where)
    edges: dict[int, dict] = {}
    resolved: dict[tuple, tuple] = {}
    unknown: list[tuple[str, int]] = []

    def resolve(i: int) -> tuple:
        j, name = int(frame_of_slot[slot[i]]), cub["cs"][i]
        key = (name, j if j in props_of else -1)
        if key not in resolved:
            if j not in edges:
                edges[j] = systems.frame_edges(props_of.get(j, {}).get("transforms"))
            resolved[key] = systems.resolve(name, edges[j])
            if name is not None and name in systems.unknown and name not in {u for u, _ in unknown}:
                unknown.append((name, i))
        return resolved[key]

    props_of = {j: p for j, p in enumerate(props) if p.get("transforms")}
    cols.update(place(cub["v"], cub["nval"], cub["cs"], resolve, where))
    cols["cub_ts"] = cub["cub_ts"]
    cols["bad"] = implausible_size(np.column_stack([cols["dl"], cols["dw"], cols["dh"]])) if len(cubs) \
        else np.zeros(0, bool)
    at = _Attributes(ods)
    cols.update(_attribute_columns(at, len(cubs)))
    types = {}
    for u, od in zip(uids, (o.object_data for o in chain.from_iterable(map(dict.values, objs)))):
        if od is not None and isinstance(od.type, str):
            types.setdefault(u, od.type)
    found = _findings(at) + [("source.openlabel.unknown_coordinate_system", name, i, 1) for name, i in unknown]
    interior = [(int(slot[i]), irow) for i in at.boxes_with_prefix("interior/")
                if (irow := interior_signals(_box_attributes(ods[i])))]
    return Block(keys=keys, stamps=[p.get("timestamp") for p in props],
                 props=props_of, uids=uids,
                 frame_len=frame_len, cols=cols, ext=_extension(cubs), interior=interior, types=types,
                 found=found, frame_of_slot=frame_of_slot)


_EMPTY = ObjectData()


def _bounding_box(cubs: Any) -> Cuboid | None:
    """The cuboid named ``bounding_box``, else the first (a single cuboid object: TUM Traffic);
    None where there is none or it has no ``val``."""
    if isinstance(cubs, Cuboid):
        cub = cubs
    elif not cubs:
        return None
    else:
        cub = cubs[0] if cubs[0].name == "bounding_box" else next(
            (c for c in cubs if c.name == "bounding_box"), cubs[0])
    return None if cub.val == _NULL else cub


def _box_attributes(od: ObjectData) -> dict[str, list[dict[str, Any]]]:
    """One box's attribute items by name, their values decoded (as :func:`~.profile.attributes_of`)."""
    items = {kind: [{"name": it.name, "val": _ANY.decode(it.val)} for it in
                    (x if isinstance(x, list) else [x] if x is not None else [])]
             for kind in _KINDS if (x := getattr(od, kind)) is not None}
    return attributes_of(items)


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
        fp = fr.get("frame_properties")
        tidy = {}
        for u, oif in objs.items():
            od = oif.get("object_data") if isinstance(oif, dict) else None
            if not isinstance(od, dict):
                tidy[u] = {}
                continue
            od = {c: (v if isinstance(v, dict) or c not in ("cuboid", *_KINDS) else
                      [x for x in v if isinstance(x, dict)] if isinstance(v, list) else None)
                  for c, v in od.items() if c in ("cuboid", "type", *_KINDS)}
            tidy[u] = {"object_data": od}
        out[k] = {"objects": tidy, "frame_properties": fp}
    return out


def _cuboids(cubs: list[Cuboid], where) -> dict[str, np.ndarray]:
    """The cuboids' values (``v``: n x 10, NaN after the ``nval`` given), coordinate systems
    (``cs``: None for the root) and per-box timestamps (``cub_ts``: the ASAM example's cuboid
    attribute ``timestamp``, NaN where absent)."""
    n = len(cubs)
    raws = list(map(attrgetter("val"), cubs))
    try:
        vals = _CUBOIDS.decode(joined(raws))
    except msgspec.ValidationError:
        i = next(i for i, r in enumerate(raws) if not _numbers(r))
        raise FormatError(f"{where(i)}: cuboid val holds non-numbers: "
                          f"{bytes(raws[i])[:80].decode(errors='replace')}") from None
    nval = np.fromiter(map(len, vals), np.int8, n)
    if n and (nval == 9).all():
        v = np.full((n, 10), np.nan)
        v[:, :9] = vals
    else:
        v = np.full((n, max(10, int(nval.max(initial=0)))), np.nan)
        for i, x in enumerate(vals):
            v[i, :len(x)] = x
        v = v[:, :10]
    cs = np.array([c.coordinate_system or None for c in cubs], object) if n else np.zeros(0, object)
    cub_ts = np.full(n, np.nan)
    for i, c in enumerate(cubs):
        if c.attributes != _NULL:
            t = first_value(attributes_of(_ANY.decode(c.attributes)), "timestamp")
            if isinstance(t, (int, float)) and not isinstance(t, bool):
                cub_ts[i] = float(t)
    return {"v": v, "nval": nval, "cs": cs, "cub_ts": cub_ts}


def _numbers(raw: msgspec.Raw) -> bool:
    try:
        _CUBOIDS.decode(b"[" + raw + b"]")
        return True
    except msgspec.ValidationError:
        return False


class _Attributes:
    """The attribute items of ``n`` boxes by name: :meth:`first` gives the boxes that have a name
    and the raw value of its first item (kinds in the order boolean, num, text, vec). Where every
    box lists the same names in the same order (an export: the common case) a name's values are a
    stride of the items, else the items are grouped by name."""

    def __init__(self, ods: list[ObjectData]) -> None:
        self.n = n = len(ods)
        self.where: dict[str, tuple] = {}  # name -> (items, first, step) or (boxes, items)
        for kind in _KINDS:
            lists = [x if isinstance(x, list) else [x] if x is not None else [] for x in map(attrgetter(kind), ods)]
            flat = list(chain.from_iterable(lists))
            if not flat:
                continue
            names = list(map(attrgetter("name"), flat))
            c = len(lists[0])
            if len(flat) == c * n and names == names[:c] * n and all(isinstance(s, str) for s in names[:c]):
                for pos, name in enumerate(names[:c]):
                    self.where.setdefault(name, (flat, pos, c))
                continue
            box = np.repeat(np.arange(n), np.fromiter(map(len, lists), np.int64, n))
            by: dict[str, list[int]] = {}
            for i, name in enumerate(names):
                if isinstance(name, str):
                    by.setdefault(name, []).append(i)
            for name, idx in by.items():
                if name in self.where:
                    prev = self.where[name]
                    boxes, raws = self._boxes(prev)
                    got = dict(zip(box[idx].tolist()[::-1], [flat[i].val for i in idx][::-1]))
                    got.update(zip(boxes.tolist()[::-1], raws[::-1]))
                    order = sorted(got)
                    self.where[name] = (np.asarray(order, np.int64), [got[b] for b in order])
                else:
                    b, first = np.unique(box[idx], return_index=True)
                    self.where[name] = (b, [flat[idx[i]].val for i in first.tolist()])

    def _boxes(self, w: tuple) -> tuple[np.ndarray, list]:
        if len(w) == 3:
            flat, pos, c = w
            return np.arange(self.n), list(map(attrgetter("val"), flat[pos::c]))
        return w

    def first(self, name: str) -> tuple[np.ndarray, list]:
        """``(boxes that have the name, the raw value of its first item in each)``."""
        w = self.where.get(name)
        return (np.zeros(0, np.int64), []) if w is None else self._boxes(w)

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
        boxes, raws = at.first(name)
        if shape == "vector":
            vals = _vector_values(raws)
            cols[f"has:{name}"] = has = np.zeros(n, bool)
            has[boxes] = np.fromiter(map(is_not, vals, repeat(None)), bool, len(vals))
            table = _matrix(vals)
            for col, e in target.items():
                cols[col] = a = np.full(n, np.nan)
                if table is not None:
                    if e < table.shape[1]:
                        a[boxes] = table[:, e]
                else:
                    a[boxes] = [_element(v, e) for v in vals]
        elif shape == "number":
            cols[target] = a = np.full(n, np.nan)
            a[boxes] = _number_values(raws)
        else:
            vals = _ANY.decode(joined(raws)) if raws else []
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
    texts: dict = {}
    cols["road_id"] = np.array([(texts[r] if r in texts else texts.setdefault(r, str(r))) if o else None
                                for r, o in zip(road.tolist(), on.tolist())], object)
    lanes = np.where(given, cols.pop("lane_code"), None).tolist()
    cols["lane_id"] = np.array([_lane(x) for x in lanes], object) if any(x is not None for x in lanes) \
        else np.full(n, None, object)
    cols["hv"], cols["hr"] = cols["has:velocity"], on
    cols["hacc"] = np.isfinite(cols["au"]) & np.isfinite(cols["av"])
    return cols


def _vector_values(raws: list) -> list:
    """Each raw value as a list of floats (None: null or no list; NaN for an element that is no
    number)."""
    if not raws:
        return []
    try:
        return _VECTORS.decode(joined(raws))
    except msgspec.ValidationError:  # (no list, or elements that are no numbers)
        return [[_float(x) for x in v] if isinstance(v, list) else None if v is None else []
                for v in _ANY.decode(joined(raws))]


def _matrix(vals: list) -> np.ndarray | None:
    """The vectors as the rows of a matrix where all are lists of one length (None in a list: NaN)."""
    if vals and None not in vals and len(set(map(len, vals))) == 1:
        return np.array(vals, float).reshape(len(vals), -1)
    return None


def _element(v: list | None, e: int) -> float:
    return np.nan if v is None or len(v) <= e or v[e] is None else v[e]


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


def _lane(v: Any) -> int | None:
    """A lane id as an integer (an enum text of aveas-openlabel read as its value), else None."""
    if v is None:
        return None
    try:
        return int(str(enum_value(v)))
    except ValueError:
        return None


def _extension(cubs: list[Cuboid]) -> dict[str, tuple[pa.Array, np.ndarray]]:
    """The ``aveas_format`` items of the boxes' cuboids: per member its values (Arrow, types
    inferred; null where missing) and where the member is present."""
    raws = list(map(attrgetter("ext"), cubs))
    if all(r == _NULL for r in raws):
        return {}
    items = [e if isinstance(e, dict) else {} for e in _ANY.decode(joined(raws))]
    out = {}
    for c in dict.fromkeys(chain.from_iterable(items)):
        present = np.fromiter(map(contains, items, repeat(c)), bool, len(items))
        vals = list(map(methodcaller("get", c), items))
        try:
            out[c] = (pa.array(vals, from_pandas=False), present)
        except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
            raise FormatError(f"the {EXT} member {c!r} of the boxes mixes values of several types") from None
    return out


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
            boxes, raws = at.first(name)
            bad = np.fromiter(map(pmf_bad, _ANY.decode(joined(raws))), bool, len(raws))
            if bad.any():
                out.append(("source.openlabel.pmf_sum", name, int(boxes[np.argmax(bad)]), int(bad.sum())))
    for name in MANDATORY_FRAME_ATTRIBUTES:
        has = np.zeros(at.n, bool)
        has[at.first(name)[0]] = True
        if not has.all():
            out.append(("source.openlabel.missing_attribute", name, int(np.argmin(has)), int((~has).sum())))
    return out
