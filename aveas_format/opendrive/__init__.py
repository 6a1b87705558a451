"""The OpenDRIVE engine: reader, exact vectorised geometry, world <-> road coordinates.

>>> from aveas_format.opendrive import load_map
>>> net = load_map("Town04.xodr")                       # doctest: +SKIP
>>> x, y, z, hdg = net.road_to_world("0", [10.0], [-1.75])  # doctest: +SKIP
>>> proj = net.world_to_road(x, y)                      # doctest: +SKIP

See ``docs/opendrive.md`` for the conventions and limits.
"""

from __future__ import annotations

from typing import Any

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
from .roadfit import RoadFit, fit_reference_line, fit_road, road_from_lane_markings
from .network import RoadNetwork
from .projection import Projection


def load_map(source: Any) -> RoadNetwork:
    """Read an OpenDRIVE map: a path, bytes, or XML text (a str starting with ``<``).

    Raises :class:`~aveas_format.errors.MapError` (a ValueError) naming the path and XML line for
    malformed maps, and :class:`~aveas_format.errors.RecordingIOError` for unreadable files.
    """
    from .reader import parse

    header, roads, junctions, path = parse(source)
    return RoadNetwork(header, roads, junctions, path)


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
