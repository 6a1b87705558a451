"""Lane chains: the map's lanes chained along the direction of travel, and each sample's place on
them.

Lanes are chained across lane sections and roads wherever the map's links give a unique
continuation (:func:`lane_graph`); where they do not (diverges, junction entries, merges) the
:class:`LaneGraph` keeps the chains' successors and predecessors. :func:`lane_positions` gives each
sample its chain, its travel coordinate ``u`` along the chain and the same in the adjacent lanes.
"""

from __future__ import annotations

import numpy as np

from aveas_format.errors import FormatError


def lane_chains(net) -> dict[tuple[str, int, int], tuple[int, float, int]]:
    """Chains of lanes along the direction of travel: ``(road_id, section_index, lane_id) ->
    (chain_id, offset, direction)``.

    ``direction`` is +1 where traffic moves towards increasing s (right lanes under right-hand
    traffic), -1 otherwise. A sample's travel coordinate is ``offset + (s - section_start)`` for
    direction +1 and ``offset + (section_end - s)`` for -1. Two lanes are chained where the
    first's only successor (in the direction of travel, across sections, road links and junction
    connections) is the second and the second's only predecessor is the first."""
    return lane_graph(net).chains


class LaneGraph:
    """Lane chains and how they connect where the continuation is not unique.

    ``chains``: as :func:`lane_chains`; ``length[c]``: the length of chain ``c`` along the
    direction of travel; ``succ[c]``: the chains entered at the end of chain ``c``, each as
    ``(chain, entry_u)`` (``entry_u`` is 0 at a chain's head; diverges and junction entries have
    several, merges lead several chains into one); ``pred[c]``: the chains whose end leads into
    ``c``; ``roads[c]``: the roads chain ``c`` runs on."""

    def __init__(self, chains: dict[tuple[str, int, int], tuple[int, float, int]],
                 length: np.ndarray, succ: list[list[tuple[int, float]]],
                 pred: list[list[int]], roads: list[frozenset[str]]) -> None:
        self.chains = chains
        self.length = length
        self.succ = succ
        self.pred = pred
        self.roads = roads

    @property
    def n(self) -> int:
        """Number of chains."""
        return len(self.length)


def lane_graph(net) -> LaneGraph:
    """The :class:`LaneGraph` of a road network (see :func:`lane_chains`)."""
    nodes: dict[tuple[str, int, int], dict] = {}
    for rid, road in net.roads.items():
        rht = (road.rule or "RHT").upper() != "LHT"
        secs = road.lane_sections
        for si, sec in enumerate(secs):
            s0 = sec.s
            s1 = secs[si + 1].s if si + 1 < len(secs) else road.length
            for lane in list(sec.left) + list(sec.right):
                if lane.id == 0:
                    continue
                d = (1 if lane.id < 0 else -1) * (1 if rht else -1)
                nodes[(rid, si, lane.id)] = {"len": max(s1 - s0, 0.0), "dir": d, "lane": lane,
                                             "s0": s0, "s1": s1}

    def neighbours_along(key, forward: bool) -> set[tuple[str, int, int]]:
        """Lanes reached by leaving ``key`` at its end (forward=True: successor side of s)."""
        rid, si, lid = key
        road = net.roads[rid]
        lane = nodes[key]["lane"]
        ids = lane.successors if forward else lane.predecessors
        out: set[tuple[str, int, int]] = set()
        last = len(road.lane_sections) - 1
        if (forward and si < last) or (not forward and si > 0):
            nsi = si + 1 if forward else si - 1
            for j in ids:
                if (rid, nsi, j) in nodes:
                    out.add((rid, nsi, j))
            if not ids and (rid, nsi, lid) in nodes and not _has_explicit_links(road, si, nsi):
                out.add((rid, nsi, lid))
            return out
        link = road.successor if forward else road.predecessor
        if link is None:
            return out
        if link.element_type == "road" and link.element_id in net.roads:
            nr = net.roads[link.element_id]
            nsi = len(nr.lane_sections) - 1 if link.contact_point == "end" else 0
            for j in ids:
                if (nr.id, nsi, j) in nodes:
                    out.add((nr.id, nsi, j))
        elif link.element_type == "junction" and link.element_id in net.junctions:
            for c in net.junctions[link.element_id].connections:
                tgt = c.target_road
                if c.incoming_road != rid or tgt not in net.roads:
                    continue
                nr = net.roads[tgt]
                nsi = len(nr.lane_sections) - 1 if c.contact_point == "end" else 0
                for ll in c.lane_links:
                    if ll.from_lane == lid and (nr.id, nsi, ll.to_lane) in nodes:
                        out.add((nr.id, nsi, ll.to_lane))
        return out

    succ: dict[tuple, set] = {}
    pred: dict[tuple, set] = {k: set() for k in nodes}
    for key, nd in nodes.items():
        nxt = neighbours_along(key, forward=nd["dir"] > 0)
        succ[key] = nxt
        for k in nxt:
            pred[k].add(key)
    nxt_of = {k: next(iter(v)) for k, v in succ.items() if len(v) == 1 and len(pred[next(iter(v))]) == 1}
    has_prev = set(nxt_of.values())
    out: dict[tuple[str, int, int], tuple[int, float, int]] = {}
    tails: list[tuple[str, int, int]] = []
    lengths: list[float] = []
    chain = 0
    for pure_cycles in (False, True):  # chain heads first, then what is left: pure cycles
        for key in nodes:
            if key in out or (not pure_cycles and key in has_prev):
                continue
            off, k, tail = 0.0, key, key
            while k is not None and k not in out:
                out[k] = (chain, off, nodes[k]["dir"])
                off += nodes[k]["len"]
                tail = k
                k = nxt_of.get(k)
            tails.append(tail)
            lengths.append(off)
            chain += 1
    csucc: list[list[tuple[int, float]]] = []
    cpred: list[list[int]] = [[] for _ in range(chain)]
    for c, tail in enumerate(tails):
        nxt = sorted({(out[k][0], out[k][1]) for k in succ[tail]})
        csucc.append(nxt)
        for d, _ in nxt:
            if c not in cpred[d]:
                cpred[d].append(c)
    roads: list[set[str]] = [set() for _ in range(chain)]
    for (rid, _, _), (c, _, _) in out.items():
        roads[c].add(rid)
    return LaneGraph(out, np.asarray(lengths, float), csucc, cpred,
                     [frozenset(r) for r in roads])


def _has_explicit_links(road, si: int, nsi: int) -> bool:
    lanes = road.lane_sections[si].left + road.lane_sections[si].right
    return any(lane.successors or lane.predecessors for lane in lanes)


def chain_lookup(chains: dict[tuple[str, int, int], tuple[int, float, int]], road_id: str,
                  section: np.ndarray, lane_id: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(chain, offset, direction)`` per sample of one road (chain -1 where the lane is not in
    the map), through a dense table over the road's (section, lane) pairs."""
    section = np.asarray(section, np.int64)
    lane_id = np.asarray(lane_id, np.int64)
    n = len(lane_id)
    if not n:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
    lo_l, hi_l = int(min(lane_id.min(), 0)), int(max(lane_id.max(), 0))
    nsec = int(section.max()) + 1
    lut = np.full((3, nsec, hi_l - lo_l + 1), [[[-1.0]], [[0.0]], [[0.0]]])
    for si in range(nsec):
        for lid in range(lo_l, hi_l + 1):
            v = chains.get((road_id, si, lid))
            if v is not None:
                lut[:, si, lid - lo_l] = v
    vals = lut[:, section, lane_id - lo_l]
    return vals[0].astype(np.int64), vals[1], vals[2].astype(np.int64)


def lane_positions(net, chains: dict[tuple[str, int, int], tuple[int, float, int]],
                   rid: np.ndarray, lid: np.ndarray, sv: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(chain, u, theta, adj_chain, adj_u)`` of samples on roads ``rid``, lanes ``lid`` at
    ``road_s`` ``sv``: the chain (-1 where the lane is not in the map), the travel coordinate along
    it, the direction of travel (rad), and chain and travel coordinate in the adjacent lanes,
    ``[0]`` left and ``[1]`` right of the direction of travel (-1 and NaN where there is none).

    A loop over roads and lane keys, not samples. Raises FormatError for a road not in the map."""
    n = len(rid)
    chain = np.full(n, -1, np.int64)
    u = np.full(n, np.nan)
    direction = np.zeros(n, np.int64)
    hdg = np.zeros(n)
    adj_chain = np.full((2, n), -1, np.int64)
    adj_u = np.full((2, n), np.nan)
    for r in np.unique(rid):
        m = np.flatnonzero(rid == r)
        if r not in net.roads:
            raise FormatError(f"derivation interactions: table states: road_id {r!r} is not in the "
                              "map")
        road_obj = net.roads[r]
        starts = np.array([q.s for q in road_obj.lane_sections])
        ends = np.r_[starts[1:], road_obj.length]
        si = np.clip(np.searchsorted(starts, sv[m], side="right") - 1, 0, len(starts) - 1)
        c, off, d = chain_lookup(chains, r, si, lid[m])
        chain[m], direction[m] = c, d
        along = np.where(d > 0, sv[m] - starts[si], ends[si] - sv[m])
        u[m] = off + along
        hdg[m] = np.asarray(net.reference_line(r, sv[m])[2])
        for k, side in enumerate((+1, -1)):
            # left of the direction of travel: towards larger lane ids for right lanes (dir +1)
            adj = lid[m] + side * d
            ok = (c >= 0) & (adj != 0) & (np.sign(adj) == np.sign(lid[m]))
            ca, offa, da = chain_lookup(chains, r, si, np.where(ok, adj, 0))
            ok &= (ca >= 0) & (da == d)
            adj_chain[k, m] = np.where(ok, ca, -1)
            adj_u[k, m] = np.where(ok, offa + along, np.nan)
    theta = hdg + np.where(direction < 0, np.pi, 0.0)
    return chain, u, theta, adj_chain, adj_u
