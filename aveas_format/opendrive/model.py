"""The typed OpenDRIVE road network: plain dataclasses filled by :mod:`.reader`.

The model keeps what the file says (ids as strings, lane ids as ints, attributes of objects and
signals as dicts, XML line numbers as ``line``); the evaluated, vectorised form lives in
:mod:`.geometry` (reference lines, elevation, superelevation) and :mod:`.lanes` (lane borders).
:class:`~aveas_format.opendrive.network.RoadNetwork` ties both together.

Conventions (ASAM OpenDRIVE): ``s`` runs along the reference line from 0 to ``Road.length``;
``t`` is positive to the left of the reference line; lanes left of the centre lane have positive
ids, lanes to the right negative ids, the centre lane is 0 and has no width.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

GEOMETRY_KINDS = ("line", "arc", "spiral", "poly3", "paramPoly3")


@dataclass(slots=True)
class Header:
    """``<header>``: revision, name, bounding box, ``<geoReference>`` and ``<offset>``."""

    rev_major: int = 1
    rev_minor: int = 8
    name: str = ""
    date: str = ""
    vendor: str = ""
    north: float = 0.0
    south: float = 0.0
    east: float = 0.0
    west: float = 0.0
    geo_reference: str | None = None
    #: ``(x, y, z, hdg)`` of ``<offset>``, or None when the header has none.
    offset: tuple[float, float, float, float] | None = None
    line: int | None = None

    @property
    def version(self) -> str:
        """``"revMajor.revMinor"``, e.g. ``"1.8"``."""
        return f"{self.rev_major}.{self.rev_minor}"


@dataclass(slots=True)
class Poly3Record:
    """A cubic record ``a + b ds + c ds^2 + d ds^3`` starting at ``s`` (absolute along the road)."""

    s: float
    a: float
    b: float = 0.0
    c: float = 0.0
    d: float = 0.0
    line: int | None = None

    @property
    def coef(self) -> tuple[float, float, float, float]:
        return (self.a, self.b, self.c, self.d)


@dataclass(slots=True)
class Geometry:
    """One ``<geometry>`` record of the plan view.

    ``kind`` is one of ``line``, ``arc``, ``spiral``, ``poly3``, ``paramPoly3``; ``params`` holds the
    kind's attributes: ``curvature`` (arc); ``curv_start``, ``curv_end`` (spiral); ``a``..``d``
    (poly3); ``aU``..``dV`` and ``p_range`` (``"arcLength"`` or ``"normalized"``) for paramPoly3.
    """

    s: float
    x: float
    y: float
    hdg: float
    length: float
    kind: str
    params: dict[str, Any] = field(default_factory=dict)
    line: int | None = None


@dataclass(slots=True)
class RoadLink:
    """A road's ``<predecessor>``/``<successor>`` (or a lane-level link target)."""

    element_type: str  # "road" or "junction"
    element_id: str
    contact_point: str | None = None  # "start" / "end"
    element_s: float | None = None  # 1.7+ virtual/direct junction linkage
    element_dir: str | None = None
    line: int | None = None


@dataclass(slots=True)
class RoadType:
    """``<type>`` record of a road with its optional ``<speed>``."""

    s: float
    type: str
    country: str | None = None
    speed_max: str | None = None  # as written: a number or "no limit"/"undefined"
    speed_unit: str | None = None
    line: int | None = None

    @property
    def speed_max_ms(self) -> float | None:
        """Speed limit in m/s (None where absent or not a number)."""
        return _speed_to_ms(self.speed_max, self.speed_unit)


def _speed_to_ms(value: str | None, unit: str | None) -> float | None:
    if value is None:
        return None
    try:
        v = float(value)
    except ValueError:
        return None
    factor = {"km/h": 1 / 3.6, "mph": 0.44704, "m/s": 1.0, None: 1.0}.get(unit, 1.0)
    return v * factor


@dataclass(slots=True)
class RoadMark:
    """``<roadMark>`` of a lane: ``s_offset`` within the section and its attributes as written."""

    s_offset: float
    type: str = "none"
    attributes: dict[str, str] = field(default_factory=dict)
    line: int | None = None


@dataclass(slots=True)
class Lane:
    """One ``<lane>``: id, type, level, width or border records, links, speed, road marks."""

    id: int
    type: str = "none"
    level: bool = False
    #: ``<width>`` records: rows of ``(sOffset, a, b, c, d)``, sOffset relative to the section.
    widths: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    #: ``<border>`` records, same layout; used only where the lane has no ``<width>`` record.
    borders: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    predecessors: list[int] = field(default_factory=list)
    successors: list[int] = field(default_factory=list)
    #: ``<speed>`` records: ``(sOffset, max, unit)``.
    speeds: list[tuple[float, float, str | None]] = field(default_factory=list)
    road_marks: list[RoadMark] = field(default_factory=list)
    #: ``<height>`` records: ``(sOffset, inner, outer)``.
    heights: list[tuple[float, float, float]] = field(default_factory=list)
    direction: str | None = None  # 1.7 ``@direction``
    line: int | None = None

    @property
    def uses_border(self) -> bool:
        """True where the lane is described by ``<border>`` (and has no ``<width>``)."""
        return len(self.widths) == 0 and len(self.borders) > 0


@dataclass(slots=True)
class LaneSection:
    """``<laneSection>``: lanes left (ids > 0), centre (0) and right (ids < 0) from ``s`` on."""

    s: float
    left: list[Lane] = field(default_factory=list)  # sorted 1, 2, 3 ... (outwards)
    center: Lane | None = None
    right: list[Lane] = field(default_factory=list)  # sorted -1, -2, -3 ... (outwards)
    single_side: bool = False
    line: int | None = None

    @property
    def lanes(self) -> list[Lane]:
        """All lanes, left outermost first, then the centre lane, then right lanes outwards."""
        centre = [self.center] if self.center is not None else []
        return list(reversed(self.left)) + centre + list(self.right)

    def lane(self, lane_id: int) -> Lane | None:
        for lane in self.lanes:
            if lane.id == lane_id:
                return lane
        return None


@dataclass(slots=True)
class RoadObject:
    """An ``<object>`` (or ``objectReference``/``tunnel``/``bridge``) or a ``<signal>`` (or
    ``signalReference``): the common fields plus every attribute and the raw XML as written."""

    kind: str  # element tag: object, objectReference, tunnel, bridge, signal, signalReference
    id: str
    s: float
    t: float = 0.0
    type: str | None = None
    subtype: str | None = None
    name: str | None = None
    z_offset: float = 0.0
    attributes: dict[str, str] = field(default_factory=dict)
    xml: str = ""
    line: int | None = None


@dataclass(slots=True)
class Road:
    """``<road>``: plan view, profiles, lanes, links, objects and signals."""

    id: str
    length: float
    name: str = ""
    junction: str | None = None  # junction id, None for "-1"
    rule: str = "RHT"  # traffic rule: RHT / LHT
    predecessor: RoadLink | None = None
    successor: RoadLink | None = None
    types: list[RoadType] = field(default_factory=list)
    geometries: list[Geometry] = field(default_factory=list)
    elevation: list[Poly3Record] = field(default_factory=list)
    superelevation: list[Poly3Record] = field(default_factory=list)
    lane_offset: list[Poly3Record] = field(default_factory=list)
    lane_sections: list[LaneSection] = field(default_factory=list)
    objects: list[RoadObject] = field(default_factory=list)
    signals: list[RoadObject] = field(default_factory=list)
    line: int | None = None

    def section_index(self, s: float) -> int:
        """Index of the lane section containing ``s`` (the last one starting at or before s)."""
        starts = [sec.s for sec in self.lane_sections]
        return max(0, int(np.searchsorted(starts, s, side="right")) - 1)


@dataclass(slots=True)
class LaneLink:
    """``<laneLink from=.. to=..>`` of a junction connection."""

    from_lane: int
    to_lane: int
    overlap_zone: float | None = None
    line: int | None = None


@dataclass(slots=True)
class Connection:
    """A junction ``<connection>``: an incoming road and a connecting (or, in direct junctions,
    linked) road with lane links."""

    id: str
    incoming_road: str | None
    connecting_road: str | None = None
    linked_road: str | None = None  # direct junctions (1.7+)
    contact_point: str | None = None
    lane_links: list[LaneLink] = field(default_factory=list)
    line: int | None = None

    @property
    def target_road(self) -> str | None:
        """The connecting road, or the linked road of a direct junction."""
        return self.connecting_road if self.connecting_road is not None else self.linked_road


@dataclass(slots=True)
class Junction:
    """``<junction>``: connections, type (``default``, ``direct``, ``virtual``, ``crossing``)."""

    id: str
    name: str = ""
    type: str = "default"
    connections: list[Connection] = field(default_factory=list)
    #: other children (priority, controller, ...) as ``(tag, attributes)``.
    extras: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    line: int | None = None


__all__ = [
    "GEOMETRY_KINDS",
    "Connection",
    "Geometry",
    "Header",
    "Junction",
    "Lane",
    "LaneLink",
    "LaneSection",
    "Poly3Record",
    "Road",
    "RoadLink",
    "RoadMark",
    "RoadObject",
    "RoadType",
]
