"""Parse ASAM OpenDRIVE 1.4-1.8 XML (lxml) into the dataclasses of :mod:`.model`.

Tolerant of what real files do (an XML comment before the ``<?xml ...?>`` declaration, missing
optional attributes, unknown elements, ``<userData>``) and strict about what makes a map unusable:
a missing or non-numeric required attribute, a ``<geometry>`` without a known shape, a road without
a plan view or lanes, duplicate road ids. Each of those raises :class:`~aveas_format.errors.MapError`
naming the file and the XML line (lxml keeps ``sourceline`` for every element).
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
from lxml import etree

from ..errors import MapError
from aveas_format.safeio import xml_parser, xml_source
from .model import (
    Connection,
    Geometry,
    Header,
    Junction,
    Lane,
    LaneLink,
    LaneSection,
    Poly3Record,
    Road,
    RoadLink,
    RoadMark,
    RoadObject,
    RoadType,
)

_REQUIRED = object()
_DECL = re.compile(rb"<\?xml[^>]*\?>")
_ENCODING = re.compile(rb"""encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")


class _Ctx:
    """Parsing context: the source name for error messages."""

    def __init__(self, path: str | None) -> None:
        self.path = path

    def error(self, message: str, el: Any = None, line: int | None = None) -> MapError:
        if line is None and el is not None:
            line = el.sourceline
        return MapError(message, path=self.path or "<map>", line=line)

    # -- attribute helpers ---------------------------------------------------------------------
    def _present(self, el: Any, name: str, default: Any) -> str | None:
        """The attribute's text, or None where it is absent/empty and ``default`` applies
        (a MapError where the attribute is required)."""
        raw = el.get(name)
        if raw is None or raw.strip() == "":
            if default is _REQUIRED:
                raise self.error(f"<{el.tag}> lacks the required attribute {name!r}", el)
            return None
        return raw

    def num(self, el: Any, name: str, default: Any = _REQUIRED, *, finite: bool = True) -> float:
        raw = self._present(el, name, default)
        if raw is None:
            return default
        try:
            value = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {name}={raw!r} is not a number", el) from None
        if finite and not math.isfinite(value):
            raise self.error(f"<{el.tag}> attribute {name}={raw!r} is not finite", el)
        return value

    def integer(self, el: Any, name: str, default: Any = _REQUIRED) -> int:
        raw = self._present(el, name, default)
        if raw is None:
            return default
        try:
            value = float(raw)
        except ValueError:
            raise self.error(f"<{el.tag}> attribute {name}={raw!r} is not an integer", el) from None
        if not value.is_integer():
            raise self.error(f"<{el.tag}> attribute {name}={raw!r} is not an integer", el)
        return int(value)

    def text(self, el: Any, name: str, default: Any = _REQUIRED) -> str:
        raw = el.get(name)
        if raw is None:
            if default is _REQUIRED:
                raise self.error(f"<{el.tag}> lacks the required attribute {name!r}", el)
            return default
        return raw.strip()


def _parse_xml(data: bytes, ctx: _Ctx) -> Any:
    """Parse with lxml, tolerating a comment (or anything) before the XML declaration."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    match = _DECL.search(data[:4096])
    if match is not None and data[: match.start()].strip():
        # A declaration that is not at the start is illegal XML; real files do this (a licence
        # comment first). Decode with the declared encoding and drop the declaration, keeping
        # its newlines so that line numbers stay those of the file.
        enc = _ENCODING.search(match.group(0))
        encoding = enc.group(1).decode("ascii") if enc else "utf-8"
        try:
            text = data.decode(encoding)
        except (LookupError, UnicodeDecodeError) as exc:
            raise ctx.error(f"cannot decode the map as {encoding}: {exc}", line=1) from None
        decl = match.group(0).decode("ascii", "replace")
        text = text.replace(decl, "\n" * decl.count("\n"), 1)
        data = text.encode("utf-8")
    parser = xml_parser()
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        line = exc.lineno if exc.lineno else None
        raise ctx.error(f"not well-formed XML: {exc.msg}", line=line) from None
    if root is None:
        raise ctx.error("empty document", line=1)
    tag = etree.QName(root).localname
    if tag != "OpenDRIVE":
        raise ctx.error(f"the root element is <{tag}>, not <OpenDRIVE>", root)
    return root


def _strip_ns(root: Any) -> None:
    """Drop XML namespaces (1.8 files may declare a default namespace)."""
    for el in root.iter():
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = etree.QName(el).localname


# ---------------------------------------------------------------------------------------------
def _header(el: Any, ctx: _Ctx) -> Header:
    h = Header(
        rev_major=ctx.integer(el, "revMajor", 1),
        rev_minor=ctx.integer(el, "revMinor", 4),
        name=el.get("name", ""),
        date=el.get("date", ""),
        vendor=el.get("vendor", ""),
        north=ctx.num(el, "north", 0.0),
        south=ctx.num(el, "south", 0.0),
        east=ctx.num(el, "east", 0.0),
        west=ctx.num(el, "west", 0.0),
        line=el.sourceline,
    )
    geo = el.find("geoReference")
    if geo is not None:
        text = "".join(geo.itertext()).strip()
        h.geo_reference = " ".join(text.split()) or None
    off = el.find("offset")
    if off is not None:
        h.offset = (
            ctx.num(off, "x", 0.0),
            ctx.num(off, "y", 0.0),
            ctx.num(off, "z", 0.0),
            ctx.num(off, "hdg", 0.0),
        )
    return h


def _link(el: Any, ctx: _Ctx) -> RoadLink:
    return RoadLink(
        element_type=ctx.text(el, "elementType", "road"),
        element_id=ctx.text(el, "elementId"),
        contact_point=el.get("contactPoint"),
        element_s=ctx.num(el, "elementS", None),
        element_dir=el.get("elementDir"),
        line=el.sourceline,
    )


def _geometry(el: Any, ctx: _Ctx) -> Geometry:
    shapes = [c for c in el if isinstance(c.tag, str) and c.tag in ("line", "arc", "spiral", "poly3", "paramPoly3")]
    if len(shapes) != 1:
        found = [c.tag for c in el if isinstance(c.tag, str)]
        raise ctx.error(f"<geometry> must hold exactly one of line/arc/spiral/poly3/paramPoly3, found {found}", el)
    shape = shapes[0]
    length = ctx.num(el, "length")
    if length < 0:
        raise ctx.error(f"<geometry> has a negative length {length}", el)
    params: dict[str, Any] = {}
    kind = shape.tag
    if kind == "arc":
        params["curvature"] = ctx.num(shape, "curvature")
    elif kind == "spiral":
        params["curv_start"] = ctx.num(shape, "curvStart")
        params["curv_end"] = ctx.num(shape, "curvEnd")
    elif kind == "poly3":
        for k in "abcd":
            params[k] = ctx.num(shape, k, 0.0)
    elif kind == "paramPoly3":
        for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV"):
            params[k] = ctx.num(shape, k, 0.0)
        p_range = shape.get("pRange", "normalized")
        if p_range not in ("arcLength", "normalized"):
            raise ctx.error(f"<paramPoly3> pRange={p_range!r} is neither 'arcLength' nor 'normalized'", shape)
        params["p_range"] = p_range
    return Geometry(
        s=ctx.num(el, "s"),
        x=ctx.num(el, "x"),
        y=ctx.num(el, "y"),
        hdg=ctx.num(el, "hdg"),
        length=length,
        kind=kind,
        params=params,
        line=el.sourceline,
    )


def _poly_records(parent: Any, tag: str, ctx: _Ctx, s_name: str = "s") -> list[Poly3Record]:
    out = []
    if parent is None:
        return out
    for el in parent.findall(tag):
        out.append(
            Poly3Record(
                s=ctx.num(el, s_name, 0.0),
                a=ctx.num(el, "a", 0.0),
                b=ctx.num(el, "b", 0.0),
                c=ctx.num(el, "c", 0.0),
                d=ctx.num(el, "d", 0.0),
                line=el.sourceline,
            )
        )
    out.sort(key=lambda r: r.s)
    return out


def _width_table(lane_el: Any, tag: str, ctx: _Ctx) -> np.ndarray:
    rows = []
    for w in lane_el.findall(tag):
        rows.append(
            (
                ctx.num(w, "sOffset", 0.0),
                ctx.num(w, "a", 0.0),
                ctx.num(w, "b", 0.0),
                ctx.num(w, "c", 0.0),
                ctx.num(w, "d", 0.0),
            )
        )
    if not rows:
        return np.zeros((0, 5))
    arr = np.array(rows, dtype=np.float64)
    return arr[np.argsort(arr[:, 0], kind="stable")]


def _lane(el: Any, ctx: _Ctx) -> Lane:
    lane = Lane(
        id=ctx.integer(el, "id"),
        type=el.get("type", "none"),
        level=el.get("level", "false").strip().lower() in ("true", "1"),
        widths=_width_table(el, "width", ctx),
        borders=_width_table(el, "border", ctx),
        direction=el.get("direction"),
        line=el.sourceline,
    )
    link = el.find("link")
    if link is not None:
        lane.predecessors = [ctx.integer(p, "id") for p in link.findall("predecessor")]
        lane.successors = [ctx.integer(p, "id") for p in link.findall("successor")]
    for sp in el.findall("speed"):
        lane.speeds.append(
            (ctx.num(sp, "sOffset", 0.0), ctx.num(sp, "max", float("nan"), finite=False), sp.get("unit"))
        )
    for rm in el.findall("roadMark"):
        lane.road_marks.append(
            RoadMark(
                s_offset=ctx.num(rm, "sOffset", 0.0),
                type=rm.get("type", "none"),
                attributes=dict(rm.attrib),
                line=rm.sourceline,
            )
        )
    for hg in el.findall("height"):
        lane.heights.append((ctx.num(hg, "sOffset", 0.0), ctx.num(hg, "inner", 0.0), ctx.num(hg, "outer", 0.0)))
    return lane


def _lane_section(el: Any, ctx: _Ctx) -> LaneSection:
    sec = LaneSection(
        s=ctx.num(el, "s", 0.0),
        single_side=el.get("singleSide", "false").strip().lower() in ("true", "1"),
        line=el.sourceline,
    )
    for side_name in ("left", "center", "right"):
        side = el.find(side_name)
        if side is None:
            continue
        lanes = [_lane(x, ctx) for x in side.findall("lane")]
        for lane in lanes:
            ok = lane.id > 0 if side_name == "left" else lane.id < 0 if side_name == "right" else lane.id == 0
            if not ok:
                raise ctx.error(f"lane id {lane.id} does not belong in <{side_name}>", line=lane.line)
        if side_name == "center":
            sec.center = lanes[0] if lanes else None
        elif side_name == "left":
            sec.left = sorted(lanes, key=lambda ln: ln.id)
        else:
            sec.right = sorted(lanes, key=lambda ln: -ln.id)
    for side in (sec.left, sec.right):
        ids = [abs(ln.id) for ln in side]
        if len(set(ids)) != len(ids):
            raise ctx.error("duplicate lane ids in a lane section", el)
    return sec


def _object(el: Any, ctx: _Ctx) -> RoadObject:
    return RoadObject(
        kind=el.tag,
        id=el.get("id", ""),
        s=ctx.num(el, "s", 0.0),
        t=ctx.num(el, "t", 0.0),
        type=el.get("type"),
        subtype=el.get("subtype"),
        name=el.get("name"),
        z_offset=ctx.num(el, "zOffset", 0.0),
        attributes=dict(el.attrib),
        xml=etree.tostring(el, encoding="unicode", with_tail=False),
        line=el.sourceline,
    )


def _road(el: Any, ctx: _Ctx) -> Road:
    junction = el.get("junction", "-1").strip()
    road = Road(
        id=ctx.text(el, "id"),
        length=ctx.num(el, "length"),
        name=el.get("name", ""),
        junction=None if junction in ("-1", "") else junction,
        rule=el.get("rule", "RHT"),
        line=el.sourceline,
    )
    if road.length < 0:
        raise ctx.error(f"road {road.id} has a negative length", el)
    link = el.find("link")
    if link is not None:
        p, s = link.find("predecessor"), link.find("successor")
        road.predecessor = _link(p, ctx) if p is not None else None
        road.successor = _link(s, ctx) if s is not None else None
    for t in el.findall("type"):
        rt = RoadType(
            s=ctx.num(t, "s", 0.0), type=t.get("type", "unknown"), country=t.get("country"), line=t.sourceline
        )
        sp = t.find("speed")
        if sp is not None:
            rt.speed_max, rt.speed_unit = sp.get("max"), sp.get("unit")
        road.types.append(rt)
    pv = el.find("planView")
    if pv is None:
        raise ctx.error(f"road {road.id} has no <planView>", el)
    road.geometries = sorted((_geometry(g, ctx) for g in pv.findall("geometry")), key=lambda g: g.s)
    if not road.geometries:
        raise ctx.error(f"road {road.id} has no <geometry> in its <planView>", pv)
    road.elevation = _poly_records(el.find("elevationProfile"), "elevation", ctx)
    road.superelevation = _poly_records(el.find("lateralProfile"), "superelevation", ctx)
    lanes = el.find("lanes")
    if lanes is None:
        raise ctx.error(f"road {road.id} has no <lanes>", el)
    road.lane_offset = _poly_records(lanes, "laneOffset", ctx)
    road.lane_sections = sorted((_lane_section(x, ctx) for x in lanes.findall("laneSection")), key=lambda x: x.s)
    if not road.lane_sections:
        raise ctx.error(f"road {road.id} has no <laneSection>", lanes)
    objs = el.find("objects")
    if objs is not None:
        road.objects = [
            _object(o, ctx)
            for o in objs
            if isinstance(o.tag, str) and o.tag in ("object", "objectReference", "tunnel", "bridge")
        ]
    sigs = el.find("signals")
    if sigs is not None:
        road.signals = [
            _object(o, ctx) for o in sigs if isinstance(o.tag, str) and o.tag in ("signal", "signalReference")
        ]
    return road


def _junction(el: Any, ctx: _Ctx) -> Junction:
    j = Junction(id=ctx.text(el, "id"), name=el.get("name", ""), type=el.get("type", "default"), line=el.sourceline)
    for c in el:
        if not isinstance(c.tag, str):
            continue
        if c.tag == "connection":
            conn = Connection(
                id=c.get("id", ""),
                incoming_road=c.get("incomingRoad"),
                connecting_road=c.get("connectingRoad"),
                linked_road=c.get("linkedRoad"),
                contact_point=c.get("contactPoint"),
                line=c.sourceline,
            )
            for ll in c.findall("laneLink"):
                conn.lane_links.append(
                    LaneLink(
                        from_lane=ctx.integer(ll, "from"),
                        to_lane=ctx.integer(ll, "to"),
                        overlap_zone=ctx.num(ll, "overlapZone", None),
                        line=ll.sourceline,
                    )
                )
            j.connections.append(conn)
        else:
            j.extras.append((c.tag, dict(c.attrib)))
    return j


def parse(source: Any) -> tuple[Header, dict[str, Road], dict[str, Junction], str | None]:
    """Parse an OpenDRIVE map into ``(header, roads, junctions, path)``.

    ``source`` is a path, bytes, or XML text (a ``str`` starting with ``<``).
    """
    data, path = xml_source(source)
    ctx = _Ctx(path)
    root = _parse_xml(data, ctx)
    _strip_ns(root)
    hdr_el = root.find("header")
    header = _header(hdr_el, ctx) if hdr_el is not None else Header(line=None)
    roads: dict[str, Road] = {}
    for el in root.findall("road"):
        road = _road(el, ctx)
        if road.id in roads:
            raise ctx.error(f"duplicate road id {road.id!r} (first on line {roads[road.id].line})", el)
        roads[road.id] = road
    junctions: dict[str, Junction] = {}
    for el in root.findall("junction"):
        j = _junction(el, ctx)
        if j.id in junctions:
            raise ctx.error(f"duplicate junction id {j.id!r}", el)
        junctions[j.id] = j
    if not roads:
        raise ctx.error("the map has no <road>", root)
    return header, roads, junctions, path


__all__ = ["parse"]
