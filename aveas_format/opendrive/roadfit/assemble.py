"""Roads from a reference line and lane borders given as samples: the step that the Lanelet2
conversion (:mod:`aveas_format.opendrive.lanelet2`) and the map built from trajectories
(:mod:`.tracks`) share.

A caller fits a reference line (:mod:`.reference` or :mod:`.hermite`), measures its lane borders
as ``t(s)`` samples against it (:class:`Frame`), and describes each lane section
(:class:`SectionSpec`: borders left to right, which border is the centre lane, the lanes between
them). :func:`lane_sections` turns that into the ``<laneOffset>`` records and the lane sections,
piecewise cubics within a tolerance of the samples and exact at the section's
ends (:func:`~.records.interpolating_cubics`): the lane offset is the centre border, each lane's
width the distance between its two borders (never below 0: a border that crosses its inner
neighbour is held at it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.opendrive.model import Geometry, Header, Lane, LaneSection, Poly3Record, Road, RoadMark
from aveas_format.opendrive.roadfit.records import interpolating_cubics, merge_continuations, relative

#: road mark attributes by type (the writer needs weight/color/width; lane change by type)
_MARK_ATTRS = {"weight": "standard", "color": "standard", "width": "0.12"}


def road_mark(kind: str) -> RoadMark:
    """A ``<roadMark>`` of ``kind`` (solid, broken, solid solid, curb, none, ...) at sOffset 0."""
    change = {"broken": "both", "solid broken": "decrease", "broken solid": "increase", "none": "both"}.get(kind, "none")
    attrs = dict(_MARK_ATTRS, laneChange=change) if kind != "none" else {"color": "standard", "laneChange": "both"}
    return RoadMark(0.0, kind, attrs)


@dataclass
class LaneSpec:
    """One lane of a section: OpenDRIVE lane ``type``, speed limit [m/s], the road mark on its outer
    border, the caller's ``key`` (a lanelet id, a cluster) and ``direction`` (1.7+: ``standard``,
    ``reversed``, ``both``; None: by the side, as usual)."""

    type: str = "driving"
    speed: float | None = None
    outer_mark: str = "none"
    key: Any = None
    direction: str | None = None


@dataclass
class SectionSpec:
    """A lane section from ``s0`` to ``s1`` (absolute s on the reference line): ``borders`` left
    to right as ``(s, t)`` samples covering [s0, s1] (their values at s0 and s1 are kept exactly),
    ``centre``: the index of the border that is the centre lane (lanes left of it get ids > 0),
    ``lanes``: the lanes between neighbouring borders, left to right."""

    s0: float
    s1: float
    borders: list[tuple[np.ndarray, np.ndarray]]
    centre: int
    lanes: list[LaneSpec]
    centre_mark: str = "none"
    #: border index -> t that the border must take at s0 / s1 (where the lanes of a road it meets
    #: end), overriding the samples there
    start_values: dict[int, float] = field(default_factory=dict)
    end_values: dict[int, float] = field(default_factory=dict)
    #: filled by :func:`lane_sections`: lane id of each lane (left to right)
    lane_ids: list[int] = field(default_factory=list)


def lane_id(position: int, centre: int) -> int:
    """OpenDRIVE id of the lane at ``position`` (left to right) with the centre lane at border
    ``centre``: ``centre - position`` left of it, ``-(position - centre + 1)`` right of it."""
    return centre - position if position < centre else -(position - centre + 1)


def _section_grid(borders: list[tuple[np.ndarray, np.ndarray]], s0: float, s1: float,
                  spacing: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """The borders' t on one grid of s over [s0, s1] (every sample's s, at least ``spacing``
    apart, and both ends), kept in order left to right (a border that crosses its left neighbour
    is held at it: no negative widths): (s, t of shape (borders, grid))."""
    cols = []
    for s, t in borders:
        s = np.asarray(s, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        ok = np.isfinite(s) & np.isfinite(t)
        if not ok.any():
            raise ValueError("a lane border has no samples")
        order = np.argsort(s[ok], kind="stable")
        cols.append((s[ok][order], t[ok][order]))
    grid = np.concatenate([c[0] for c in cols])
    grid = np.unique(np.clip(grid, s0, s1))
    grid = grid[(grid > s0 + 1e-6) & (grid < s1 - 1e-6)]
    if len(grid):
        keep = np.r_[True, np.diff(grid) >= spacing]
        grid = grid[keep]
    grid = np.r_[s0, grid, s1]
    T = np.array([np.interp(grid, s, t) for s, t in cols])
    T = np.minimum.accumulate(T, axis=0)
    return grid, T


def _join(grids: list[tuple[np.ndarray, np.ndarray]], sections: list[SectionSpec],
          pairs: list[list[tuple[int, int]]] | None) -> None:
    """Where lanes continue from one section into the next, their borders take one value at the
    boundary (the mean of both sections' own), and so does the centre lane (the lane offset is
    continuous), so linked lanes meet without a gap."""
    if not pairs:
        return
    for k, plist in enumerate(pairs):
        (_, Ta), (_, Tb) = grids[k], grids[k + 1]
        links = set()
        for pa, pb in plist:
            links.update({(pa, pb), (pa + 1, pb + 1)})
        ca, cb = sections[k].centre, sections[k + 1].centre
        if abs(Ta[ca, -1] - Tb[cb, 0]) < 0.5:
            links.add((ca, cb))
        parent: dict[tuple[str, int], tuple[str, int]] = {}

        def find(x):
            while parent.setdefault(x, x) != x:
                x = parent[x]
            return x

        for ba, bb in links:
            parent[find(("a", ba))] = find(("b", bb))
        # a lane that ends (begins) there has no width: its two borders are one
        for side, T, col in (("a", Ta, -1), ("b", Tb, 0)):
            for j in range(len(T) - 1):
                if abs(T[j, col] - T[j + 1, col]) < 1e-9:
                    parent[find((side, j))] = find((side, j + 1))
        groups: dict[tuple[str, int], list[tuple[str, int]]] = {}
        for x in list(parent):
            groups.setdefault(find(x), []).append(x)
        for members in groups.values():
            vals = [Ta[j, -1] if side == "a" else Tb[j, 0] for side, j in members]
            v = float(np.mean(vals))
            for side, j in members:
                if side == "a":
                    Ta[j, -1] = v
                else:
                    Tb[j, 0] = v
        for T, col in ((Ta, -1), (Tb, 0)):
            T[:, col] = np.minimum.accumulate(T[:, col])


def lane_sections(sections: list[SectionSpec], tol: float, pairs: list[list[tuple[int, int]]] | None = None
                  ) -> tuple[list[Poly3Record], list[LaneSection]]:
    """The road's ``<laneOffset>`` records and lane sections of ``sections`` (see the module doc).
    Sets ``SectionSpec.lane_ids``. ``pairs[k]``: the lanes (positions left to right) that continue
    from section k into k + 1 (as for :func:`link_sections`): their borders meet at the boundary.

    The centre border is fitted within ``tol``, every lane's width within ``tol / 2`` and never
    below 0, so a border lies within ``tol / 2`` per lane between it and the centre of its samples
    (and exactly on them at the section's ends)."""
    offset: list[Poly3Record] = []
    out: list[LaneSection] = []
    for spec in sections:
        if len(spec.lanes) != len(spec.borders) - 1:
            raise ValueError("a section needs one lane between each pair of neighbouring borders")
    grids = [_section_grid(spec.borders, spec.s0, spec.s1) for spec in sections]
    for spec, (_, T) in zip(sections, grids):
        for values, col in ((spec.start_values, 0), (spec.end_values, -1)):
            for j, v in values.items():
                T[j, col] = v
            T[:, col] = np.minimum.accumulate(T[:, col])
    _join(grids, sections, pairs)
    for spec, (grid, T) in zip(sections, grids):
        for row in interpolating_cubics(grid, T[spec.centre], tol):
            offset.append(Poly3Record(float(row[0]), float(row[1]), float(row[2]), float(row[3]), float(row[4])))
        left, right, ids = [], [], []
        for j, lane_spec in enumerate(spec.lanes):
            lid = lane_id(j, spec.centre)
            ids.append(lid)
            w = interpolating_cubics(grid, T[j] - T[j + 1], tol / 2, lower=0.0)
            lane = Lane(id=lid, type=lane_spec.type, widths=relative(w, spec.s0),
                        road_marks=[road_mark(lane_spec.outer_mark)], direction=lane_spec.direction)
            if lane_spec.speed is not None and np.isfinite(lane_spec.speed):
                lane.speeds = [(0.0, float(lane_spec.speed), "m/s")]
            (left if lid > 0 else right).append(lane)
        spec.lane_ids = ids
        left.sort(key=lambda ln: ln.id)
        right.sort(key=lambda ln: -ln.id)
        out.append(LaneSection(s=float(spec.s0), left=left,
                               center=Lane(id=0, type="none", road_marks=[road_mark(spec.centre_mark)]),
                               right=right))
    # consecutive records that continue each other (a centre border that does not change between
    # sections) are one record
    if offset:
        rows = np.array([[r.s, r.a, r.b, r.c, r.d] for r in offset])
        rows = merge_continuations(rows, sections[-1].s1)
        if len(rows) == 1 and np.all(np.abs(rows[0, 1:]) < 1e-12):
            offset = []
        else:
            offset = [Poly3Record(*(float(v) for v in row)) for row in rows]
    return offset, out


def width_at(lane: Lane, ds: float) -> float:
    """The width of ``lane`` at ``ds`` from its section's start."""
    if not len(lane.widths):
        return 0.0
    i = max(0, int(np.searchsorted(lane.widths[:, 0], ds + 1e-12, side="right")) - 1)
    a, b, c, d = lane.widths[i, 1:5]
    u = ds - lane.widths[i, 0]
    return float(a + u * (b + u * (c + u * d)))


#: m: a lane narrower than this where it meets another is not linked to it (it ends or begins
#: there: ASAM qc-opendrive's rules on zero-width lanes and appearing lanes)
ZERO_WIDTH = 1e-3


def link_sections(road: Road, pairs: list[list[tuple[int, int]]], sections: list[SectionSpec]) -> None:
    """Lane links between consecutive lane sections of ``road``: ``pairs[k]`` lists (position in
    section k, position in section k + 1) of the lanes that continue (positions left to right);
    a lane that ends or begins with no width there is not linked."""
    for k, plist in enumerate(pairs):
        a, b = road.lane_sections[k], road.lane_sections[k + 1]
        for pa, pb in plist:
            la = a.lane(sections[k].lane_ids[pa])
            lb = b.lane(sections[k + 1].lane_ids[pb])
            if la is None or lb is None:
                continue
            if width_at(la, b.s - a.s) < ZERO_WIDTH or width_at(lb, 0.0) < ZERO_WIDTH:
                continue
            if lb.id not in la.successors:
                la.successors.append(lb.id)
            if la.id not in lb.predecessors:
                lb.predecessors.append(la.id)


class Frame:
    """World <-> (s, t) on a reference line given as geometries (exact, through the engine's
    projection onto a probe road ``reach`` m wide on each side); points up to 5 cm beyond either
    end are clamped to it, points farther beyond get s and t along the end's tangent."""

    def __init__(self, geoms: list[Geometry], reach: float = 30.0) -> None:
        from aveas_format.opendrive.network import RoadNetwork

        self.geoms = geoms
        self.length = float(sum(g.length for g in geoms))
        w = np.array([[0.0, reach, 0.0, 0.0, 0.0]])
        road = Road(id="frame", length=self.length, geometries=geoms,
                    lane_sections=[LaneSection(0.0, left=[Lane(1, "driving", widths=w)], center=Lane(0),
                                               right=[Lane(-1, "driving", widths=w)])])
        self.net = RoadNetwork(Header(), {"frame": road}, {})
        x, y, _, h = self.net.road_to_world("frame", [0.0, self.length], [0.0, 0.0])
        self.ends = np.column_stack([x, y]), h

    def to_world(self, s: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y and the reference heading at (s, t) (s clamped to the line)."""
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.length)
        x, y, _, h = self.net.road_to_world("frame", s, np.asarray(t, dtype=np.float64))
        return x, y, h

    def project(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """s, t of world points (see the class doc)."""
        x = np.asarray(x, dtype=np.float64).ravel()
        y = np.asarray(y, dtype=np.float64).ravel()
        pr = self.net.world_to_road(x, y)
        s, t = pr.s.copy(), pr.t.copy()
        miss = ~np.isfinite(s)
        if miss.any():
            (p, h) = self.ends
            for k, sign in ((0, -1.0), (1, 1.0)):
                dx, dy = x[miss] - p[k, 0], y[miss] - p[k, 1]
                along = dx * np.cos(h[k]) + dy * np.sin(h[k])
                side = -dx * np.sin(h[k]) + dy * np.cos(h[k])
                beyond = sign * along >= 0
                rows = np.flatnonzero(miss)[beyond]
                s[rows] = (0.0 if k == 0 else self.length) + along[beyond]
                t[rows] = side[beyond]
        return s, t


__all__ = ["ZERO_WIDTH", "Frame", "LaneSpec", "SectionSpec", "lane_id", "lane_sections", "link_sections", "road_mark",
           "width_at"]
