"""Lanelet2 maps as they are stored: OSM XML (nodes, ways, relations with tags), read with lxml,
and their projection to a local metric frame.

Lanelet2 keeps every point as an OSM ``<node lat lon>`` (``ele`` as a tag) and leaves the map's
origin to the user (``UtmProjector(Origin(lat, lon))``: UTM minus the origin's UTM). Two frames
are offered, each written as the OpenDRIVE ``<geoReference>`` (and ``<offset>``):

- ``"tmerc"`` (default): a transverse Mercator centred at the origin (k = 1, WGS 84): no scale
  error and no grid convergence at the site; the origin defaults to the centre of the nodes'
  bounding box.
- ``"utm"``: Lanelet2's own ``UtmProjector``: UTM in the origin's zone, shifted by the origin's
  UTM coordinates (the header ``<offset>`` holds the shift). The INTERACTION dataset's tracks are
  in this frame with the origin (0, 0) (UTM zone 31).

Malformed files raise :class:`~aveas_format.errors.MapError` naming the file and the XML line
(a node without a number, a way naming a node that is not there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from lxml import etree

from aveas_format.errors import MapError
from aveas_format.safeio import xml_parser, xml_source


@dataclass
class Way:
    id: int
    nodes: list[int]
    tags: dict[str, str]
    line: int | None = None


@dataclass
class Member:
    type: str  # node / way / relation
    ref: int
    role: str


@dataclass
class Relation:
    id: int
    members: list[Member]
    tags: dict[str, str]
    line: int | None = None


@dataclass
class OsmMap:
    """The content of an OSM file: node coordinates (and their line numbers), ways and relations
    by id. ``lat``/``lon``/``ele`` are arrays indexed through ``node_index``."""

    path: str | None
    node_ids: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    ele: np.ndarray
    node_line: np.ndarray
    ways: dict[int, Way] = field(default_factory=dict)
    relations: dict[int, Relation] = field(default_factory=dict)
    node_index: dict[int, int] = field(default_factory=dict)
    node_tags: dict[int, dict[str, str]] = field(default_factory=dict)

    def way_nodes(self, way: Way) -> np.ndarray:
        """Indices (into the node arrays) of the nodes of ``way``; a MapError for a missing node."""
        try:
            return np.fromiter((self.node_index[n] for n in way.nodes), dtype=np.int64, count=len(way.nodes))
        except KeyError as e:
            raise MapError(f"way {way.id} names node {e.args[0]}, which is not in the file",
                           path=self.path or "<osm>", line=way.line) from None


def _int(el: Any, name: str, where: str, path: str) -> int:
    raw = el.get(name)
    try:
        return int(raw)
    except (TypeError, ValueError):
        raise MapError(f"<{el.tag}> {where}: attribute {name}={raw!r} is not an integer", path=path,
                       line=el.sourceline) from None


def _tags(el: Any) -> dict[str, str]:
    return {t.get("k"): t.get("v", "") for t in el.iterchildren("tag") if t.get("k") is not None}


def read_osm(source: Any) -> OsmMap:
    """Parse an OSM XML file (a path, bytes or XML text) into an :class:`OsmMap`."""
    data, path = xml_source(source, "Lanelet2 map")
    name = path or "<osm>"
    try:
        root = etree.fromstring(data, xml_parser())
    except etree.XMLSyntaxError as e:
        raise MapError(f"not well-formed XML: {e.msg}", path=name, line=e.lineno or None) from None
    if root is None or root.tag != "osm":
        raise MapError(f"the root element is <{getattr(root, 'tag', None)}>, not <osm> (not a Lanelet2 "
                       "OSM map)", path=name, line=getattr(root, "sourceline", None))
    ids, lat, lon, ele, lines, node_tags = [], [], [], [], [], {}
    for el in root.iterchildren("node"):
        nid = _int(el, "id", "", name)
        tags = _tags(el)
        try:
            la, lo = float(el.get("lat")), float(el.get("lon"))
        except (TypeError, ValueError):
            raise MapError(f"node {nid}: lat={el.get('lat')!r} lon={el.get('lon')!r} are not numbers",
                           path=name, line=el.sourceline) from None
        if not (math.isfinite(la) and math.isfinite(lo) and -90 <= la <= 90 and -180 <= lo <= 180):
            raise MapError(f"node {nid}: lat={la!r} lon={lo!r} out of range", path=name, line=el.sourceline)
        try:
            e = float(tags.get("ele", 0.0))
        except ValueError:
            raise MapError(f"node {nid}: tag ele={tags['ele']!r} is not a number", path=name,
                           line=el.sourceline) from None
        ids.append(nid)
        lat.append(la)
        lon.append(lo)
        ele.append(e)
        lines.append(el.sourceline or 0)
        if tags:
            node_tags[nid] = tags
    m = OsmMap(name if path else None, np.array(ids, dtype=np.int64), np.array(lat), np.array(lon),
               np.array(ele), np.array(lines, dtype=np.int64), node_tags=node_tags)
    m.node_index = {n: i for i, n in enumerate(ids)}
    if len(m.node_index) != len(ids):
        raise MapError("duplicate node ids", path=name)
    for el in root.iterchildren("way"):
        wid = _int(el, "id", "", name)
        nodes = [_int(nd, "ref", f"of way {wid}", name) for nd in el.iterchildren("nd")]
        if wid in m.ways:
            raise MapError(f"duplicate way id {wid}", path=name, line=el.sourceline)
        m.ways[wid] = Way(wid, nodes, _tags(el), el.sourceline)
    for el in root.iterchildren("relation"):
        rid = _int(el, "id", "", name)
        members = [Member(mb.get("type", ""), _int(mb, "ref", f"of relation {rid}", name), mb.get("role", ""))
                   for mb in el.iterchildren("member")]
        if rid in m.relations:
            raise MapError(f"duplicate relation id {rid}", path=name, line=el.sourceline)
        m.relations[rid] = Relation(rid, members, _tags(el), el.sourceline)
    if not ids:
        raise MapError("the file has no <node>", path=name)
    return m


@dataclass(frozen=True)
class Projection:
    """How lat/lon become the local frame: ``geo_reference`` (PROJ) and the header ``offset``."""

    kind: str
    lat0: float
    lon0: float
    geo_reference: str
    offset: tuple[float, float, float, float] | None

    def forward(self, lat: np.ndarray, lon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local x, y of WGS 84 lat/lon (vectorised)."""
        import pyproj

        tr = pyproj.Transformer.from_crs("EPSG:4326", self.geo_reference, always_xy=True)
        x, y = tr.transform(np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64))
        if self.offset is not None:
            x, y = x - self.offset[0], y - self.offset[1]
        return np.asarray(x), np.asarray(y)


def utm_zone(lat: float, lon: float) -> tuple[int, bool]:
    """UTM zone number and hemisphere (True: south) of a point (Norway/Svalbard exceptions left out,
    as in Lanelet2's projector, which uses GeographicLib's standard zone)."""
    zone = int(math.floor((lon + 180.0) / 6.0)) % 60 + 1
    return zone, lat < 0


def projection(kind: str, lat0: float, lon0: float) -> Projection:
    """The local frame ``kind`` (``"tmerc"`` or ``"utm"``) at the origin (lat0, lon0)."""
    if kind == "tmerc":
        geo = (f"+proj=tmerc +lat_0={lat0!r} +lon_0={lon0!r} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
               "+units=m +no_defs")
        return Projection(kind, lat0, lon0, geo, None)
    if kind == "utm":
        import pyproj

        zone, south = utm_zone(lat0, lon0)
        geo = f"+proj=utm +zone={zone}{' +south' if south else ''} +datum=WGS84 +units=m +no_defs"
        tr = pyproj.Transformer.from_crs("EPSG:4326", geo, always_xy=True)
        e0, n0 = tr.transform(lon0, lat0)
        return Projection(kind, lat0, lon0, geo, (float(e0), float(n0), 0.0, 0.0))
    raise ValueError(f"projection must be 'tmerc' or 'utm', not {kind!r}")


def default_origin(m: OsmMap) -> tuple[float, float]:
    """The centre of the nodes' bounding box (rounded to 1e-7 degrees, ~1 cm)."""
    return (round(float(m.lat.min() + m.lat.max()) / 2, 7), round(float(m.lon.min() + m.lon.max()) / 2, 7))


__all__ = ["Member", "OsmMap", "Projection", "Relation", "Way", "default_origin", "projection", "read_osm",
           "utm_zone"]
