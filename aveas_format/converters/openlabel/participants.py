"""The participants of an OpenLABEL import: one per object imported, from its type (in ``objects``,
or inside a frame's ``object_data`` as TUM Traffic writes it) and static attributes (the size,
else the median of its boxes; the classification PMF, ``is_recorder``, ``attached_to``), with the
extension items of this library's own export.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.labels import implausible_size, refine
from aveas_format.converters.openlabel.profile import TYPE_TO_CLASS, attributes_of, first_value, object_type
from aveas_format.schema.taxonomy import CLASSES

#: an extension value an object does not carry (``None`` is a value: null)
MISSING = object()


def participants_of(uids: list[str], objects: dict[str, Any], pid_of: dict[str, int], obj_ext: dict,
                    sizes: dict[str, list], ext: dict[str, Any] | None, frame_types: dict[str, str],
                    subtypes: dict[str, str] | None = None) -> tuple[dict[str, Any], bool]:
    """``(participants columns, whether an object is the recording vehicle)``; ``subtypes``: per
    object its boxes' ``type`` attribute (the class of a generic label, :func:`refine`)."""
    part, ego_seen = _profile_participants(uids, objects, pid_of, sizes, frame_types, subtypes or {})
    if all(v is None for v in part["class_pmf"]):
        del part["class_pmf"]
    else:
        from aveas_format.schema.pmf import one_hot

        part["class_pmf"] = [v if v is not None else one_hot([c], "class")[0].tolist()
                             for v, c in zip(part["class_pmf"], part["class"])]
        m = np.asarray(part["class_pmf"], np.float32)
        part["class_pmf"] = pa.array(list(m), pa.list_(pa.float32()))
        # the class is the PMF's argmax (a foreign file may disagree; the PMF wins)
        part["class"] = [CLASSES[int(np.argmax(r))] if not obj_ext.get(u) else c
                         for r, c, u in zip(m, part["class"], uids)]
    for c in ("attached_to", "height", "length_std", "width_std", "height_std"):
        if c in part and all(v is None for v in part[c]):
            del part[c]
    p_ext_rows = [obj_ext.get(u) for u in uids]
    if any(e for e in p_ext_rows):
        _apply_participants_extension(part, p_ext_rows)
    pcols = (ext or {}).get("participants_columns")
    if pcols:
        for c in list(part):
            if c not in pcols:
                del part[c]
    participants = {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(v))
                    for c, v in part.items()}
    if not uids:  # a file without objects (e.g. the profile's minimum example)
        participants = {"participant_id": pa.array([], pa.int64()), "class": pa.array([], pa.string()),
                        "length": pa.array([], pa.float64()), "width": pa.array([], pa.float64())}
    return participants, ego_seen


def _profile_participants(uids: list[str], objects: dict[str, Any], pid_of: dict[str, int],
                          sizes: dict[str, list], frame_types: dict[str, str], subtypes: dict[str, str]
                          ) -> tuple[dict[str, list], bool]:
    """The participants' columns from the objects' types (in ``objects``, or inside a frame's
    object_data as TUM Traffic writes them) and static attributes (the size, else the median of
    the object's boxes; a static size with a sentinel value is ignored)."""
    part: dict[str, list] = defaultdict(list)
    ego_seen = False
    for u in uids:
        obj = objects.get(u) or {}
        attrs = attributes_of(obj.get("object_data"))
        otype = object_type(objects, u, frame_types)
        cls = TYPE_TO_CLASS.get(otype) or refine(otype, subtypes.get(u))
        is_ego = otype.lower() in ("egocar", "ego", "ego_vehicle") or bool(first_value(attrs, "is_recorder", False))
        ego_seen |= is_ego
        size = _static_size(first_value(attrs, "dimensions/size"))
        if size is None:
            size = list(sizes.get(u, [1.0, 1.0, 1.0]))  # (the median of its boxes)
        ssd = first_value(attrs, "dimensions/size/ustddev")
        pmf = first_value(attrs, "classification/uncertainties")
        part["participant_id"].append(pid_of[u])
        part["source_id"].append(str(obj.get("name") or u))
        part["class"].append(cls)
        part["length"].append(float(size[0]))
        part["width"].append(float(size[1]))
        part["height"].append(float(size[2]) if len(size) > 2 and size[2] else None)
        part["length_std"].append(float(ssd[0]) if ssd else None)
        part["width_std"].append(float(ssd[1]) if ssd else None)
        part["height_std"].append(float(ssd[2]) if ssd and len(ssd) > 2 else None)
        part["class_pmf"].append([float(v) for v in pmf] if pmf and len(pmf) == len(CLASSES) else None)
        att = first_value(attrs, "attached_to")
        part["attached_to"].append(pid_of.get(str(att)) if att is not None else None)
        part["role"].append("recording_vehicle" if is_ego else "observed")
    return part, ego_seen


def _static_size(size: Any) -> list | None:
    """An object's static ``dimensions/size`` (length, width[, height]), or None where absent or
    a sentinel (a -1000, a 0, not numbers)."""
    if not isinstance(size, (list, tuple)) or len(size) < 2:
        return None
    try:
        arr = np.asarray([[float(v) for v in size[:3]] + [np.nan] * (3 - len(size[:3]))])
    except (TypeError, ValueError):
        return None
    return None if implausible_size(arr)[0] else list(size)


def _apply_participants_extension(part: dict[str, Any], p_ext_rows: list) -> None:
    """The participants' extension items of this library's own export into ``part``."""
    keys = sorted({c for e in p_ext_rows if e for c in e} - {"participant_id"})
    for c in keys:
        vals = [e.get(c, MISSING) if e else MISSING for e in p_ext_rows]
        cur = part.get(c)
        if c == "class_pmf":
            mats = [None if v is MISSING else v for v in vals]
            if cur is not None:
                curl = cur.to_pylist()
                mats = [curl[i] if v is MISSING else v for i, v in enumerate(vals)]
            part[c] = pa.array(mats, pa.list_(pa.float32()))
            continue
        if cur is None:
            part[c] = [None if v is MISSING else v for v in vals]
        else:
            part[c] = [cur[i] if v is MISSING else v for i, v in enumerate(vals)]
