"""``RoadNetwork``: the parsed map plus its vectorised geometry, lanes and spatial index.

:class:`RoadNetwork` is :class:`~.core.NetworkCore` (ids, reference lines, profiles, lane
borders) with what is built on top of it: the spatial index and world -> road projection
(:mod:`.projection`), lane polygons (:mod:`.polygons`) and the self-check (:mod:`.check`).
:func:`load_map` reads a map into one.
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

from .check import Finding, check_network
from .core import NetworkCore
from .polygons import lane_polygons
from .projection import Projection, SpatialIndex, project, project_track


class RoadNetwork(NetworkCore):
    """An OpenDRIVE road network (see :func:`aveas_format.opendrive.load_map`): the attributes,
    conventions and road-coordinate methods of :class:`~.core.NetworkCore`, plus world -> road,
    lane polygons, the bounds and the self-check."""

    # -- world -> road -------------------------------------------------------------------------------
    @cached_property
    def spatial_index(self) -> SpatialIndex:
        """The chunk STRtree used by :meth:`world_to_road` (built on first use)."""
        return SpatialIndex(self)

    def world_to_road(self, x: Any, y: Any, heading: Any = None, **kw: Any) -> Projection:
        """Road coordinates of world points: a :class:`~.projection.Projection`.

        Keyword options: ``drivable_only`` (ignore non-drivable lanes), ``batch``, ``threads``.
        """
        return project(self, x, y, heading, **kw)

    def world_to_road_track(
        self, x: Any, y: Any, heading: Any = None, time: Any = None, track_id: Any = None, **kw: Any
    ) -> Projection:
        """Like :meth:`world_to_road`, choosing among candidates by trajectory continuity."""
        return project_track(self, x, y, heading, time, track_id, **kw)

    # -- lanes as polygons -----------------------------------------------------------------------------
    def lane_polygons(self, step: float = 1.0, drivable_only: bool = False) -> list[tuple[str, int, int, Any]]:
        """``[(road_id, section_index, lane_id, shapely.Polygon)]`` for every non-centre lane."""
        return lane_polygons(self, step=step, drivable_only=drivable_only)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the road surfaces (lane area, not just reference lines)."""
        return self.spatial_index.bounds

    def check(self) -> list[Finding]:
        """Self-consistency findings (see :mod:`.check`)."""
        return check_network(self)


def load_map(source: Any) -> RoadNetwork:
    """Read an OpenDRIVE map: a path, bytes, or XML text (a str starting with ``<``).

    Raises :class:`~aveas_format.errors.MapError` (a ValueError) naming the path and XML line for
    malformed maps, and :class:`~aveas_format.errors.RecordingIOError` for unreadable files.
    """
    from .reader import parse

    header, roads, junctions, path = parse(source)
    return RoadNetwork(header, roads, junctions, path)


__all__ = ["RoadNetwork", "load_map"]
