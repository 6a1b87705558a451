"""Generate OpenDRIVE 1.8 maps of multi-lane highways (for demos, tests and the SUMO runner).

>>> from aveas_format.opendrive.builder import straight_highway
>>> xodr = straight_highway(length=500.0, lanes_right=2)
>>> xodr.startswith("<?xml")
True

The builders return XML text (pass it to :func:`~aveas_format.opendrive.load_map` directly).
Roads have one lane section: driving lanes of ``lane_width``, a solid road mark on the outer
borders, broken marks between lanes, a solid centre line when both directions exist, and a
``motorway`` type with an optional speed limit.
"""

from __future__ import annotations

import numpy as np

from .geometry import PlanView
from .model import Geometry, Header, Lane, LaneSection, Road, RoadMark, RoadType
from .writer import write_xodr


def _lanes(n: int, side: int, lane_width: float) -> list[Lane]:
    out = []
    for k in range(1, n + 1):
        outer = k == n
        mark = RoadMark(
            s_offset=0.0,
            type="solid" if outer else "broken",
            attributes={
                "weight": "standard",
                "color": "standard",
                "width": "0.15",
                "laneChange": "none" if outer else "both",
            },
        )
        out.append(
            Lane(
                id=side * k,
                type="driving",
                widths=np.array([[0.0, lane_width, 0.0, 0.0, 0.0]]),
                road_marks=[mark],
            )
        )
    return out


def chain_geometries(geoms: list[Geometry], x0: float, y0: float, hdg: float) -> list[Geometry]:
    """Set each geometry's start (s, x, y, hdg) to the exact end of the previous one."""
    s = 0.0
    x, y, h = x0, y0, hdg
    out = []
    for g in geoms:
        g.s, g.x, g.y, g.hdg = s, x, y, h
        out.append(g)
        road = Road(id="_", length=s + g.length, geometries=[g])
        pv = PlanView([road], np.zeros(1))
        xe, ye, he, _, _ = pv.evaluate(np.array([0]), np.array([g.length]))
        x, y, h = float(xe[0]), float(ye[0]), float(he[0])
        s += g.length
    return out


def _road_xodr(
    geoms: list[Geometry],
    lanes_right: int,
    lanes_left: int,
    lane_width: float,
    x0: float,
    y0: float,
    hdg: float,
    geo_reference: str | None,
    name: str,
    speed_limit: float | None,
    road_id: str,
) -> str:
    if lanes_right < 0 or lanes_left < 0 or lanes_right + lanes_left == 0:
        raise ValueError("a highway needs at least one lane (lanes_right + lanes_left >= 1)")
    if lane_width <= 0:
        raise ValueError("lane_width must be positive")
    geoms = chain_geometries(geoms, x0, y0, hdg)
    length = float(sum(g.length for g in geoms))
    centre_mark = RoadMark(
        s_offset=0.0,
        type="solid" if lanes_left and lanes_right else "none",
        attributes={"weight": "standard", "color": "standard", "width": "0.15", "laneChange": "none"},
    )
    section = LaneSection(
        s=0.0,
        left=_lanes(lanes_left, 1, lane_width),
        center=Lane(id=0, type="none", road_marks=[centre_mark]),
        right=_lanes(lanes_right, -1, lane_width),
    )
    road = Road(
        id=road_id,
        name=name,
        length=length,
        types=[
            RoadType(
                s=0.0,
                type="motorway",
                country=None,
                speed_max=None if speed_limit is None else repr(float(speed_limit)),
                speed_unit=None if speed_limit is None else "m/s",
            )
        ],
        geometries=geoms,
        lane_sections=[section],
    )
    pv = PlanView([road], np.zeros(1))
    ss = np.linspace(0.0, length, 256)
    g = pv.find(np.zeros_like(ss, dtype=np.int64), ss)
    x, y, h, _, _ = pv.evaluate(g, ss - pv.s0[g])
    half = np.array([lanes_left * lane_width, -lanes_right * lane_width])
    xs = np.concatenate([x - t * np.sin(h) for t in half])
    ys = np.concatenate([y + t * np.cos(h) for t in half])
    header = Header(
        rev_major=1,
        rev_minor=8,
        name=name,
        vendor="aveas_format",
        north=float(ys.max()),
        south=float(ys.min()),
        east=float(xs.max()),
        west=float(xs.min()),
        geo_reference=geo_reference,
    )
    return write_xodr((header, [road], []))


def straight_highway(
    length: float = 2000.0,
    lanes_right: int = 3,
    lanes_left: int = 0,
    lane_width: float = 3.5,
    x0: float = 0.0,
    y0: float = 0.0,
    hdg: float = 0.0,
    geo_reference: str | None = None,
    *,
    name: str = "straight_highway",
    speed_limit: float | None = None,
    road_id: str = "1",
) -> str:
    """A straight road of ``length`` m starting at (x0, y0) with heading ``hdg`` (rad).

    Right lanes (ids -1..-lanes_right) drive along +s under right-hand traffic; left lanes
    (1..lanes_left) the other way. ``speed_limit`` is in m/s. Returns OpenDRIVE 1.8 XML text.
    """
    if length <= 0:
        raise ValueError("length must be positive")
    geoms = [Geometry(s=0.0, x=x0, y=y0, hdg=hdg, length=float(length), kind="line")]
    return _road_xodr(
        geoms, lanes_right, lanes_left, lane_width, x0, y0, hdg, geo_reference, name, speed_limit, road_id
    )


def curved_highway(
    length: float = 2000.0,
    radius: float = 1000.0,
    lanes_right: int = 3,
    lanes_left: int = 0,
    lane_width: float = 3.5,
    x0: float = 0.0,
    y0: float = 0.0,
    hdg: float = 0.0,
    geo_reference: str | None = None,
    *,
    straight: float = 0.0,
    spiral: float = 0.0,
    name: str = "curved_highway",
    speed_limit: float | None = None,
    road_id: str = "1",
) -> str:
    """A highway of total ``length`` m: ``straight`` m of line, ``spiral`` m of clothoid from
    curvature 0 to ``1/radius``, then an arc of ``radius`` (positive: turning left, negative:
    right) for the rest. Returns OpenDRIVE 1.8 XML text."""
    if radius == 0:
        raise ValueError("radius must be non-zero")
    arc_len = length - straight - spiral
    if straight < 0 or spiral < 0 or arc_len <= 0:
        raise ValueError("need straight >= 0, spiral >= 0 and straight + spiral < length")
    inner = max(lanes_left if radius > 0 else lanes_right, 0) * lane_width
    if inner >= abs(radius):
        raise ValueError(
            f"the lanes on the inner side ({inner} m) reach beyond the curve's centre (|radius| = {abs(radius)} m)"
        )
    k = 1.0 / radius
    geoms = []
    if straight > 0:
        geoms.append(Geometry(s=0.0, x=0.0, y=0.0, hdg=0.0, length=float(straight), kind="line"))
    if spiral > 0:
        geoms.append(
            Geometry(
                s=0.0,
                x=0.0,
                y=0.0,
                hdg=0.0,
                length=float(spiral),
                kind="spiral",
                params={"curv_start": 0.0, "curv_end": k},
            )
        )
    geoms.append(Geometry(s=0.0, x=0.0, y=0.0, hdg=0.0, length=float(arc_len), kind="arc", params={"curvature": k}))
    return _road_xodr(
        geoms, lanes_right, lanes_left, lane_width, x0, y0, hdg, geo_reference, name, speed_limit, road_id
    )


def roads_xodr(
    roads: list[Road],
    junctions: list | tuple = (),
    *,
    name: str = "",
    geo_reference: str | None = None,
    offset: tuple[float, float, float, float] | None = None,
    rev_minor: int = 8,
) -> str:
    """OpenDRIVE 1.``rev_minor`` text of hand-made or fitted roads (:mod:`.model` dataclasses).

    The header's bounding box (north/south/east/west) is computed from the lane surfaces of the
    roads (the reference lines offset to their outermost lane borders). Used by
    :mod:`.fit`; the highway builders above write their one road the same way.
    """
    from .network import RoadNetwork

    roads = list(roads)
    if not roads:
        raise ValueError("roads_xodr needs at least one road")
    header = Header(rev_major=1, rev_minor=rev_minor, name=name, vendor="aveas_format",
                    geo_reference=geo_reference, offset=offset)
    net = RoadNetwork(header, {r.id: r for r in roads}, {j.id: j for j in junctions})
    xs, ys = [], []
    for gsec in range(len(net.lanes.section_road)):
        ri = int(net.lanes.section_road[gsec])
        a, b = float(net.lanes.section_start[gsec]), float(net.lanes.section_end[gsec])
        s = np.linspace(a, b, max(2, int(np.ceil((b - a) / 2.0)) + 1))
        r = np.full(len(s), ri)
        x, y, h, _, _, _ = net.plan.at(r, s)
        tl, tr = net.lanes.extent(net.lanes.borders(net.lanes.find_piece(r, s), s))
        for t in (tl, tr):
            xs.append(x - t * np.sin(h))
            ys.append(y + t * np.cos(h))
    xa, ya = np.concatenate(xs), np.concatenate(ys)
    header.north, header.south = float(ya.max()), float(ya.min())
    header.east, header.west = float(xa.max()), float(xa.min())
    return write_xodr((header, roads, list(junctions)), rev_minor=rev_minor)


__all__ = ["curved_highway", "roads_xodr", "straight_highway"]
