"""Lanelets from the OSM relations: oriented bounds, neighbours that share a bound, successors,
regulatory elements.

A lanelet is a relation ``type=lanelet`` with a ``left`` and a ``right`` way. Its direction is the
one in which its left bound lies on the left, as Lanelet2 reads it: the right bound is first turned
to run the way the left one does (their ends nearer each other), and when the left bound then lies
on the right of that direction both are reversed (a lanelet of the opposite direction that shares
its left bound with its neighbour stores that way once, pointing the neighbour's way). Lanelets
whose bounds cannot be read (a missing way or node, fewer than two points, no area) are listed with
the reason, not converted.

Relations between lanelets follow from shared points and ways, as in Lanelet2's routing graph:
``B`` follows ``A`` where A's bounds end at the points where B's begin; two lanelets are
neighbours where they share a bound way (the same direction when one's right bound is the other's
left, opposite directions when both use it as their left bound, or both as their right bound).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from aveas_format.opendrive.lanelet2.osm import OsmMap

#: Lanelet2 lanelet subtype -> OpenDRIVE lane type
LANE_TYPES = {
    "road": "driving", "highway": "driving", "play_street": "driving", "emergency_lane": "shoulder",
    "bus_lane": "bus", "bicycle_lane": "biking", "walkway": "sidewalk", "shared_walkway": "sidewalk",
    "stairs": "sidewalk", "exit": "exit", "rail": "rail", "tram": "tram", "parking": "parking",
    "crosswalk": "walking",
}
#: Lanelet2 line types (type, subtype) -> OpenDRIVE road mark type
def mark_type(tags: dict[str, str]) -> str:
    kind, sub = tags.get("type", ""), tags.get("subtype", "")
    if kind in ("line_thin", "line_thick"):
        return {"dashed": "broken", "solid": "solid", "solid_solid": "solid solid",
                "dashed_solid": "broken solid", "solid_dashed": "solid broken"}.get(sub, "solid")
    if kind == "curbstone":
        return "curb"
    return "none"


@dataclass
class Lanelet:
    """A lanelet with its bounds oriented along it (node indices into the OSM arrays and local
    x/y), its tags and the regulatory elements it references."""

    id: int
    left_way: int
    right_way: int
    left_nodes: np.ndarray
    right_nodes: np.ndarray
    left: np.ndarray
    right: np.ndarray
    tags: dict[str, str]
    regulatory: list[int] = field(default_factory=list)
    line: int | None = None

    @property
    def subtype(self) -> str:
        return self.tags.get("subtype", "road")

    @property
    def one_way(self) -> bool:
        default = self.subtype not in ("walkway", "shared_walkway", "stairs", "crosswalk")
        v = self.tags.get("one_way")
        return default if v is None else v.strip().lower() in ("yes", "true", "1")

    @property
    def lane_type(self) -> str:
        t = LANE_TYPES.get(self.subtype, "none")
        if t == "driving" and not self.one_way:
            return "bidirectional"
        return t

    def polygon(self):
        import shapely

        ring = np.concatenate([self.left, self.right[::-1]])
        return shapely.make_valid(shapely.Polygon(ring)) if len(ring) >= 3 else shapely.Polygon()

    @property
    def length(self) -> float:
        mid = 0.5 * (by_share(self.left, 32) + by_share(self.right, 32))
        return float(np.hypot(*np.diff(mid, axis=0).T).sum())


def by_share(pts: np.ndarray, n: int) -> np.ndarray:
    """``n`` points along a polyline at equal shares of its length (its ends included)."""
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(pts, axis=0).T))]
    if cum[-1] <= 0:
        return np.repeat(pts[:1], n, 0)
    u = np.linspace(0.0, cum[-1], n)
    return np.column_stack([np.interp(u, cum, pts[:, 0]), np.interp(u, cum, pts[:, 1])])


def _signed_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def read_lanelets(osm: OsmMap, x: np.ndarray, y: np.ndarray) -> tuple[dict[int, Lanelet], list[tuple[int, str]]]:
    """The lanelets of ``osm`` with local coordinates ``x``/``y`` (per node), and ``(relation id,
    reason)`` for every lanelet relation that cannot be read."""
    out: dict[int, Lanelet] = {}
    skipped: list[tuple[int, str]] = []
    xy = np.column_stack([x, y])
    for rel in osm.relations.values():
        if rel.tags.get("type") != "lanelet":
            continue
        roles: dict[str, list[int]] = defaultdict(list)
        regs = []
        for m in rel.members:
            if m.type == "way":
                roles[m.role].append(m.ref)
            elif m.type == "relation" and m.role == "regulatory_element":
                regs.append(m.ref)
        if len(roles.get("left", [])) != 1 or len(roles.get("right", [])) != 1:
            skipped.append((rel.id, f"needs one 'left' and one 'right' way, has {len(roles.get('left', []))} "
                                    f"and {len(roles.get('right', []))} (line {rel.line})"))
            continue
        lw, rw = roles["left"][0], roles["right"][0]
        missing = [w for w in (lw, rw) if w not in osm.ways]
        if missing:
            skipped.append((rel.id, f"its bound way {missing[0]} is not in the file (line {rel.line})"))
            continue
        try:
            ln, rn = osm.way_nodes(osm.ways[lw]), osm.way_nodes(osm.ways[rw])
        except ValueError as e:
            skipped.append((rel.id, str(e)))
            continue
        if len(ln) < 2 or len(rn) < 2:
            skipped.append((rel.id, f"a bound has fewer than two points (line {rel.line})"))
            continue
        L, R = xy[ln], xy[rn]
        if (np.hypot(*(R[0] - L[0])) + np.hypot(*(R[-1] - L[-1]))
                > np.hypot(*(R[-1] - L[0])) + np.hypot(*(R[0] - L[-1]))):
            rn, R = rn[::-1], R[::-1]
        area = _signed_area(np.concatenate([L, R[::-1]]))
        if area > 0:  # the left bound lies on the right: the lanelet runs the other way
            ln, rn, L, R = ln[::-1], rn[::-1], L[::-1], R[::-1]
        if abs(area) < 1e-6 or min(np.hypot(*np.diff(L, axis=0).T).sum(), np.hypot(*np.diff(R, axis=0).T).sum()) < 1e-6:
            skipped.append((rel.id, f"its bounds enclose no area (line {rel.line})"))
            continue
        out[rel.id] = Lanelet(rel.id, lw, rw, ln.copy(), rn.copy(), L.copy(), R.copy(), dict(rel.tags), regs, rel.line)
    return out, skipped


@dataclass
class Topology:
    """Successors/predecessors and shared-bound neighbours of the lanelets."""

    successors: dict[int, list[int]]
    predecessors: dict[int, list[int]]
    #: way id -> [(lanelet id, "left"/"right")] of the lanelets that use it as a bound
    way_users: dict[int, list[tuple[int, str]]]


def topology(lanelets: dict[int, Lanelet], xy: np.ndarray, tol: float = 1e-3) -> Topology:
    """Successor relations (shared end/start points, by node or within ``tol`` m) and bound users."""
    starts: dict[tuple[int, int], list[int]] = defaultdict(list)
    for ll in lanelets.values():
        starts[(int(ll.left_nodes[0]), int(ll.right_nodes[0]))].append(ll.id)
    succ: dict[int, list[int]] = defaultdict(list)
    pred: dict[int, list[int]] = defaultdict(list)
    # by node ids first, then by position (points duplicated in the file)
    import shapely

    first_pts = {lid: np.r_[ll.left[0], ll.right[0]] for lid, ll in lanelets.items()}
    ids = list(first_pts)
    tree = shapely.STRtree(shapely.points(np.array([first_pts[i][:2] for i in ids]))) if ids else None
    for ll in lanelets.values():
        cands = set(starts.get((int(ll.left_nodes[-1]), int(ll.right_nodes[-1])), []))
        if tree is not None:
            near = tree.query(shapely.points(ll.left[-1]).buffer(tol))
            for k in near:
                other = lanelets[ids[int(k)]]
                if (np.hypot(*(other.left[0] - ll.left[-1])) <= tol
                        and np.hypot(*(other.right[0] - ll.right[-1])) <= tol):
                    cands.add(other.id)
        cands.discard(ll.id)
        for c in sorted(cands):
            succ[ll.id].append(c)
            pred[c].append(ll.id)
    users: dict[int, list[tuple[int, str]]] = defaultdict(list)
    for ll in lanelets.values():
        users[ll.left_way].append((ll.id, "left"))
        users[ll.right_way].append((ll.id, "right"))
    return Topology(dict(succ), dict(pred), dict(users))


__all__ = ["LANE_TYPES", "Lanelet", "Topology", "by_share", "mark_type", "read_lanelets", "topology"]
