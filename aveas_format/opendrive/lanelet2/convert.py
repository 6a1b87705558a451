"""Lanelet2 -> OpenDRIVE 1.8 (:func:`lanelet2_to_opendrive`).

Roads come from :mod:`.roads` (cross-sections of neighbouring lanelets, chained where they meet one
to one; junctions where traffic branches, merges or crosses). Per road:

- **Reference line**: along the centre border of its cross-sections (the bound between the two
  directions, else the left edge), a G1 chain of lines and paramPoly3 (:mod:`..roadfit.hermite`)
  within ``reference_tol`` of that bound smoothed over a few metres; at both ends it starts
  perpendicular to the lanelets' end line (left end point to right end point), so that the lanes of
  roads that meet there meet point for point.
- **Lanes**: one lane section per cross-section; every lane border is the lanelet bound itself
  (its points densified every 0.5 m and measured against the reference line), a piecewise cubic
  within ``tol`` of it and exact at the section's ends (:mod:`..roadfit.assemble`). The lane
  centre is so the middle of the bounds, not Lanelet2's ``centerline`` (chords between bound
  midpoints).
- **Types and marks**: lane types by lanelet subtype (road/highway: driving, or bidirectional
  where ``one_way=no``; bicycle_lane: biking; walkway: sidewalk; ...), road marks by the bound's
  line type (dashed: broken, solid, curbstone: curb, virtual/road_border: none), speed limits
  (lanelet ``speed_limit`` tags and ``speed_limit`` regulatory elements with German
  ``de274``-signs) as lane ``<speed>``.
- **Links**: lane links from the lanelets' successors; roads that meet one to one are linked
  directly, the others through junctions whose connecting roads are the lanelets inside them
  (one ``<connection>`` per incoming road and connecting road).
- **Regulatory elements**: traffic lights become dynamic ``<signal>``s (German catalogue type
  1000001, with ``<validity>`` for the lanes that reference them) at the stop line's s; stop lines
  ``<object type="roadMark" subtype="stopLine">``; crosswalk lanelets that cross a vehicle lane
  ``<object type="crosswalk">`` with their outline on the road they cross (the others, roads with a
  ``walking`` lane).

Every lanelet is accounted for: converted (``Lanelet2Conversion.lanelet_lanes``, the
``crosswalks``) or named in ``warnings`` with the reason.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.errors import MapError
from aveas_format.opendrive.lanelet2.lanelets import Lanelet, mark_type, read_lanelets, topology
from aveas_format.opendrive.lanelet2.osm import OsmMap, default_origin, projection, read_osm
from aveas_format.opendrive.lanelet2.roads import (
    Chain,
    CrossSection,
    chains,
    classify,
    contacts,
    cross_sections,
    junction_paths,
    lanelet_links,
)
from aveas_format.opendrive.model import (
    Connection,
    Header,
    Junction,
    LaneLink,
    Road,
    RoadLink,
    RoadObject,
    RoadType,
)
from aveas_format.opendrive.roadfit.assemble import (
    ZERO_WIDTH,
    Frame,
    LaneSpec,
    SectionSpec,
    lane_sections,
    link_sections,
    width_at,
)
from aveas_format.opendrive.roadfit.hermite import hermite_chain

#: the largest angle between a road's natural heading and the normal of its end line for which the
#: road starts perpendicular to that line (beyond it, the natural heading: a skewed end line)
MAX_END_SKEW = math.radians(25.0)


@dataclass
class Lanelet2Conversion:
    """The result of :func:`lanelet2_to_opendrive`."""

    xodr: str
    warnings: list[str]
    #: lanelet id -> (road id, lane section index, lane id)
    lanelet_lanes: dict[int, tuple[str, int, int]]
    #: crosswalk lanelet id -> (road id, object id)
    crosswalks: dict[int, tuple[str, str]]
    lanelets: int
    areas: int
    geo_reference: str
    offset: tuple[float, float, float, float] | None
    origin: tuple[float, float]
    roads: int = 0
    junctions: int = 0
    signals: int = 0
    stats: dict[str, Any] = field(default_factory=dict)

    def network(self):
        """The converted map as a :class:`~aveas_format.opendrive.network.RoadNetwork`."""
        from aveas_format.opendrive.network import load_map

        return load_map(self.xodr)

    def write(self, path) -> Any:
        from aveas_format.safeio import write_text_atomic

        return write_text_atomic(path, self.xodr)


def _speed_kmh(text: str) -> float | None:
    m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*(km/h|kmh|kph|mph|m/s)?\s*", text or "")
    if not m:
        return None
    v = float(m.group(1))
    unit = m.group(2) or "km/h"
    return v * {"km/h": 1.0, "kmh": 1.0, "kph": 1.0, "mph": 1.609344, "m/s": 3.6}[unit]


def _sign_speed_kmh(subtype: str) -> float | None:
    """Speed limit of a German sign subtype as Lanelet2 maps write it: de274_1 / de274.1 (zone 30),
    de274-NN / de274_NN (NN km/h, NN >= 5), de325_1 (traffic-calmed area, walking speed 7 km/h)."""
    s = subtype.lower().replace(".", "_")
    if s in ("de274_1", "de2741"):
        return 30.0
    if s in ("de325_1", "de3251"):
        return 7.0
    m = re.fullmatch(r"de274[-_](\d+)", s)
    if m and int(m.group(1)) >= 5:
        return float(m.group(1))
    return None


def _speed_limits(osm: OsmMap, lanelets: dict[int, Lanelet], warnings: list[str]) -> dict[int, float]:
    """m/s per lanelet: its ``speed_limit`` tag, else a speed-limit regulatory element it references."""
    out: dict[int, float] = {}
    referenced = {r for ll in lanelets.values() for r in ll.regulatory}
    for rel in osm.relations.values():
        if rel.tags.get("subtype") == "speed_limit" and rel.id not in referenced:
            warnings.append(f"speed-limit regulatory element {rel.id} (line {rel.line}): no lanelet references "
                            "it; left out")
    for ll in lanelets.values():
        if "speed_limit" in ll.tags:
            v = _speed_kmh(ll.tags["speed_limit"])
            if v is None:
                warnings.append(f"lanelet {ll.id}: speed_limit={ll.tags['speed_limit']!r} is not a speed; left out")
            else:
                out[ll.id] = v / 3.6
                continue
        for rid in ll.regulatory:
            rel = osm.relations.get(rid)
            if rel is None or rel.tags.get("subtype") != "speed_limit":
                continue
            v = _speed_kmh(rel.tags["speed_limit"]) if "speed_limit" in rel.tags else None
            for mb in rel.members:
                if v is None and mb.role == "refers" and mb.ref in osm.ways:
                    v = _sign_speed_kmh(osm.ways[mb.ref].tags.get("subtype", ""))
            if v is None:
                warnings.append(f"speed-limit regulatory element {rid} (line {rel.line}): no speed known "
                                f"for its sign; lanelet {ll.id} has no speed limit")
            else:
                out[ll.id] = v / 3.6
    return out


def _densify(pts: np.ndarray, step: float = 0.5) -> np.ndarray:
    out = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step)))
        u = np.linspace(0.0, 1.0, n + 1)[1:, None]
        out.append(a + u * (b - a))
    return np.concatenate(out)


def _end_heading(left: np.ndarray, right: np.ndarray, natural: float) -> float:
    """Heading normal to the end line left -> right (pointing along the road), or ``natural``
    where that line is degenerate or skewed by more than :data:`MAX_END_SKEW`."""
    v = right - left
    if np.hypot(*v) < 0.1:
        return natural
    h = math.atan2(v[0], -v[1])
    if abs((h - natural + math.pi) % (2 * math.pi) - math.pi) > MAX_END_SKEW:
        return natural
    return h


@dataclass
class Anchor:
    """Where a road must start or end to meet a road built before: the reference point, the
    heading (along the road being built) and the t of its borders there (border index -> t)."""

    point: np.ndarray
    heading: float
    values: dict[int, float]


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


class _Conversion:
    """The state of one conversion: the OSM content, local coordinates, lanelets and their topology,
    the roads built so far and the warnings."""

    def __init__(self, osm: OsmMap, xy: np.ndarray, lanelets: dict[int, Lanelet], topo, tol: float,
                 reference_tol: float, warnings: list[str]) -> None:
        self.osm, self.xy, self.lanelets, self.topo = osm, xy, lanelets, topo
        self.tol, self.reference_tol, self.warnings = tol, reference_tol, warnings
        self.speeds = _speed_limits(osm, lanelets, warnings)
        self.roads: dict[str, Road] = {}
        self.frames: dict[str, Frame] = {}
        self.road_of_chain: dict[int, Road] = {}
        self.specs_of: dict[int, list[SectionSpec]] = {}
        self.lanelet_lanes: dict[int, tuple[str, int, int]] = {}
        self.n_objects = 0

    # -- roads -------------------------------------------------------------------------------------
    def chain_road(self, chain: Chain, rid: str, start: Anchor | None = None, end: Anchor | None = None
                   ) -> tuple[Road, list[SectionSpec], Frame]:
        """One road of a chain of cross-sections (see the module doc); ``start``/``end``: where it
        must meet a road built before."""
        mids = [p.midline() for p in chain.parts]
        ref = np.concatenate([mids[0]] + [c[1:] for c in mids[1:]])
        seg = np.hypot(*np.diff(ref, axis=0).T)
        ref = ref[np.r_[True, seg > 1e-6]]
        if len(ref) < 2:
            raise ValueError("the centre border has no length")
        first, last = chain.parts[0].borders, chain.parts[-1].borders
        nat0 = math.atan2(*(ref[1] - ref[0])[::-1])
        nat1 = math.atan2(*(ref[-1] - ref[-2])[::-1])
        h0 = _end_heading(first[0][0], first[-1][0], nat0)
        h1 = _end_heading(last[0][-1], last[-1][-1], nat1)
        if start is not None and abs(_wrap(start.heading - nat0)) < math.radians(60):
            ref[0], h0 = start.point, start.heading
        else:
            start = None
        if end is not None and abs(_wrap(end.heading - nat1)) < math.radians(60):
            ref[-1], h1 = end.point, end.heading
        else:
            end = None
        seg = seg[seg > 1e-6]
        spacing = float(np.median(seg)) if len(seg) else 1.0
        geoms = hermite_chain(ref, start_heading=h0, end_heading=h1, tol=self.reference_tol,
                              smooth=max(2.0, min(10.0, 1.5 * spacing)))
        reach = 5.0 + max(float(np.max(np.hypot(*(b - ref.mean(0)).T))) for p in chain.parts for b in p.borders)
        frame = Frame(geoms, reach=min(reach, 500.0))
        L = frame.length
        starts = [0.0]
        for p in chain.parts[1:]:
            c = 0.5 * (p.borders[0][0] + p.borders[-1][0])
            s, _ = frame.project(np.array([c[0]]), np.array([c[1]]))
            starts.append(float(np.clip(s[0], starts[-1] + 1e-3, L - 1e-3)))
        ends = starts[1:] + [L]
        specs = []
        for p, s0, s1 in zip(chain.parts, starts, ends):
            borders = []
            for b in p.borders:
                d = _densify(b)
                s, t = frame.project(d[:, 0], d[:, 1])
                borders.append((s, t))
            lanes = []
            for k, m in enumerate(p.members):
                ll = m.lanelet
                direction = "reversed" if p.centre == 0 and not m.forward else None
                if ll.lane_type == "bidirectional":
                    direction = "both"
                outer_way = m.way_left() if k < p.centre else m.way_right()
                lanes.append(LaneSpec(type=ll.lane_type, speed=self.speeds.get(ll.id),
                                      outer_mark=mark_type(self.osm.ways[outer_way].tags), key=ll.id,
                                      direction=direction))
            centre_way = p.members[p.centre].way_left() if p.centre < len(p.members) else p.members[-1].way_right()
            specs.append(SectionSpec(s0, s1, borders, p.centre, lanes,
                                     centre_mark=mark_type(self.osm.ways[centre_way].tags)))
        if start is not None:
            specs[0].start_values = dict(start.values)
        if end is not None:
            specs[-1].end_values = dict(end.values)
        pairs = [lanelet_links(a, "end", b, "start", self.topo) for a, b in zip(chain.parts[:-1], chain.parts[1:])]
        offset, secs = lane_sections(specs, self.tol, pairs)
        location = chain.parts[0].members[0].lanelet.tags.get("location", "urban")
        subtypes = {m.lanelet.subtype for p in chain.parts for m in p.members}
        rtype = "motorway" if "highway" in subtypes else ("town" if location == "urban" else "rural")
        road = Road(id=rid, length=L, name="", junction=None, types=[RoadType(0.0, rtype)], geometries=geoms,
                    lane_offset=offset, lane_sections=secs)
        link_sections(road, pairs, specs)
        return road, specs, frame

    def build_roads(self, chain_list: list[Chain], touch) -> None:
        """Every road, those outside junctions first (each one that meets a road already built
        starts or ends where that one ends or starts), then the connecting roads (from the lane
        they come from to the lane they go to)."""
        outside = [ci for ci, ch in enumerate(chain_list) if ch.junction is None]
        index = {}
        for ci in outside:
            for which in ("start", "end"):
                index[chain_list[ci].end(which)] = (ci, which)
        partners: dict[tuple[int, str], tuple[int, str]] = {}
        for ci in outside:
            for which in ("start", "end"):
                others = {index[o] for o in touch.get(chain_list[ci].end(which), ()) if o in index}
                if len(others) == 1:
                    partners[(ci, which)] = next(iter(others))
        # breadth first along direct links, so that a road meets the roads built before it
        order, seen = [], set()
        for root in outside:
            if root in seen:
                continue
            queue = [root]
            seen.add(root)
            while queue:
                ci = queue.pop(0)
                order.append(ci)
                for which in ("start", "end"):
                    o = partners.get((ci, which))
                    if o is not None and o[0] not in seen:
                        seen.add(o[0])
                        queue.append(o[0])
        for ci in order:
            anchors = {which: self._road_anchor(chain_list, ci, which, partners) for which in ("start", "end")}
            self._build(chain_list, ci, anchors)
        where = self._where(chain_list)
        for ci, ch in enumerate(chain_list):
            if ch.junction is None:
                continue
            first, last = ch.parts[0].members[0].lanelet, ch.parts[-1].members[0].lanelet
            anchors = {"start": self._lane_anchor([where[n] for n in self.topo.predecessors.get(first.id, [])
                                                   if n in where], "start"),
                       "end": self._lane_anchor([where[n] for n in self.topo.successors.get(last.id, [])
                                                 if n in where], "end")}
            self._build(chain_list, ci, anchors)

    def _build(self, chain_list: list[Chain], ci: int, anchors: dict[str, Anchor | None]) -> None:
        ch = chain_list[ci]
        rid = str(ci + 1)
        try:
            road, specs, frame = self.chain_road(ch, rid, anchors.get("start"), anchors.get("end"))
        except (ValueError, np.linalg.LinAlgError) as e:
            ids = [m.lanelet.id for p in ch.parts for m in p.members]
            self.warnings.append(f"lanelets {ids}: not converted: their road cannot be built ({e})")
            return
        self.roads[rid] = road
        self.frames[rid] = frame
        self.road_of_chain[ci] = road
        self.specs_of[ci] = specs
        for k, (p, spec) in enumerate(zip(ch.parts, specs)):
            for m, lid in zip(p.members, spec.lane_ids):
                self.lanelet_lanes.setdefault(m.lanelet.id, (rid, k, lid))

    def _end_state(self, rid: str, which: str) -> tuple[np.ndarray, float, Any, float]:
        """Reference point, heading, a network of the road alone and s at its ``which`` end."""
        from aveas_format.opendrive.network import RoadNetwork

        road = self.roads[rid]
        s = 0.0 if which == "start" else road.length
        net = RoadNetwork(Header(), {rid: road}, {})
        x, y, _, h = net.road_to_world(rid, [s], [0.0])
        return np.array([x[0], y[0]]), float(h[0]), net, s

    def _road_anchor(self, chain_list, ci: int, which: str, partners) -> Anchor | None:
        """Where road ``ci`` meets, at its ``which`` end, a road outside junctions built before it."""
        o = partners.get((ci, which))
        if o is None or o[0] not in self.road_of_chain or partners.get(o) != (ci, which):
            return None
        oc, owhich = o
        orid = self.road_of_chain[oc].id
        p_o, h_o, net, s_o = self._end_state(orid, owhich)
        # at an end, a road runs on in the other road's direction if one's end meets the other's start
        same = (which == "start") == (owhich == "end")
        heading = h_o if same else h_o + math.pi
        n = np.array([-math.sin(h_o), math.cos(h_o)])
        ch = chain_list[ci]
        part = ch.parts[0] if which == "start" else ch.parts[-1]
        k = 0 if which == "start" else -1
        own_mid = 0.5 * (part.borders[0][k] + part.borders[-1][k])
        d = float((own_mid - p_o) @ n)
        point = p_o + d * n
        # the borders that continue: their t in the other road's frame, shifted to ours
        opart = chain_list[oc].parts[0] if owhich == "start" else chain_list[oc].parts[-1]
        pairs = lanelet_links(part, which, opart, owhich, self.topo)
        ospec = self.specs_of[oc][0 if owhich == "start" else -1]
        values: dict[int, float] = {}
        for pa, pb in pairs:
            for ba, bb in ((pa, pb), (pa + 1, pb + 1)):
                values[ba] = (self._border_t(net, orid, s_o, ospec.lane_ids, bb) - d) * (1.0 if same else -1.0)
        return Anchor(point, heading, values)

    @staticmethod
    def _border_t(net, rid: str, s: float, lane_ids: list[int], border: int) -> float:
        """t of border ``border`` (left to right) of a section with lanes ``lane_ids`` at ``s``."""
        pos = min(border, len(lane_ids) - 1)  # the lane right of the border (left of the last one)
        inner, outer = net.lane_borders(rid, [s], lane_ids[pos])
        left_of_lane = outer[0] if lane_ids[pos] > 0 else inner[0]
        right_of_lane = inner[0] if lane_ids[pos] > 0 else outer[0]
        return float(left_of_lane if border == pos else right_of_lane)

    def _lane_anchor(self, cands: list[tuple[str, int, str | None, str | None]], which: str) -> Anchor | None:
        """Where a connecting road starts (ends): at the centre of the lane it comes from (goes to),
        as wide as that lane, along the direction traffic takes there."""
        cands = [c for c in cands if (c[2] if which == "start" else c[3]) is not None]
        if not cands:
            return None
        rid, lane_id, end_at, start_at = cands[0]
        at = end_at if which == "start" else start_at
        p, h, net, s = self._end_state(rid, at)
        inner, outer = net.lane_borders(rid, [s], lane_id)
        tc = 0.5 * float(inner[0] + outer[0])
        w = abs(float(outer[0] - inner[0]))
        n = np.array([-math.sin(h), math.cos(h)])
        # traffic leaves a road by its end along its heading and by its start against it
        heading = h if (at == "end") == (which == "start") else h + math.pi
        return Anchor(p + tc * n, heading, {0: w / 2, 1: -w / 2})

    # -- links and junctions -----------------------------------------------------------------------
    def _where(self, chain_list: list[Chain]) -> dict[int, tuple[str, int, str | None, str | None]]:
        """For the lanelets of roads outside junctions: (road id, lane id, the road end its own end
        lies at, the road end its start lies at; None where that is inside the road)."""
        out = {}
        for ci, ch in enumerate(chain_list):
            if ch.junction is not None or ci not in self.road_of_chain:
                continue
            rid = self.road_of_chain[ci].id
            last = len(ch.parts) - 1
            for k, (p, spec) in enumerate(zip(ch.parts, self.specs_of[ci])):
                for m, lid in zip(p.members, spec.lane_ids):
                    end_at = ("end" if k == last else None) if m.forward else ("start" if k == 0 else None)
                    start_at = ("start" if k == 0 else None) if m.forward else ("end" if k == last else None)
                    out[m.lanelet.id] = (rid, lid, end_at, start_at)
        return out

    def link(self, chain_list: list[Chain], touch) -> list[Junction]:
        self._chains = chain_list
        """Road links, lane links across roads and the junctions with their connections: roads
        outside junctions that meet one to one are linked directly; a road whose lanes lead into a
        junction (or come out of one) links to the junction; each connecting road links to the road
        its lanelet path comes from and the one it goes to, with one ``<connection>`` from the road
        traffic enters by."""
        outside = [ci for ci, ch in enumerate(chain_list) if ch.junction is None]
        index = {}
        for ci in outside:
            for which in ("start", "end"):
                index[chain_list[ci].end(which)] = (ci, which)
        in_junction = {m.lanelet.id: ch.junction for ch in chain_list if ch.junction is not None
                       for p in ch.parts for m in p.members}
        where = self._where(chain_list)
        js = sorted({ch.junction for ci, ch in enumerate(chain_list) if ch.junction is not None
                     and ci in self.road_of_chain})
        jid = {j: str(1000 + k) for k, j in enumerate(js)}
        connections: dict[int, list[Connection]] = defaultdict(list)
        for ci in outside:
            ch, road = chain_list[ci], self.road_of_chain.get(ci)
            if road is None:
                continue
            for which in ("start", "end"):
                junction = None
                for lid, (_, _, end_at, start_at) in where.items():
                    if where[lid][0] != road.id:
                        continue
                    if end_at == which:
                        junction = next((in_junction[n] for n in self.topo.successors.get(lid, []) if n in in_junction), junction)
                    if start_at == which:
                        junction = next((in_junction[n] for n in self.topo.predecessors.get(lid, []) if n in in_junction), junction)
                link = None
                if junction is not None and junction in jid:
                    link = RoadLink("junction", jid[junction])
                else:
                    others = sorted({index[o] for o in touch.get(ch.end(which), ())
                                     if o in index and index[o][0] in self.road_of_chain})
                    if len(others) == 1:
                        oc, owhich = others[0]
                        link = RoadLink("road", self.road_of_chain[oc].id, owhich)
                        self.lane_links(ch, which, chain_list[oc], owhich, road, self.specs_of[ci], self.specs_of[oc])
                if link is not None:
                    if which == "start":
                        road.predecessor = link
                    else:
                        road.successor = link
        for ci, ch in enumerate(chain_list):
            road = self.road_of_chain.get(ci)
            if ch.junction is None or road is None:
                continue
            road.junction = jid[ch.junction]
            lane = road.lane_sections[0].lane(-1)
            last = road.lane_sections[-1].lane(-1)
            first_ll, last_ll = ch.parts[0].members[0].lanelet, ch.parts[-1].members[0].lanelet
            for which, ll, linked in (("start", first_ll, self.topo.predecessors.get(first_ll.id, [])),
                                      ("end", last_ll, self.topo.successors.get(last_ll.id, []))):
                cands = [(where[n][0], where[n][1], where[n][2] if which == "start" else where[n][3])
                         for n in linked if n in where]
                cands = [c for c in cands if c[2] is not None]
                if not cands:
                    continue
                if len({c[0] for c in cands}) > 1:
                    self.warnings.append(f"road {road.id} (junction {road.junction}): lanelet {ll.id} continues "
                                         f"roads {sorted({c[0] for c in cands})}; linked to {cands[0][0]}")
                orid, olane, oend = cands[0]
                link = RoadLink("road", orid, oend)
                other = self.roads[orid]
                osec = other.lane_sections[0 if oend == "start" else -1]
                olane_obj = osec.lane(olane)
                ods = 0.0 if oend == "start" else other.length - osec.s
                here = lane if which == "start" else last
                hsec = road.lane_sections[0 if which == "start" else -1]
                hds = 0.0 if which == "start" else road.length - hsec.s
                linked_lanes = (olane_obj is not None and width_at(olane_obj, ods) >= ZERO_WIDTH
                                and width_at(here, hds) >= ZERO_WIDTH)
                if which == "start":
                    road.predecessor = link
                    lane.predecessors = [olane] if linked_lanes else []
                    # qc-opendrive 1.0.0 takes a lane link from a bidirectional lane into a junction
                    # for one in the wrong direction: such a connection keeps no laneLink (the
                    # connecting road's own lane link says it)
                    both = olane_obj is not None and olane_obj.direction == "both"
                    connections[ch.junction].append(Connection(
                        str(len(connections[ch.junction])), orid, road.id, contact_point="start",
                        lane_links=[LaneLink(olane, -1)] if linked_lanes and not both else []))
                else:
                    road.successor = link
                    last.successors = [olane] if linked_lanes else []
        return [Junction(jid[j], name="", connections=connections[j]) for j in js]

    def lane_links(self, ch: Chain, which: str, other: Chain, owhich: str, road: Road, specs: list[SectionSpec],
                   ospecs: list[SectionSpec]) -> list[tuple[int, int]]:
        """Lane links of ``road`` at its ``which`` end to ``other`` at its ``owhich`` end:
        returns [(other lane id, this lane id)]."""
        a = _part(ch, which)
        b = _part(other, owhich)
        pairs = lanelet_links(a, which, b, owhich, self.topo)
        k = 0 if which == "start" else -1
        ok = 0 if owhich == "start" else -1
        ids, oids = specs[k].lane_ids, ospecs[ok].lane_ids
        sec = road.lane_sections[k]
        orid = self.road_of_chain[[ci for ci, c in enumerate(self._chains) if c is other][0]].id
        osec = self.roads[orid].lane_sections[ok]
        ds = 0.0 if which == "start" else road.length - sec.s
        ods = 0.0 if owhich == "start" else self.roads[orid].length - osec.s
        out = []
        for pa, pb in pairs:
            lane, olane = sec.lane(ids[pa]), osec.lane(oids[pb])
            if lane is None or olane is None:
                continue
            if width_at(lane, ds) < ZERO_WIDTH or width_at(olane, ods) < ZERO_WIDTH:
                continue
            lst = lane.successors if which == "end" else lane.predecessors
            if oids[pb] not in lst:
                lst.append(oids[pb])
            out.append((oids[pb], ids[pa]))
        return out

    # -- signals and objects -----------------------------------------------------------------------
    def _on_road(self, rid: str, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.frames[rid].project(self.xy[idx, 0], self.xy[idx, 1])

    def traffic_lights(self) -> int:
        """Dynamic signals for the traffic-light regulatory elements (see the module doc)."""
        n = 0
        osm = self.osm
        for rel in osm.relations.values():
            if rel.tags.get("type") != "regulatory_element" or rel.tags.get("subtype") != "traffic_light":
                continue
            users = [ll for ll in self.lanelets.values() if rel.id in ll.regulatory and ll.id in self.lanelet_lanes]
            if not users:
                self.warnings.append(f"traffic light {rel.id} (line {rel.line}): no converted lanelet references "
                                     "it; left out")
                continue
            lights = [osm.ways[m.ref] for m in rel.members if m.role == "refers" and m.ref in osm.ways]
            stop = [osm.ways[m.ref] for m in rel.members if m.role == "ref_line" and m.ref in osm.ways]
            by_road: dict[tuple[str, str], list[int]] = defaultdict(list)
            for ll in users:
                rid, _, lid = self.lanelet_lanes[ll.id]
                by_road[(rid, "+" if lid < 0 else "-")].append(lid)
            for (rid, orient), lanes in sorted(by_road.items()):
                frame = self.frames[rid]
                where = stop[0] if stop else (lights[0] if lights else None)
                s0 = frame.length if orient == "+" else 0.0
                if where is not None:
                    s, _ = self._on_road(rid, osm.way_nodes(where))
                    s0 = float(np.clip(np.nanmean(s), 0.0, frame.length))
                t0, z = 0.0, 0.0
                if lights:
                    li = osm.way_nodes(lights[0])
                    _, t = self._on_road(rid, li)
                    t0 = float(np.nanmean(t)) if np.isfinite(t).any() else 0.0
                    z = float(np.mean(osm.ele[li]))
                region = users[0].tags.get("region", "")
                country = region.upper() if len(region) == 2 else "OpenDRIVE"
                n += 1
                self.n_objects += 1
                sid = str(self.n_objects)
                name = f"traffic_light_{rel.id}"
                xml = (f'<signal s="{s0!r}" t="{t0!r}" id="{sid}" name="{name}" dynamic="yes" '
                       f'orientation="{orient}" zOffset="{z!r}" country="{country}" type="1000001" subtype="-1">'
                       f'<validity fromLane="{min(lanes)}" toLane="{max(lanes)}"/></signal>')
                self.roads[rid].signals.append(RoadObject("signal", sid, s0, t0, type="1000001", subtype="-1",
                                                          name=name, z_offset=z, xml=xml))
        return n

    def _outline_object(self, rid: str, kind: str, subtype: str | None, name: str, idx_or_xy, closed: bool) -> str:
        frame = self.frames[rid]
        pts = idx_or_xy
        s, t = frame.project(pts[:, 0], pts[:, 1])
        s = np.clip(s, 0.0, frame.length)
        self.n_objects += 1
        oid = str(self.n_objects)
        sm, tm = float(np.mean(s)), float(np.mean(t))
        corners = "".join(f'<cornerRoad s="{float(a)!r}" t="{float(b)!r}" dz="0.0" height="0.0"/>'
                          for a, b in zip(s, t))
        sub = f' subtype="{subtype}"' if subtype else ""
        xml = (f'<object type="{kind}"{sub} name="{name}" id="{oid}" s="{sm!r}" t="{tm!r}" zOffset="0.0" '
               f'orientation="none"><outlines><outline id="0" closed="{"true" if closed else "false"}">'
               f'{corners}</outline></outlines></object>')
        self.roads[rid].objects.append(RoadObject("object", oid, sm, tm, type=kind, subtype=subtype, name=name, xml=xml))
        return oid

    def stop_lines(self) -> int:
        """Stop lines (ways of type stop_line) as roadMark objects on the road they cross."""
        import shapely

        n = 0
        polys: dict[str, Any] = {}
        for w in self.osm.ways.values():
            if w.tags.get("type") != "stop_line":
                continue
            try:
                idx = self.osm.way_nodes(w)
            except ValueError:
                continue
            line = shapely.LineString(self.xy[idx]) if len(idx) >= 2 else None
            if line is None:
                continue
            rid = self._road_crossed(line, polys)
            if rid is None:
                self.warnings.append(f"stop line {w.id} (line {w.line}): crosses no converted lane; left out")
                continue
            self._outline_object(rid, "roadMark", "stopLine", f"stop_line_{w.id}", self.xy[idx], closed=False)
            n += 1
        return n

    def _road_crossed(self, geom, polys) -> str | None:
        """The road whose lanelets ``geom`` overlaps most (within 0.5 m), roads outside junctions
        first."""
        import shapely

        if not polys:
            for rid in self.roads:
                members = [self.lanelets[lid].polygon() for lid, v in self.lanelet_lanes.items() if v[0] == rid]
                polys[rid] = shapely.buffer(shapely.union_all(members), 0.5) if members else shapely.Polygon()
        best, best_key = None, (False, 0.0)
        for rid, road in self.roads.items():
            inter = shapely.intersection(polys[rid], geom)
            size = float(shapely.length(inter) + shapely.area(inter))
            key = (road.junction is None, size)
            if size > 0 and key > best_key:
                best, best_key = rid, key
        return best

    def crosswalks(self, lanelets: list[Lanelet]) -> dict[int, tuple[str, str]]:
        """Crosswalk lanelets as crosswalk objects with their outline on the road they cross most."""
        out = {}
        polys: dict[str, Any] = {}
        for ll in lanelets:
            rid = self._road_crossed(ll.polygon(), polys)
            if rid is None:
                self.warnings.append(f"lanelet {ll.id} (crosswalk): crosses no converted road; not converted")
                continue
            ring = np.concatenate([ll.left, ll.right[::-1]])
            out[ll.id] = (rid, self._outline_object(rid, "crosswalk", None, f"crosswalk_{ll.id}", ring, closed=True))
        return out


def _crossing_walks(lanelets: dict[int, Lanelet]) -> list[int]:
    """The crosswalk lanelets that cross a vehicle lane (they become crosswalk objects on that
    road; the others, walkways of their own, become roads with a walking lane)."""
    import shapely

    from aveas_format.opendrive.lanelet2.roads import VEHICLE_TYPES

    walks = [ll for ll in lanelets.values() if ll.subtype == "crosswalk"]
    vehicle = [ll.polygon() for ll in lanelets.values() if ll.lane_type in VEHICLE_TYPES]
    if not walks or not vehicle:
        return []
    tree = shapely.STRtree(vehicle)
    return sorted(w.id for w in walks if len(tree.query(w.polygon(), predicate="intersects")))


def _part(ch: Chain, which: str) -> CrossSection:
    return ch.parts[0] if which == "start" else ch.parts[-1]


def _both(road: Road, which: str, lane_id: int) -> bool:
    sec = road.lane_sections[0 if which == "start" else -1]
    lane = sec.lane(lane_id)
    return lane is not None and lane.direction == "both"


def lanelet2_to_opendrive(source: Any, *, origin: tuple[float, float] | None = None, projection_kind: str = "tmerc",
                          tol: float = 0.02, reference_tol: float = 0.1, name: str | None = None,
                          ) -> Lanelet2Conversion:
    """Convert a Lanelet2 OSM map (a path, bytes or XML text) to OpenDRIVE 1.8 (see the module doc).

    ``origin``: (lat, lon) of the local frame's origin (default: the centre of the nodes' bounding
    box); ``projection_kind``: ``"tmerc"`` or ``"utm"`` (:mod:`.osm`). ``tol``: metres the lane
    borders may deviate from the lanelet bounds; ``reference_tol``: the reference line from the
    smoothed centre border.
    """
    from aveas_format.opendrive.builder import roads_xodr

    osm = read_osm(source)
    lat0, lon0 = origin if origin is not None else default_origin(osm)
    proj = projection(projection_kind, float(lat0), float(lon0))
    x, y = proj.forward(osm.lat, osm.lon)
    xy = np.column_stack([x, y])
    lanelets, skipped = read_lanelets(osm, x, y)
    warnings = [f"lanelet {lid}: not converted: {why}" for lid, why in skipped]
    topo = topology(lanelets, xy)
    conv = _Conversion(osm, xy, lanelets, topo, tol, reference_tol, warnings)
    crosswalk_ids = _crossing_walks(lanelets)
    lane_lls = {lid: ll for lid, ll in lanelets.items() if lid not in crosswalk_ids}
    sections = cross_sections(lane_lls, topo)
    touch = contacts(sections, xy)
    classify(sections, touch)
    chain_list = chains(sections, touch, topo)
    paths, lost = junction_paths(sections, topo)
    for lid in lost:
        warnings.append(f"lanelet {lid}: in a junction that no path from an incoming road reaches; converted as "
                        "a connecting road without links")
    chain_list += paths
    conv.build_roads(chain_list, touch)
    junctions = conv.link(chain_list, touch)
    signals = conv.traffic_lights()
    conv.stop_lines()
    crosswalks = conv.crosswalks([lanelets[c] for c in crosswalk_ids])
    areas = sum(1 for r in osm.relations.values() if r.tags.get("type") == "multipolygon")
    header_name = name or (osm.path.rsplit("/", 1)[-1] if osm.path else "lanelet2")
    roads = list(conv.roads.values())
    if not roads:
        raise MapError("no lanelet could be converted: " + ("; ".join(warnings[:5]) or "the file has none"),
                       path=osm.path or "<osm>")
    xodr = roads_xodr(roads, junctions, name=header_name, geo_reference=proj.geo_reference, offset=proj.offset)
    return Lanelet2Conversion(
        xodr=xodr, warnings=warnings, lanelet_lanes=conv.lanelet_lanes, crosswalks=crosswalks,
        lanelets=len(lanelets) + len(skipped), areas=areas, geo_reference=proj.geo_reference,
        offset=proj.offset, origin=(float(lat0), float(lon0)), roads=len(roads), junctions=len(junctions),
        signals=signals,
        stats={"lane_sections": sum(len(r.lane_sections) for r in roads),
               "lanes": sum(len(s.left) + len(s.right) for r in roads for s in r.lane_sections),
               "connecting_roads": sum(1 for r in roads if r.junction is not None)},
    )


__all__ = ["Lanelet2Conversion", "lanelet2_to_opendrive"]
