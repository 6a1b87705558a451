"""Lane chains: the map's lanes chained along the direction of travel, and each sample's place on
them.

Lanes are chained across lane sections and roads wherever the map's links give a unique
continuation (:func:`lane_graph`); where they do not (diverges, junction entries, merges) the
:class:`LaneGraph` keeps the chains' successors and predecessors. :func:`lane_positions` gives each
sample its chain, its travel coordinate ``u`` along the chain and the same in the adjacent lanes.

Distances along a lane are measured along the **lane centre's own arc length** (:class:`LaneArcs`),
not along the road's reference line: on a curved road a lane at lateral offset ``t`` has the length
``∫ sqrt((1 - κ t)² + t'²) ds``, shorter on the inside of the curve and longer on the outside (a
left-turn lane of a junction is longer than its connecting road's reference line, a right-turn lane
shorter). The arc length is tabulated per lane of every lane section on a grid of ``ARC_STEP`` in
``s`` (trapezoidal rule on ``sqrt((1 - κ t)² + t'²)``, exact on arcs with lanes of constant width)
and interpolated linearly in between.
"""

from __future__ import annotations

import numpy as np

from aveas_format.errors import FormatError

#: the step (m in s) of the tabulated lane-centre arc lengths
ARC_STEP = 0.5


class LaneArcs:
    """The lane-centre arc length of every lane of every lane section, tabulated in ``s``.

    ``node[(road_id, section_index, lane_id)]`` is the lane's index; :meth:`along` gives, for
    samples of lanes ``idx`` at ``s``, the arc length of the lane centre from the section's start;
    ``length[idx]`` is the whole lane's arc length over its section."""

    def __init__(self, net, keys: list[tuple[str, int, int]], s0: np.ndarray, s1: np.ndarray) -> None:
        self.node = {k: i for i, k in enumerate(keys)}
        n = len(keys)
        counts = np.maximum(np.ceil((s1 - s0) / ARC_STEP).astype(np.int64), 1) + 1
        first = np.r_[0, np.cumsum(counts)[:-1]]
        total = int(counts.sum()) if n else 0
        seg = np.repeat(np.arange(n), counts)
        pos = np.arange(total) - first[seg] if n else np.zeros(0, np.int64)
        frac = pos / np.maximum(counts[seg] - 1, 1)
        sg = s0[seg] + frac * (s1 - s0)[seg]
        cum = np.zeros(total)
        roads = np.array([k[0] for k in keys], dtype=object)
        lids = np.array([k[2] for k in keys], np.int64)
        for r in np.unique(roads) if n else ():
            m = np.flatnonzero(roads[seg] == r)
            inner, outer = net.lane_borders(r, sg[m], lids[seg[m]])
            tc = np.nan_to_num(0.5 * (inner + outer))
            kappa = np.asarray(net.reference_line(r, sg[m])[3])
            same = seg[m][1:] == seg[m][:-1]
            ds = np.where(same, np.diff(sg[m]), 0.0)
            # |d(ref + t n)/ds| = sqrt((1 - κ t)² + t'²), integrated by the trapezoidal rule
            # (exact on arcs with lanes of constant width, where the integrand is constant)
            with np.errstate(invalid="ignore", divide="ignore"):
                slope = np.where(same & (ds > 0), np.diff(tc) / ds, 0.0)
            dt_ds = np.zeros(len(m))
            dt_ds[1:] += np.where(same, slope, 0.0)
            dt_ds[:-1] += np.where(same, slope, 0.0)
            nb = np.zeros(len(m))
            nb[1:] += same
            nb[:-1] += same
            dt_ds /= np.maximum(nb, 1)
            speed = np.hypot(1.0 - kappa * tc, dt_ds)
            d = 0.5 * (speed[1:] + speed[:-1]) * ds
            c = np.r_[0.0, np.cumsum(d)]
            # restart the cumulative sum at each lane's first grid point
            starts = np.r_[True, ~same]
            c -= np.maximum.accumulate(np.where(starts, c, 0.0))
            cum[m] = c
        self.s0, self.s1 = s0, s1
        # one increasing key over all lanes: s shifted by each lane's offset
        self._shift = np.r_[0.0, np.cumsum((s1 - s0) + 1.0)[:-1]] - s0 if n else np.zeros(0)
        self._key = sg + self._shift[seg] if n else np.zeros(0)
        self._cum = cum
        last = first + counts - 1
        self.length = cum[last] if n else np.zeros(0)

    def along(self, idx: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Arc length of the centre of lanes ``idx`` from their section's start to ``s``."""
        idx = np.asarray(idx, np.int64)
        if not len(idx):
            return np.zeros(0)
        sc = np.clip(s, self.s0[idx], self.s1[idx])
        return np.interp(sc + self._shift[idx], self._key, self._cum)


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
    ``c``; ``roads[c]``: the roads chain ``c`` runs on; ``arcs``: the lanes' centre arc lengths
    (:class:`LaneArcs`), in which offsets and lengths are measured."""

    def __init__(self, chains: dict[tuple[str, int, int], tuple[int, float, int]],
                 length: np.ndarray, succ: list[list[tuple[int, float]]],
                 pred: list[list[int]], roads: list[frozenset[str]],
                 arcs: LaneArcs | None = None) -> None:
        self.chains = chains
        self.arcs = arcs
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
    keys = list(nodes)
    arcs = LaneArcs(net, keys, np.array([nodes[k]["s0"] for k in keys], float),
                    np.array([max(nodes[k]["s1"], nodes[k]["s0"]) for k in keys], float))
    for k in keys:
        nodes[k]["len"] = float(arcs.length[arcs.node[k]])

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
                     [frozenset(r) for r in roads], arcs)


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


def _node_lookup(arcs: LaneArcs, road_id: str, section: np.ndarray, lane_id: np.ndarray
                 ) -> np.ndarray:
    """The :class:`LaneArcs` index of each (section, lane) of one road (0 where none)."""
    if not len(lane_id):
        return np.zeros(0, np.int64)
    section, lane_id = np.asarray(section, np.int64), np.asarray(lane_id, np.int64)
    lo = int(lane_id.min())
    span = int(lane_id.max()) - lo + 1
    keys, inv = np.unique(section * span + (lane_id - lo), return_inverse=True)  # (section, lane)
    nodes = np.array([arcs.node.get((road_id, si, lid + lo), 0) for si, lid in
                      zip(*(v.tolist() for v in np.divmod(keys, span)))], np.int64)
    return nodes[inv.ravel()]


def lane_positions(net, G: LaneGraph, rid: np.ndarray, lid: np.ndarray, sv: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(chain, u, theta, adj_chain, adj_u)`` of samples on roads ``rid``, lanes ``lid`` at
    ``road_s`` ``sv``: the chain (-1 where the lane is not in the map), the travel coordinate along
    it (the lane centre's arc length, :class:`LaneArcs`), the direction of travel (rad), and chain
    and travel coordinate in the adjacent lanes, ``[0]`` left and ``[1]`` right of the direction of
    travel (-1 and NaN where there is none; the adjacent lane's own arc length at the same ``s``).

    A loop over roads and lane keys, not samples. Raises FormatError for a road not in the map."""
    chains, arcs = G.chains, G.arcs
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
        si = np.clip(np.searchsorted(starts, sv[m], side="right") - 1, 0, len(starts) - 1)
        c, off, d = chain_lookup(chains, r, si, lid[m])
        chain[m], direction[m] = c, d
        u[m] = off + _along(arcs, r, si, lid[m], sv[m], d)
        hdg[m] = np.asarray(net.reference_line(r, sv[m])[2])
        for k, side in enumerate((+1, -1)):
            # left of the direction of travel: towards larger lane ids for right lanes (dir +1)
            adj = lid[m] + side * d
            ok = (c >= 0) & (adj != 0) & (np.sign(adj) == np.sign(lid[m]))
            ca, offa, da = chain_lookup(chains, r, si, np.where(ok, adj, 0))
            ok &= (ca >= 0) & (da == d)
            adj_chain[k, m] = np.where(ok, ca, -1)
            adj_u[k, m] = np.where(ok, offa + _along(arcs, r, si, np.where(ok, adj, lid[m]),
                                                      sv[m], d), np.nan)
    theta = hdg + np.where(direction < 0, np.pi, 0.0)
    return chain, u, theta, adj_chain, adj_u


def _along(arcs: LaneArcs, road_id: str, si: np.ndarray, lid: np.ndarray, s: np.ndarray,
           d: np.ndarray) -> np.ndarray:
    """Distance along the lane centre in the direction of travel ``d`` from the lane's entry into
    its section (its start for d = +1, its end for d = -1) to ``s``."""
    node = _node_lookup(arcs, road_id, si, np.asarray(lid, np.int64))
    a = arcs.along(node, s)
    return np.where(d > 0, a, arcs.length[node] - a)
