"""The OpenLABEL import's findings about the source (``source.openlabel.*``, rules in
:mod:`aveas_format.validate.rules.source`): located by file, frame key, object uid and JSON path,
one finding per kind at its first place with the count. Reported through
:func:`aveas_format.errors.report_source` (a warning, or collected by ``validate FILE``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from aveas_format.converters.labels import label_kind
from aveas_format.converters.openlabel.profile import (MANDATORY_OBJECT_ATTRIBUTES, TYPE_TO_CLASS, attributes_of,
                                                       first_value, object_type, pmf_bad)
from aveas_format.errors import report_source


def jpath(*keys: Any) -> str | None:
    """A JSONPath into the document: ``$.openlabel.frames['12'].objects['3']...``; None where a key
    is unknown."""
    if any(k is None for k in keys):
        return None
    out = "$.openlabel"
    for k in keys:
        out += f".{k}" if isinstance(k, str) and k.isidentifier() else f"[{str(k)!r}]"
    return out


def claims_profile(md: dict[str, Any], objects: Any) -> bool:
    """Whether a file claims the AVEAS profile: its metadata has the profile's
    ``acquisition_method``, or an object has one of the profile's types (``vehicle/car``...)."""
    if isinstance(md, dict) and md.get("acquisition_method") is not None:
        return True
    return isinstance(objects, dict) and any(
        isinstance(o, dict) and o.get("type") in TYPE_TO_CLASS for o in objects.values())


def report_frame_findings(found: dict[tuple[str, str], list], path: Path | None) -> None:
    """What the checks of the frames found (``(code, attribute or coordinate system) -> [first
    frame, first object, count]``): one finding per kind and attribute, at its first box."""
    file = str(path) if path is not None else None
    unknown = [what for (code, what) in found if code == "source.openlabel.unknown_coordinate_system"]
    for (code, what), (frame, uid, count) in found.items():
        if code == "source.openlabel.unknown_coordinate_system":
            if what != unknown[0]:
                continue  # one finding for all (as the one warning always said)
            msg = ("coordinate system(s) " + ", ".join(map(repr, sorted(unknown)))
                   + " are not in coordinate_systems: taken as the root frame")
            count = len(unknown)
            jp = jpath("frames", frame, "objects", uid, "object_data", "cuboid") if uid else None
        elif code == "source.openlabel.pmf_sum":
            msg = f"{count} value(s) of {what!r} do not sum to 1 (first: frame {frame}, object {uid})"
            jp = jpath("frames", frame, "objects", uid, "object_data", "vec")
        else:
            msg = (f"{count} object(s) in frames lack the profile's mandatory attribute {what!r} "
                   f"(first: frame {frame}, object {uid})")
            jp = jpath("frames", frame, "objects", uid, "object_data")
        report_source(code, f"OpenLABEL: {msg}", count=count, stacklevel=4, file=file,
                      frame=frame, uid=uid, json_path=jp)


def check_objects(uids: list[str], objects: dict[str, Any], frame_types: dict[str, str],
                   profile: bool, path: Path | None) -> None:
    """The objects' findings: a type that is not one of the profile's (in a file that claims the
    profile; in any file a type no table knows, read as ``other``), a ``classification/
    uncertainties`` PMF not summing to 1, a mandatory attribute missing (files that claim the
    profile). One finding per kind (and type or attribute) at its first object, with the count."""

    file = str(path) if path is not None else None
    where = "OpenLABEL: "  # the file is the finding's location
    types: dict[str, list] = {}
    missing: dict[str, list] = {}
    pmfs: list[tuple[str, Any]] = []
    for u in uids:
        otype = object_type(objects, u, frame_types)
        if otype not in TYPE_TO_CLASS and (profile or label_kind(otype) == ("other", "road_user")
                                           and otype.lower() != "other"):
            types.setdefault(otype, [u, 0])[1] += 1
        od = (objects.get(u) if isinstance(objects.get(u), dict) else {}).get("object_data")
        attrs = attributes_of(od if isinstance(od, dict) else None)
        pmf = first_value(attrs, "classification/uncertainties")
        if pmf is not None:
            pmfs.append((u, pmf))
        if profile and u in objects:
            for name in MANDATORY_OBJECT_ATTRIBUTES:
                if first_value(attrs, name) is None:
                    missing.setdefault(name, [u, 0])[1] += 1
    for otype, (u, count) in types.items():
        cls = TYPE_TO_CLASS.get(otype) or label_kind(otype)[0]
        report_source("source.openlabel.unknown_type", where + f"object type {otype!r} is not one of the "
                      f"AVEAS profile's types: read as class {cls} ({count} object(s), first {u})",
                      count=count, stacklevel=3, file=file, uid=u, json_path=jpath("objects", u, "type"))
    for name, (u, count) in missing.items():
        report_source("source.openlabel.missing_attribute", where + f"{count} object(s) lack the "
                      f"profile's mandatory attribute {name!r} (first {u})", count=count, stacklevel=3,
                      file=file, uid=u, json_path=jpath("objects", u, "object_data"))
    if pmfs:
        bad = [u for u, v in pmfs if pmf_bad(v)]
        if bad:
            report_source("source.openlabel.pmf_sum", where + f"{len(bad)} object(s)' "
                          f"'classification/uncertainties' do not sum to 1 (first {bad[0]})",
                          count=len(bad), stacklevel=3, file=file, uid=bad[0],
                          json_path=jpath("objects", bad[0], "object_data", "vec"))


def report_repeats(count: int, frame: Any, uid: str, path: Path | None) -> None:
    report_source("source.openlabel.duplicate_state",
                  f"OpenLABEL: {count} boxes repeat a (participant, time) and were "
                  f"dropped (first: frame {frame}, object {uid})", count=count,
                  stacklevel=4, file=str(path) if path is not None else None, frame=frame,
                  uid=uid, json_path=jpath("frames", frame, "objects", uid))


def report_bad_sizes(count: int, who: set[str], frame: Any, uid: str, path: Path | None) -> None:
    who_ = sorted(who)
    report_source("source.openlabel.bad_size",
                  f"OpenLABEL: dropped {count} boxes with a sentinel or impossible size "
                  f"(<= 0, not finite or > 400 m) of object(s) {', '.join(who_[:5])}"
                  + (" ..." if len(who_) > 5 else ""), count=count, stacklevel=4,
                  file=str(path) if path is not None else None, frame=frame, uid=uid,
                  json_path=jpath("frames", frame, "objects", uid, "object_data", "cuboid"))


def what_objects_have(uids: list[str], objects: dict[str, Any], shapes: dict[str, set[str]]) -> dict[str, str]:
    """Per object (``uids``) what labels it carries without a 3D state: the kinds of
    ``object_data`` (``bbox``, ``poly2d``, ... in its frames, ``shapes``; in ``objects``, a static
    ``cuboid`` too), ``nothing`` where it has none."""
    from aveas_format.converters.openlabel.decode import SHAPES

    out = {}
    for u in uids:
        od = (objects.get(u) or {}).get("object_data") if isinstance(objects.get(u), dict) else None
        static = {k for k in (*SHAPES, "cuboid") if isinstance(od, dict) and od.get(k)}
        kinds = sorted(shapes.get(u, set()) | {k for k in static if k != "cuboid"})
        if "cuboid" in static:
            kinds.append("a static cuboid without time")
        out[u] = "+".join(kinds) if kinds else "nothing"
    return out


def report_no_state(uids: list[str], objects: dict[str, Any], shapes: dict[str, set[str]],
                    path: Path | None) -> None:
    """One finding for the objects left out because no frame gives them a 3D state (a cuboid):
    2D image labels only (``bbox``, ``poly2d``...), a static cuboid without time, or nothing."""
    if not uids:
        return
    have = what_objects_have(uids, objects, shapes)
    by: dict[str, int] = {}
    for v in have.values():
        by[v] = by.get(v, 0) + 1
    kinds = ", ".join(f"{c} with {k}" for k, c in sorted(by.items(), key=lambda kv: -kv[1]))
    first = uids[0]
    report_source("source.openlabel.no_3d_state",
                  f"OpenLABEL: {len(uids)} object(s) have no 3D state (no cuboid in any frame) and are not "
                  f"imported as participants: {kinds}; the first: {first!r} ({have[first]})",
                  count=len(uids), stacklevel=4, file=str(path) if path is not None else None, uid=first,
                  json_path=jpath("objects", first) if first in objects else None)
