"""The OpenDRIVE engine: reader, exact vectorised geometry, world <-> road coordinates.

>>> from aveas_format.opendrive import load_map
>>> net = load_map("Town04.xodr")                       # doctest: +SKIP
>>> x, y, z, hdg = net.road_to_world("0", [10.0], [-1.75])  # doctest: +SKIP
>>> proj = net.world_to_road(x, y)                      # doctest: +SKIP

See ``docs/opendrive.md`` for the conventions and limits.
"""

from __future__ import annotations

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
from .network import RoadNetwork, load_map
from .projection import Projection
from .roadfit import RoadFit, fit_reference_line, fit_road, road_from_lane_markings


__all__ = [
    "Connection",
    "Geometry",
    "Header",
    "Junction",
    "Lane",
    "LaneLink",
    "LaneSection",
    "Poly3Record",
    "Projection",
    "Road",
    "RoadLink",
    "RoadMark",
    "RoadNetwork",
    "RoadFit",
    "RoadObject",
    "RoadType",
    "fit_reference_line",
    "fit_road",
    "load_map",
    "road_from_lane_markings",
]
