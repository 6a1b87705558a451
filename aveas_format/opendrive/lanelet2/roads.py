"""Lanelets grouped into roads: cross-sections of neighbours, their contacts, junctions, chains.

1. **Cross-sections.** Lanelets that share bound ways form a cross-section (a path through the
   shared ways: each lanelet has two bounds). Seen in the direction of its first one-way lanelet
   (the *primary* direction) it is ordered left to right; each lanelet runs with it (forward) or
   against it. Borders, left to right, are the bounds between them.
2. **Contacts.** The ends of cross-sections meet where their lanelets' ends share points (node
   ids, or positions within 1 mm): ``contacts[(g, "start"|"end")]`` lists the other ends.
3. **Junctions.** A cross-section is part of a junction (a connecting road) when it is one of
   several that continue the same end (traffic branches there, or merges), or when its vehicle
   lanes overlap the lanes of another cross-section they do not continue (crossing conflicts).
   Ends that meet continue each other where they point away from each other; ends that start
   side by side at the same line are branches. Connecting roads that overlap, meet, or branch
   from the same end form one junction.
4. **Chains.** Outside junctions, cross-sections that meet one to one, end to start, with both
   outer borders continuing, become one road with one lane section each. Inside a junction every
   path of lanelets from where traffic enters to where it leaves is one connecting road, one lane
   wide (:func:`junction_paths`).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from aveas_format.opendrive.lanelet2.lanelets import Lanelet, Topology, by_share

VEHICLE_TYPES = frozenset({"driving", "bidirectional", "bus", "exit", "shoulder"})


@dataclass
class Member:
    """A lanelet in a cross-section: whether it runs with the primary direction."""

    lanelet: Lanelet
    forward: bool

    def border_left(self) -> np.ndarray:
        """Its bound on the primary left, in the primary direction."""
        return self.lanelet.left if self.forward else self.lanelet.right[::-1]

    def border_right(self) -> np.ndarray:
        return self.lanelet.right if self.forward else self.lanelet.left[::-1]

    def way_left(self) -> int:
        return self.lanelet.left_way if self.forward else self.lanelet.right_way

    def way_right(self) -> int:
        return self.lanelet.right_way if self.forward else self.lanelet.left_way

    def end_nodes(self, end: str) -> tuple[int, int]:
        """(left, right) node of the lanelet at the cross-section's ``end`` in primary terms."""
        ll = self.lanelet
        if self.forward:
            return (int(ll.left_nodes[-1]), int(ll.right_nodes[-1])) if end == "end" else \
                (int(ll.left_nodes[0]), int(ll.right_nodes[0]))
        return (int(ll.right_nodes[0]), int(ll.left_nodes[0])) if end == "end" else \
            (int(ll.right_nodes[-1]), int(ll.left_nodes[-1]))

    def lanelet_end(self, end: str) -> str:
        """Which end of the lanelet itself lies at the cross-section's ``end``."""
        return end if self.forward else ("start" if end == "end" else "end")


@dataclass
class CrossSection:
    id: int
    members: list[Member]  # left to right
    junction: int | None = None
    connecting: bool = False

    @property
    def borders(self) -> list[np.ndarray]:
        return [self.members[0].border_left()] + [m.border_right() for m in self.members]

    def flipped(self) -> CrossSection:
        """The same cross-section seen in the opposite direction."""
        return CrossSection(self.id, [Member(m.lanelet, not m.forward) for m in reversed(self.members)],
                            self.junction, self.connecting)

    def midline(self, step: float = 0.5) -> np.ndarray:
        """The middle between the cross-section's outer borders, points paired by their share of
        each border's length (so it runs from the middle of the start line to the middle of the
        end line even where one border is much longer than the other, as at a corner)."""
        a, b = self.borders[0], self.borders[-1]
        la = float(np.hypot(*np.diff(a, axis=0).T).sum())
        lb = float(np.hypot(*np.diff(b, axis=0).T).sum())
        n = max(2, int(np.ceil(max(la, lb) / step)) + 1)
        return 0.5 * (by_share(a, n) + by_share(b, n))

    @property
    def centre(self) -> int:
        """Index of the border between lanes against (left) and with (right) the primary
        direction; 0 where the pattern is not [against..., with...] (lanes against it then carry
        direction "reversed")."""
        fw = [m.forward for m in self.members]
        k = fw.index(True) if True in fw else len(fw)
        return k if all(not f for f in fw[:k]) and all(fw[k:]) else 0

    def polygon(self):
        import shapely

        return shapely.union_all([m.lanelet.polygon() for m in self.members])

    @property
    def vehicle(self) -> bool:
        return any(m.lanelet.lane_type in VEHICLE_TYPES for m in self.members)


def cross_sections(lanelets: dict[int, Lanelet], topo: Topology) -> list[CrossSection]:
    """Lanelets grouped by shared bounds (see the module doc), in a stable order."""
    nb: dict[int, list[tuple[int, int, bool]]] = defaultdict(list)  # lanelet -> (other, way, same dir)
    for way, users in topo.way_users.items():
        users = [(lid, role) for lid, role in users if lid in lanelets]
        if len(users) != 2:
            continue
        (a, ra), (b, rb) = users
        if a == b:
            continue
        nb[a].append((b, way, ra != rb))
        nb[b].append((a, way, ra != rb))
    seen: set[int] = set()
    out: list[CrossSection] = []
    for lid in sorted(lanelets):
        if lid in seen:
            continue
        # the component (a path: two bounds per lanelet), with orientation relative to lid
        comp = {lid: True}
        stack = [lid]
        while stack:
            c = stack.pop()
            for o, _, same in nb[c]:
                if o not in comp:
                    comp[o] = comp[c] if same else not comp[c]
                    stack.append(o)
        seen.update(comp)
        one_way = [k for k in sorted(comp) if lanelets[k].one_way]
        ref = one_way[0] if one_way else min(comp)
        members = {k: Member(lanelets[k], comp[k] == comp[ref]) for k in comp}
        # walk from the leftmost: the member whose primary-left way nobody else uses
        ways_right = {m.way_right(): k for k, m in members.items()}
        start = [k for k, m in members.items() if m.way_left() not in ways_right]
        order = []
        cur = start[0] if start else ref
        visited = set()
        while cur is not None and cur not in visited:
            visited.add(cur)
            order.append(members[cur])
            nxt = [o for o, w, _ in nb[cur] if w == members[cur].way_right() and o in members]
            cur = nxt[0] if nxt else None
        cs = CrossSection(len(out), order)
        if len(order) != len(members) or (len(order) > 1 and not _ordered(cs)):
            # not a simple left-to-right path (bounds shared by lanelets that do not run side by
            # side, as where one turns off the other): every lanelet alone
            for k in sorted(members):
                out.append(CrossSection(len(out), [Member(lanelets[k], True)]))
            continue
        out.append(cs)
    return out


def _ordered(g: CrossSection) -> bool:
    """Whether the borders' end points lie in order along the start and the end line, and the two
    lines are apart (neighbours that run side by side)."""
    b = g.borders
    for k in (0, -1):
        pts = np.array([x[k] for x in b])
        d = pts[-1] - pts[0]
        n = float(np.hypot(*d))
        if n < 0.5:
            return False
        u = (pts - pts[0]) @ (d / n)
        if np.any(np.diff(u) < -0.05):
            return False
    m0 = 0.5 * (b[0][0] + b[-1][0])
    m1 = 0.5 * (b[0][-1] + b[-1][-1])
    return bool(np.hypot(*(m1 - m0)) > 0.5)


def _end_key(xy: np.ndarray, nodes: tuple[int, int]) -> tuple:
    return tuple(sorted(nodes))


def _inward(g: CrossSection, end: str, reach: float = 2.0) -> np.ndarray:
    """Unit vector from the cross-section's ``end`` into it (along its midline, ``reach`` m in)."""
    mid = g.midline(step=0.25)
    if end == "end":
        mid = mid[::-1]
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(mid, axis=0).T))]
    k = min(len(mid) - 1, int(np.searchsorted(cum, min(reach, cum[-1]))))
    d = mid[k] - mid[0]
    n = float(np.hypot(*d))
    return d / n if n > 0 else d


def contacts(sections: list[CrossSection], xy: np.ndarray, tol: float = 1e-3) -> dict[tuple[int, str], set]:
    """For every cross-section end, the ends that continue it (see the module doc): ends meet where
    one of their lanelets' end lines is the other's (the same two nodes, or the same points within
    ``tol``); of those, the ends that lie beyond it continue it (they point away from each other),
    the others start or end beside it (a lane splitting off, several lanes merging)."""
    by_key: dict[tuple, set[tuple[int, str]]] = defaultdict(set)
    for g in sections:
        for end in ("start", "end"):
            for m in g.members:
                nodes = m.end_nodes(end)
                if nodes[0] == nodes[1]:
                    continue
                by_key[("n",) + tuple(sorted(nodes))].add((g.id, end))
                p = np.round(xy[list(nodes)] / tol).astype(np.int64)
                by_key[("p",) + tuple(sorted(map(tuple, p)))].add((g.id, end))
    by_id = {g.id: g for g in sections}
    inward: dict[tuple[int, str], np.ndarray] = {}

    def direction(e: tuple[int, str]) -> np.ndarray:
        if e not in inward:
            inward[e] = _inward(by_id[e[0]], e[1])
        return inward[e]

    out: dict[tuple[int, str], set] = defaultdict(set)
    for ends in by_key.values():
        for e in ends:
            for o in ends:
                if o[0] != e[0] and float(np.dot(direction(e), direction(o))) < 0:
                    out[e].add(o)
    return out


def lanelet_links(g: CrossSection, end: str, other: CrossSection, other_end: str,
                  topo: Topology) -> list[tuple[int, int]]:
    """(position in g, position in other) of lanelets that continue each other across the contact
    of g's ``end`` and other's ``other_end`` (a lanelet's successor or predecessor)."""
    pos = {m.lanelet.id: i for i, m in enumerate(other.members)}
    out = []
    for i, m in enumerate(g.members):
        lid = m.lanelet.id
        lend = m.lanelet_end(end)
        linked = topo.successors.get(lid, []) if lend == "end" else topo.predecessors.get(lid, [])
        for o in linked:
            if o in pos:
                out.append((i, pos[o]))
        # bidirectional lanelets meet head on: their ends share the points the other way round
        if not m.lanelet.one_way or any(not other.members[j].lanelet.one_way for j in pos.values()):
            a = m.end_nodes(end)
            for om in other.members:
                b = om.end_nodes(other_end)
                if set(a) == set(b) and om.lanelet.id != lid and (i, pos[om.lanelet.id]) not in out:
                    out.append((i, pos[om.lanelet.id]))
    return out


def classify(sections: list[CrossSection], touch: dict[tuple[int, str], set]) -> None:
    """Mark connecting roads and group them into junctions (see the module doc)."""
    import shapely

    conn = set()
    for g in sections:
        for end in ("start", "end"):
            beyond = touch.get((g.id, end), ())
            if len(beyond) >= 2:  # traffic branches (or merges) here: the branches are connecting roads
                conn.update(o[0] for o in beyond)
    veh = [g for g in sections if g.vehicle]
    polys = [g.polygon() for g in veh]
    conflict_pairs = []
    if veh:
        tree = shapely.STRtree(polys)
        a, b = tree.query(polys, predicate="intersects")
        for i, j in zip(a, b):
            if i >= j:
                continue
            gi, gj = veh[int(i)], veh[int(j)]
            linked = any(o[0] == gj.id for e in ("start", "end") for o in touch.get((gi.id, e), ()))
            if linked:
                continue
            area = float(shapely.area(shapely.intersection(polys[int(i)], polys[int(j)])))
            if area > 0.5:
                conn.update((gi.id, gj.id))
                conflict_pairs.append((gi.id, gj.id))
    for g in sections:
        g.connecting = g.id in conn
    # junctions: connecting roads that overlap or meet the same end of another road
    parent = {g: g for g in conn}

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    def union(x, y):
        parent[find(x)] = find(y)

    for a, b in conflict_pairs:
        union(a, b)
    for g in sections:
        for end in ("start", "end"):
            others = [o[0] for o in touch.get((g.id, end), ()) if o[0] in conn]
            if g.id in conn:
                others.append(g.id)
            for o in others[1:]:
                union(others[0], o)
            # connecting roads that branch off (or merge into) the same end form one junction
            beyond = [o for o in touch.get((g.id, end), ()) if o[0] in conn]
            for o in beyond:
                for o2 in touch.get(o, ()):
                    if o2[0] in conn:
                        union(o[0], o2[0])
    roots = sorted({find(g) for g in conn})
    jid = {r: k for k, r in enumerate(roots)}
    for g in sections:
        g.junction = jid[find(g.id)] if g.id in conn else None


@dataclass
class Chain:
    """Cross-sections that become one road (each its own lane section), in road direction."""

    parts: list[CrossSection] = field(default_factory=list)
    #: per part: whether it is seen against its own primary direction
    flips: list[bool] = field(default_factory=list)

    def end(self, which: str) -> tuple[int, str]:
        """The cross-section end (id, "start"/"end" in its own terms) at the chain's ``which`` end."""
        k = 0 if which == "start" else -1
        flip = self.flips[k]
        own = which if not flip else ("end" if which == "start" else "start")
        return self.parts[k].id, own

    @property
    def junction(self) -> int | None:
        return self.parts[0].junction


def chains(sections: list[CrossSection], touch: dict[tuple[int, str], set], topo: Topology,
           tol: float = 1e-3) -> list[Chain]:
    """The roads outside junctions: cross-sections merged where they meet one to one, both outer
    borders and the centre lane continue (the lane offset stays continuous) and no lane changes
    sides of the centre lane (see the module doc)."""
    by_id = {g.id: g for g in sections}
    used: set[int] = set()
    out: list[Chain] = []

    def partner(gid: int, end: str):
        o = touch.get((gid, end), set())
        if len(o) != 1:
            return None
        (oid, oend), = o
        if touch.get((oid, oend), set()) != {(gid, end)}:
            return None
        a, b = by_id[gid], by_id[oid]
        if a.junction != b.junction or a.connecting != b.connecting:
            return None
        return oid, oend

    def outer_points(g: CrossSection, end: str) -> np.ndarray:
        k = -1 if end == "end" else 0
        return np.array([g.borders[0][k], g.borders[g.centre][k], g.borders[-1][k]])

    for g in sections:
        if g.id in used or g.connecting:
            continue
        # walk back to the chain's first cross-section
        cur, cur_flip = g.id, False
        seen = {cur}
        while True:
            end = "end" if cur_flip else "start"
            p = partner(cur, end)
            if p is None or p[0] in seen or p[0] in used:
                break
            oid, oend = p
            # the partner continues backwards: its 'end' meets our start (or flipped)
            cur, cur_flip = oid, (oend == "start")
            seen.add(cur)
        # walk forward from there
        first = by_id[cur].flipped() if cur_flip else by_id[cur]
        chain = Chain([first], [cur_flip])
        used.add(cur)
        flip = cur_flip
        while True:
            end = "start" if flip else "end"
            p = partner(chain.parts[-1].id, end)
            if p is None or p[0] in used:
                break
            oid, oend = p
            nxt = by_id[oid] if oend == "start" else by_id[oid].flipped()
            prev = chain.parts[-1]
            if np.max(np.hypot(*(outer_points(prev, "end") - outer_points(nxt, "start")).T)) > tol:
                break
            pairs = lanelet_links(prev, "end", nxt, "start", topo)
            if any((pa < prev.centre) != (pb < nxt.centre) for pa, pb in pairs):
                break
            chain.parts.append(nxt)
            flip = oend == "end"
            chain.flips.append(flip)
            used.add(oid)
        out.append(chain)
    return out


def junction_paths(sections: list[CrossSection], topo: Topology, max_paths: int = 5000
                   ) -> tuple[list[Chain], list[int]]:
    """The connecting roads: every path of lanelets through a junction (successor after
    successor) from one traffic enters by (its predecessor lies outside the junction, or it has
    none) to one it leaves by, one lane wide, as one road (lanelets that several paths share are
    in each). Returns the chains (one single-lanelet cross-section per lanelet, in the lanelet's
    direction) and the ids of junction lanelets no path reaches."""
    inside: dict[int, Lanelet] = {m.lanelet.id: m.lanelet for g in sections if g.connecting for m in g.members}
    junction_of = {m.lanelet.id: g.junction for g in sections if g.connecting for m in g.members}
    out: list[Chain] = []
    reached: set[int] = set()
    cs_id = 1_000_000

    def single(ll: Lanelet) -> CrossSection:
        nonlocal cs_id
        cs_id += 1
        return CrossSection(cs_id, [Member(ll, True)], junction_of[ll.id], True)

    entries = [lid for lid in sorted(inside)
               if not any(p in inside for p in topo.predecessors.get(lid, []))
               or any(p not in inside for p in topo.predecessors.get(lid, []))]
    for lid in entries:
        stack = [[lid]]
        while stack and len(out) < max_paths:
            path = stack.pop()
            nxt = [n for n in topo.successors.get(path[-1], []) if n in inside and n not in path
                   and junction_of[n] == junction_of[path[0]]]
            leaves = [n for n in topo.successors.get(path[-1], []) if n not in inside]
            if leaves or not nxt:
                out.append(Chain([single(inside[k]) for k in path], [False] * len(path)))
                reached.update(path)
            for n in nxt:
                stack.append(path + [n])
    lost = sorted(set(inside) - reached)
    for lid in lost:
        out.append(Chain([single(inside[lid])], [False]))
    return out, lost


__all__ = ["Chain", "CrossSection", "Member", "VEHICLE_TYPES", "chains", "classify", "contacts", "cross_sections",
           "junction_paths", "lanelet_links"]
