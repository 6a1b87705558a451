"""Serialise a road network to ASAM OpenDRIVE 1.8 XML text (or an older revision on request).

:func:`write_xodr` takes a :class:`~.network.RoadNetwork` (or the ``(header, roads, junctions)``
of :mod:`.model`) and writes every element the model holds, in the element order of the schema
(the same from 1.6 to 1.8). What only newer revisions have is written only to them: a lane's
``direction`` and a link's ``elementS``/``elementDir`` from 1.7 on, a lane link's ``overlapZone``
from 1.8 on. Every map the package writes (builders, fits, converted and built maps) is 1.8 and
passes ASAM qc-opendrive 1.0.0 with 0 issues (tests/opendrive/test_odr_qc.py).
Floats are written with 17 significant digits so that reading the text back gives the same
numbers. Objects and signals are written back from the XML they were read from.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from lxml import etree

from aveas_format.safeio import xml_parser
from .model import Geometry, Header, Junction, Lane, LaneSection, Poly3Record, Road


def _f(v: float) -> str:
    v = float(v)
    if v == 0.0:
        return "0.0"
    return repr(v) if abs(v) >= 1e-4 and abs(v) < 1e16 else f"{v:.17e}"


def _sub(parent: Any, tag: str, attrib: Mapping[str, Any] | None = None) -> Any:
    el = etree.SubElement(parent, tag)
    for k, v in (attrib or {}).items():
        if v is None:
            continue
        el.set(k, _f(v) if isinstance(v, (float, np.floating)) else str(v))
    return el


def _header(root: Any, h: Header, rev_minor: int) -> None:
    el = _sub(
        root,
        "header",
        {
            "revMajor": 1,
            "revMinor": rev_minor,
            "name": h.name,
            "version": "1.00",
            "date": h.date,
            "north": float(h.north),
            "south": float(h.south),
            "east": float(h.east),
            "west": float(h.west),
            "vendor": h.vendor or None,
        },
    )
    if h.geo_reference:
        geo = _sub(el, "geoReference")
        geo.text = etree.CDATA(h.geo_reference)
    if h.offset is not None:
        x, y, z, hdg = h.offset
        _sub(el, "offset", {"x": float(x), "y": float(y), "z": float(z), "hdg": float(hdg)})


def _geometry(pv: Any, g: Geometry) -> None:
    el = _sub(pv, "geometry", {"s": g.s, "x": g.x, "y": g.y, "hdg": g.hdg, "length": g.length})
    p = g.params
    if g.kind == "line":
        _sub(el, "line")
    elif g.kind == "arc":
        _sub(el, "arc", {"curvature": float(p["curvature"])})
    elif g.kind == "spiral":
        _sub(el, "spiral", {"curvStart": float(p["curv_start"]), "curvEnd": float(p["curv_end"])})
    elif g.kind == "poly3":
        _sub(el, "poly3", {k: float(p[k]) for k in "abcd"})
    elif g.kind == "paramPoly3":
        attrs: dict[str, Any] = {k: float(p[k]) for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
        attrs["pRange"] = p.get("p_range", "normalized")
        _sub(el, "paramPoly3", attrs)
    else:  # pragma: no cover - the reader never makes other kinds
        raise ValueError(f"unknown geometry kind {g.kind!r}")


def _records(parent: Any, tag: str, recs: Iterable[Poly3Record]) -> None:
    for r in recs:
        _sub(parent, tag, {"s": float(r.s), "a": float(r.a), "b": float(r.b), "c": float(r.c), "d": float(r.d)})


def _lane(parent: Any, lane: Lane, rev_minor: int) -> None:
    el = _sub(parent, "lane", {"id": lane.id, "type": lane.type, "level": "true" if lane.level else "false",
                               "direction": lane.direction if rev_minor >= 7 else None})
    if lane.predecessors or lane.successors:
        link = _sub(el, "link")
        for p in lane.predecessors:
            _sub(link, "predecessor", {"id": p})
        for s in lane.successors:
            _sub(link, "successor", {"id": s})
    if lane.id != 0:
        if len(lane.widths) or not len(lane.borders):
            for row in lane.widths:
                _sub(
                    el,
                    "width",
                    {
                        "sOffset": float(row[0]),
                        "a": float(row[1]),
                        "b": float(row[2]),
                        "c": float(row[3]),
                        "d": float(row[4]),
                    },
                )
        else:
            for row in lane.borders:
                _sub(
                    el,
                    "border",
                    {
                        "sOffset": float(row[0]),
                        "a": float(row[1]),
                        "b": float(row[2]),
                        "c": float(row[3]),
                        "d": float(row[4]),
                    },
                )
    for rm in lane.road_marks:
        attrs = dict(rm.attributes)
        attrs["sOffset"] = _f(rm.s_offset)
        attrs.setdefault("type", rm.type)
        _sub(el, "roadMark", attrs)
    if lane.id != 0:
        for s_off, vmax, unit in lane.speeds:
            _sub(el, "speed", {"sOffset": float(s_off), "max": float(vmax), "unit": unit})
        for s_off, inner, outer in lane.heights:
            _sub(el, "height", {"sOffset": float(s_off), "inner": float(inner), "outer": float(outer)})


def _section(parent: Any, sec: LaneSection, rev_minor: int) -> None:
    el = _sub(parent, "laneSection", {"s": float(sec.s), "singleSide": "true" if sec.single_side else None})
    if sec.left:
        left = _sub(el, "left")
        for lane in sorted(sec.left, key=lambda ln: -ln.id):
            _lane(left, lane, rev_minor)
    center = _sub(el, "center")
    _lane(center, sec.center if sec.center is not None else Lane(id=0, type="none"), rev_minor)
    if sec.right:
        right = _sub(el, "right")
        for lane in sorted(sec.right, key=lambda ln: -ln.id):
            _lane(right, lane, rev_minor)


def _road(root: Any, road: Road, rev_minor: int) -> None:
    el = _sub(
        root,
        "road",
        {
            "name": road.name,
            "length": float(road.length),
            "id": road.id,
            "junction": road.junction or "-1",
            "rule": road.rule,
        },
    )
    if road.predecessor or road.successor:
        link = _sub(el, "link")
        for tag, lk in (("predecessor", road.predecessor), ("successor", road.successor)):
            if lk is not None:
                _sub(
                    link,
                    tag,
                    {"elementType": lk.element_type, "elementId": lk.element_id, "contactPoint": lk.contact_point,
                     "elementS": lk.element_s if rev_minor >= 7 else None,
                     "elementDir": lk.element_dir if rev_minor >= 7 else None},
                )
    for rt in road.types:
        t = _sub(el, "type", {"s": float(rt.s), "type": rt.type, "country": rt.country})
        if rt.speed_max is not None:
            _sub(t, "speed", {"max": rt.speed_max, "unit": rt.speed_unit})
    pv = _sub(el, "planView")
    for g in road.geometries:
        _geometry(pv, g)
    _records(_sub(el, "elevationProfile"), "elevation", road.elevation)
    _records(_sub(el, "lateralProfile"), "superelevation", road.superelevation)
    lanes = _sub(el, "lanes")
    _records(lanes, "laneOffset", road.lane_offset)
    for sec in road.lane_sections:
        _section(lanes, sec, rev_minor)
    for tag, items in (("objects", road.objects), ("signals", road.signals)):
        if items:
            box = _sub(el, tag)
            for obj in items:
                box.append(etree.fromstring(obj.xml, xml_parser()) if obj.xml else _plain_object(obj))


def _plain_object(obj: Any) -> Any:
    el = etree.Element(obj.kind)
    attrs = dict(obj.attributes)
    attrs.update({"id": obj.id, "s": _f(obj.s), "t": _f(obj.t)})
    for k, v in attrs.items():
        el.set(k, str(v))
    return el


def _junction(root: Any, j: Junction, rev_minor: int) -> None:
    el = _sub(root, "junction", {"id": j.id, "name": j.name, "type": j.type if j.type != "default" else None})
    for c in j.connections:
        ce = _sub(
            el,
            "connection",
            {
                "id": c.id,
                "incomingRoad": c.incoming_road,
                "connectingRoad": c.connecting_road,
                "linkedRoad": c.linked_road,
                "contactPoint": c.contact_point,
            },
        )
        for ll in c.lane_links:
            # overlapZone is new in 1.8: left out of older revisions
            zone = ll.overlap_zone if rev_minor >= 8 else None
            _sub(ce, "laneLink", {"from": ll.from_lane, "to": ll.to_lane, "overlapZone": zone})
    for tag, attrs in j.extras:
        _sub(el, tag, attrs)


def write_xodr(network: Any, rev_minor: int = 8) -> str:
    """OpenDRIVE XML text (revision 1.``rev_minor``, default 1.8) of ``network``.

    ``network`` is a :class:`~.network.RoadNetwork`, or a tuple ``(header, roads, junctions)``
    with ``roads``/``junctions`` as dicts or lists of the :mod:`.model` dataclasses.
    """
    if isinstance(network, tuple):
        header, roads, junctions = network
    else:
        header, roads, junctions = network.header, network.roads, network.junctions
    roads = list(roads.values()) if isinstance(roads, Mapping) else list(roads)
    junctions = list(junctions.values()) if isinstance(junctions, Mapping) else list(junctions)
    root = etree.Element("OpenDRIVE")
    _header(root, header, rev_minor)
    for road in roads:
        _road(root, road, rev_minor)
    for j in junctions:
        _junction(root, j, rev_minor)
    body = etree.tostring(root, pretty_print=True, encoding="unicode")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body


__all__ = ["write_xodr"]
