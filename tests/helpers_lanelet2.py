"""Measures of a converted Lanelet2 map against the Lanelet2 map itself (tests, docs/opendrive.md)."""

from __future__ import annotations

import numpy as np
import shapely


def densify(pts: np.ndarray, step: float = 0.25) -> np.ndarray:
    out = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step)))
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.concatenate(out)


def off_centre(points: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """How far ``points`` lie from a lanelet's centre line computed properly from its bounds, the
    line of points as far from the left bound as from the right: ``|d_left - d_right| / 2``
    (exact on straight parallel bounds, to first order elsewhere)."""
    p = shapely.points(points)
    return 0.5 * np.abs(shapely.distance(shapely.LineString(left), p) - shapely.distance(shapely.LineString(right), p))


def densify_pair(left: np.ndarray, right: np.ndarray, n: int = 64) -> np.ndarray:
    def by_share(p):
        cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
        u = np.linspace(0.0, cum[-1], n)
        return np.column_stack([np.interp(u, cum, p[:, 0]), np.interp(u, cum, p[:, 1])])
    return by_share(left) + by_share(right)


def lane_centre(net, road_id: str, section: int, lane_id: int, step: float = 0.5) -> np.ndarray:
    """x, y of the OpenDRIVE lane's centre (the middle of its borders) along its lane section."""
    road = net.roads[road_id]
    s0 = road.lane_sections[section].s
    s1 = road.lane_sections[section + 1].s if section + 1 < len(road.lane_sections) else road.length
    s = np.linspace(s0, s1, max(3, int(np.ceil((s1 - s0) / step)) + 1))
    inner, outer = net.lane_borders(road_id, s, np.full(len(s), lane_id))
    x, y, _, _ = net.road_to_world(road_id, s, 0.5 * (inner + outer))
    return np.column_stack([x, y])


def centre_deviation(net, lanelets, lanelet_lanes) -> np.ndarray:
    """For every converted lanelet, how far its OpenDRIVE lane centre (sampled every 0.5 m) lies
    from its proper centre line (:func:`off_centre`), all lanelets' points together."""
    out = []
    for lid, (rid, sec, lane) in lanelet_lanes.items():
        ll = lanelets[lid]
        out.append(off_centre(lane_centre(net, rid, sec, lane), ll.left, ll.right))
    return np.concatenate(out)


# --- Lanelet2 maps written for the tests ---------------------------------------------------------
ORIGIN = (49.0, 8.4)


class OsmWriter:
    """A Lanelet2 OSM file from polylines in a local transverse Mercator frame at :data:`ORIGIN`:
    ways by name (nodes shared where coordinates repeat), lanelets naming their left/right ways."""

    def __init__(self) -> None:
        self.nodes: dict[tuple[float, float], int] = {}
        self.ways: dict[str, tuple[int, list[int], dict[str, str]]] = {}
        self.relations: list[tuple[int, list[tuple[str, int, str]], dict[str, str]]] = []
        self.next_id = 1

    def _id(self) -> int:
        self.next_id += 1
        return self.next_id

    def node(self, p) -> int:
        key = (round(float(p[0]), 4), round(float(p[1]), 4))
        if key not in self.nodes:
            self.nodes[key] = self._id()
        return self.nodes[key]

    def way(self, name: str, pts, **tags) -> int:
        ids = [self.node(p) for p in pts]
        wid = self._id()
        self.ways[name] = (wid, ids, {"type": "line_thin", "subtype": "solid", **tags})
        return wid

    def lanelet(self, left: str, right: str, regulatory=(), **tags) -> int:
        rid = self._id()
        members = [("way", self.ways[left][0], "left"), ("way", self.ways[right][0], "right")]
        members += [("relation", r, "regulatory_element") for r in regulatory]
        self.relations.append((rid, members, {"type": "lanelet", "subtype": "road", "location": "urban",
                                              "one_way": "yes", "region": "de", **tags}))
        return rid

    def regulatory(self, members, **tags) -> int:
        rid = self._id()
        self.relations.append((rid, list(members), {"type": "regulatory_element", **tags}))
        return rid

    def text(self) -> str:
        import pyproj

        tr = pyproj.Transformer.from_crs(f"+proj=tmerc +lat_0={ORIGIN[0]} +lon_0={ORIGIN[1]} +ellps=WGS84",
                                         "EPSG:4326", always_xy=True)
        out = ["<?xml version='1.0' encoding='UTF-8'?>", "<osm version='0.6' generator='aveas tests'>"]
        for (x, y), nid in self.nodes.items():
            lon, lat = tr.transform(x, y)
            out.append(f"  <node id='{nid}' visible='true' version='1' lat='{lat:.11f}' lon='{lon:.11f}' />")
        for wid, ids, tags in self.ways.values():
            out.append(f"  <way id='{wid}' visible='true' version='1'>")
            out += [f"    <nd ref='{n}' />" for n in ids]
            out += [f"    <tag k='{k}' v='{v}' />" for k, v in tags.items()]
            out.append("  </way>")
        for rid, members, tags in self.relations:
            out.append(f"  <relation id='{rid}' visible='true' version='1'>")
            out += [f"    <member type='{t}' ref='{r}' role='{role}' />" for t, r, role in members]
            out += [f"    <tag k='{k}' v='{v}' />" for k, v in tags.items()]
            out.append("  </relation>")
        out.append("</osm>")
        return "\n".join(out) + "\n"


def _bezier(p0, d0, p3, d3, n: int = 24) -> np.ndarray:
    """A cubic Bezier from p0 leaving along d0 to p3 arriving along d3."""
    p0, p3 = np.asarray(p0, float), np.asarray(p3, float)
    k = 0.4 * np.hypot(*(p3 - p0))
    p1, p2 = p0 + k * np.asarray(d0), p3 - k * np.asarray(d3)
    u = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - u) ** 3 * p0 + 3 * (1 - u) ** 2 * u * p1 + 3 * (1 - u) * u ** 2 * p2 + u ** 3 * p3


def crossroads(width: float = 3.5, r0: float = 12.0, r1: float = 80.0, speed_kmh: float | None = 50.0):
    """A four-way crossroads: four arms of one lane each way (the centre line a shared way), and
    inside the junction a lanelet from every incoming lane to every other arm's outgoing lane
    (left, straight, right). The north arm's incoming lane has a traffic light with a stop line;
    a crosswalk crosses the east arm. Returns the OSM text and the ids (arms, junction lanelets,
    crosswalk)."""
    w = OsmWriter()
    arms = {}
    for k, a in enumerate(np.radians([0.0, 90.0, 180.0, 270.0])):
        u, n = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        r = np.linspace(r0, r1, 9)[:, None]
        w.way(f"c{k}", r * u, type="line_thin", subtype="dashed")
        w.way(f"o{k}", r * u - width * n, type="line_thin", subtype="solid")
        w.way(f"i{k}", (r * u + width * n)[::-1], type="curbstone", subtype="high")
        tags = {"speed_limit": f"{speed_kmh:g}"} if speed_kmh else {}
        out_id = w.lanelet(f"c{k}", f"o{k}", **tags)
        arms[k] = {"out": out_id, "u": u, "n": n}
    # incoming lanes use the centre way reversed as their left bound: a second pass, once the
    # ways exist (Lanelet2 orients each lanelet by its bounds)
    for k in range(4):
        tags = {"speed_limit": f"{speed_kmh:g}"} if speed_kmh else {}
        arms[k]["in"] = w.lanelet(f"c{k}", f"i{k}", **tags)
    stop = w.way("stop", [r0 * arms[1]["u"], r0 * arms[1]["u"] + width * arms[1]["n"]], type="stop_line")
    light = w.way("light", [r0 * arms[1]["u"] + (width + 1.0) * arms[1]["n"] + 2.0 * arms[1]["u"]],
                  type="traffic_light", subtype="red_yellow_green")
    tl = w.regulatory([("way", light, "refers"), ("way", stop, "ref_line")], subtype="traffic_light")
    w.relations = [(rid, m + ([("relation", tl, "regulatory_element")] if rid == arms[1]["in"] else []), t)
                   for rid, m, t in w.relations]
    inner = {}
    for i in range(4):
        for j in range(4):
            if i == j:
                continue
            ui, ni, uj, nj = arms[i]["u"], arms[i]["n"], arms[j]["u"], arms[j]["n"]
            left = _bezier(r0 * ui, -ui, r0 * uj, uj)
            right = _bezier(r0 * ui + width * ni, -ui, r0 * uj - width * nj, uj)
            w.way(f"jl{i}{j}", left, type="virtual")
            w.way(f"jr{i}{j}", right, type="virtual")
            inner[(i, j)] = w.lanelet(f"jl{i}{j}", f"jr{i}{j}")
    # a crosswalk over the east arm (arm 0) at r = 30
    u, n = arms[0]["u"], arms[0]["n"]
    w.way("cwl", [30.0 * u + (width + 1) * n, 30.0 * u - (width + 1) * n], type="zebra_marking")
    w.way("cwr", [33.0 * u + (width + 1) * n, 33.0 * u - (width + 1) * n], type="zebra_marking")
    cw = w.lanelet("cwl", "cwr", subtype="crosswalk", one_way="no")
    return w.text(), {"arms": arms, "inner": inner, "crosswalk": cw, "traffic_light": tl}
