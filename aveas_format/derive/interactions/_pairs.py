"""Lane relations per time step: leaders and followers along lane chains and, past a chain's end,
along each participant's route; left and right neighbours (lead and lag) in the adjacent lanes.

Each sample on a lane gets its chain and travel coordinate ``u`` (:mod:`._lanes`); one sort by
``(time step, chain, u)`` gives every leader within a chain. The frontmost sample of a chain at a
time step looks on beyond the chain's end along its route (:func:`_route`), up to
``route_range``. Followers mirror leaders. Neighbours are searched along the adjacent lane's chain
within ``neighbour_range``. The rows carry the 1D metrics of :mod:`._ttc`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from aveas_format.derive._samples import Samples, ragged, road_columns, searchsorted_segments
from aveas_format.derive.interactions._lanes import LaneGraph, lane_graph, lane_positions
from aveas_format.derive.interactions._ttc import follower_leader_metrics
from aveas_format.derive.interactions._velocities import range_rate, range_rate_var, var_along

if TYPE_CHECKING:
    from aveas_format.derive.interactions import InteractionsParams

#: the columns of a block of relation rows (before ``kind``)
ROW_KEYS = ("i", "j", "rel", "gap", "gap_var", "closing", "closing_var", "ttc", "ttc_std", "thw",
            "dhw", "ttc_ca", "ttc_ca_std", "drac", "drac_std", "mdrac", "mdrac_std", "psd", "psd_std")
#: ``rel`` of a block of rows: a code, the position of the relation's name in :data:`REL_NAMES`
#: (sorted: the table's order of relations)
REL_NAMES = ("conflicting", "follower", "leader", "left_neighbour", "right_neighbour")
REL = {name: np.int8(k) for k, name in enumerate(REL_NAMES)}
#: ``kind`` of a block of rows (the TTC's): a code, the position in :data:`KIND_NAMES`
KIND_NAMES = (None, "lane_1d", "box_2d")
KIND = {name: np.int8(k) for k, name in enumerate(KIND_NAMES)}
#: the surrogate columns (``._surrogates``), NaN where a relation has none
SURROGATE_KEYS = ("drac", "drac_std", "mdrac", "mdrac_std", "psd", "psd_std")


@dataclass
class LaneSamples:
    """The states rows on a lane chain whose heading follows the lane's direction of travel.

    ``idx``: their rows in :class:`Samples`; per row the participant, time step, road, chain,
    travel coordinate ``u`` and those in the adjacent lanes (``adj_chain``, ``adj_u``: ``[0]``
    left, ``[1]`` right); speed ``v`` and acceleration ``a`` along the lane with the variances of
    position, speed and acceleration along it (``vp``, ``vv``, ``va``)."""

    G: LaneGraph
    idx: np.ndarray
    pid: np.ndarray
    ts: np.ndarray
    rid: np.ndarray
    chain: np.ndarray
    u: np.ndarray
    adj_chain: np.ndarray
    adj_u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    vp: np.ndarray
    vv: np.ndarray
    va: np.ndarray


def lane_samples(rec, S: Samples, p: InteractionsParams) -> LaneSamples | None:
    """The :class:`LaneSamples` of ``rec`` (None where no sample is on a lane of the map)."""
    s = rec.states
    if not {"road_id", "lane_id", "road_s"} <= set(s.column_names):
        return None
    road_np, lane, rs, on = road_columns(s)
    on &= lane != 0
    if not on.any():
        return None
    net = rec.map
    G = lane_graph(net)
    idx = np.flatnonzero(on)
    rid = road_np[idx].astype(str)
    chain, u, theta, adj_chain, adj_u = lane_positions(net, G, rid,
                                                       lane[idx].astype(np.int64), rs[idx])
    good = chain >= 0
    good &= np.abs(np.angle(np.exp(1j * (S.h[idx] - theta)))) <= p.max_heading_deviation
    idx, rid, chain, u, theta = idx[good], rid[good], chain[good], u[good], theta[good]
    adj_chain, adj_u = adj_chain[:, good], adj_u[:, good]
    if not len(idx):
        return None
    c, sn = np.cos(theta), np.sin(theta)
    if S.shift_x is not None:
        # the smoothed positions (interactions.velocities) move the travel coordinates along
        du = S.shift_x[idx] * c + S.shift_y[idx] * sn
        u = u + du
        adj_u = adj_u + du
    vp, vv, va = var_along(S, idx, c, sn)
    return LaneSamples(G=G, idx=idx, pid=S.pid[idx], ts=S.tstep[idx], rid=rid, chain=chain, u=u,
                       adj_chain=adj_chain, adj_u=adj_u, v=S.vx[idx] * c + S.vy[idx] * sn,
                       a=S.ax[idx] * c + S.ay[idx] * sn, vp=vp, vv=vv, va=va)


def lane_rows(rec, S: Samples, p: InteractionsParams, active: np.ndarray | None = None
              ) -> dict[str, np.ndarray]:
    """Leader/follower rows (along lane chains and, past a chain's end, along each participant's
    route) and left/right neighbour rows (lead and lag in the adjacent lanes); empty if none.
    ``active`` (per states row, whole time steps): the rows that get relations (None: all); the
    others only tell the routes."""
    L = lane_samples(rec, S, p)
    if L is None:
        return {}
    sel = np.arange(len(L.idx)) if active is None else np.flatnonzero(active[L.idx])
    rows: dict[str, list] = {k: [] for k in ROW_KEYS}
    _leader_rows(rows, S, L, p, sel)
    _neighbour_rows(rows, S, L, p, sel)
    if not rows["i"]:
        return {}
    out = {k: np.concatenate(v) for k, v in rows.items()}
    out["kind"] = np.where(along_lane(out["rel"]), KIND["lane_1d"], KIND[None])
    return out


def along_lane(rel: np.ndarray) -> np.ndarray:
    """Which rows (``rel`` codes) are leader or follower rows."""
    return (rel == REL["leader"]) | (rel == REL["follower"])


def _append(rows: dict[str, list], i: np.ndarray, j: np.ndarray, rel: str,
            metrics: dict[str, np.ndarray]) -> None:
    rows["i"].append(i)
    rows["j"].append(j)
    rows["rel"].append(np.full(len(i), REL[rel]))
    for k in ROW_KEYS[3:]:
        rows[k].append(metrics[k])


def _leader_rows(rows: dict[str, list], S: Samples, L: LaneSamples, p: InteractionsParams,
                 sel: np.ndarray) -> None:
    """A ``leader`` row for every follower and a ``follower`` row for its leader, with the
    follower's headways and the pair's 1D TTC (the followers ``sel``: positions in ``L``)."""
    a, b, du = leaders(L, S.t, p.route_range, sel)
    if not len(a):
        return
    fi, li = L.idx[a], L.idx[b]
    gap = du - 0.5 * (S.L[li] + S.L[fi])
    gvar = L.vp[a] + L.vp[b] + 0.25 * (S.sL[li] ** 2 + S.sL[fi] ** 2)
    m = follower_leader_metrics(gap, gvar, S.L[li], (L.v[a], L.a[a], L.vv[a], L.va[a]),
                                (L.v[b], L.a[b], L.vv[b], L.va[b]), p.reaction_time,
                                p.max_deceleration)
    m = {**m, "closing_var": L.vv[a] + L.vv[b]}
    for (i, j, rel) in ((fi, li, "leader"), (li, fi, "follower")):
        _append(rows, i, j, rel, m)


def _neighbour_rows(rows: dict[str, list], S: Samples, L: LaneSamples, p: InteractionsParams,
                    among: np.ndarray) -> None:
    """Lead (front level with or ahead) and lag (front behind) in the adjacent lanes, within
    ``neighbour_range`` of the participant's front along the lanes (of the samples ``among``,
    whole time steps: positions in ``L``)."""
    nch = max(L.G.n, 1)
    key = L.ts.astype(np.int64) * nch + L.chain
    front = L.u + 0.5 * S.L[L.idx]
    o2 = among[np.lexsort((front[among], key[among]))]
    k_sorted, f_sorted = key[o2], front[o2]
    for k, rel in enumerate(("left_neighbour", "right_neighbour")):
        q = among[L.adj_chain[k, among] >= 0]
        if not len(q):
            continue
        gq = L.ts[q].astype(np.int64) * nch + L.adj_chain[k, q]
        lo = np.searchsorted(k_sorted, gq, side="left")
        hi = np.searchsorted(k_sorted, gq, side="right")
        has = hi > lo
        q, lo, hi = q[has], lo[has], hi[has]
        fq = L.adj_u[k, q] + 0.5 * S.L[L.idx[q]]  # own front, in the adjacent lane's coordinate
        pos = lo + searchsorted_segments(f_sorted, lo, hi, fq)
        for sel, at in ((pos < hi, pos), (pos > lo, pos - 1)):  # lead (front level or ahead), lag
            qq, other = q[sel], o2[at[sel]]
            dh = front[other] - fq[sel]
            near = (np.abs(dh) <= p.neighbour_range) & (L.pid[other] != L.pid[qq])
            qq, other, dh = qq[near], other[near], dh[near]
            if not len(qq):
                continue
            i, j = L.idx[qq], L.idx[other]
            gap = np.abs(L.u[other] - L.adj_u[k, qq]) - 0.5 * (S.L[i] + S.L[j])
            gvar = L.vp[qq] + L.vp[other] + 0.25 * (S.sL[i] ** 2 + S.sL[j] ** 2)
            nan = np.full(len(i), np.nan)
            _append(rows, i, j, rel, {
                "gap": gap, "gap_var": gvar, "closing": range_rate(S, i, j),
                "closing_var": range_rate_var(S, i, j),
                "ttc": np.full(len(i), np.inf), "ttc_std": nan, "thw": nan, "dhw": dh,
                "ttc_ca": np.full(len(i), np.inf), "ttc_ca_std": nan,
                **{k: nan for k in SURROGATE_KEYS}})


def leaders(L: LaneSamples, t: np.ndarray, route_range: float, sel: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Follower/leader pairs ``(a, b, du)`` (positions in the lane samples, ``du``: centre
    distance along the lanes; ``t``: the time of every states row) among the samples ``sel``
    (positions in ``L``, whole time steps; None: all), the routes from all of ``L``.

    Within a lane chain the leader is the next sample by ``u`` at the same time step (one sort).
    The last sample of a chain at a time step looks beyond the chain's end along its route
    (:func:`_route`): the nearest sample, within ``route_range`` of the chain's end, among the
    chains the route enters."""
    G, pid, ts, chain, u = L.G, L.pid, L.ts, L.chain, L.u
    nch = max(G.n, 1)
    key = ts.astype(np.int64) * nch + chain
    order = np.lexsort((u, key)) if sel is None else sel[np.lexsort((u[sel], key[sel]))]
    ks, us = key[order], u[order]
    same = ks[:-1] == ks[1:]
    a, b = order[:-1][same], order[1:][same]
    du = u[b] - u[a]
    tails = order[np.r_[~same, True]] if len(order) else np.zeros(0, np.int64)
    if not len(tails) or not any(G.succ):
        return a, b, du
    rep, ent_chain, ent_u, ent_dist = _route_entries(L, t, tails, route_range)
    q = tails[rep]
    gk = ts[q].astype(np.int64) * nch + ent_chain
    lo = np.searchsorted(ks, gk, side="left")
    hi = np.searchsorted(ks, gk, side="right")
    pos = lo + searchsorted_segments(us, lo, hi, ent_u)
    found = pos < hi
    cand = order[np.minimum(pos, len(order) - 1)]
    dist = ent_dist + u[cand] - ent_u
    ok = found & (dist <= route_range) & (pid[cand] != pid[q])
    rep, q, cand, dist = rep[ok], q[ok], cand[ok], dist[ok]
    pick = np.lexsort((dist, rep))
    first = pick[np.r_[True, rep[pick][1:] != rep[pick][:-1]]] if len(pick) else pick
    q, cand, dist = q[first], cand[first], dist[first]
    du_x = (G.length[chain[q]] - u[q]) + dist
    return np.r_[a, q], np.r_[b, cand], np.r_[du, du_x]


def _route_entries(L: LaneSamples, t: np.ndarray, tails: np.ndarray, route_range: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The chains entered along the route of each tail (the frontmost sample of a chain at a time
    step), as ``(tail, chain, entry_u, distance from the end of the tail's chain to the entry)``,
    one row per entry (``tail``: position in ``tails``).

    The route of a sample is that of its *run* (a participant's stretch in one chain, up to its
    later runs); runs with the same chain and later runs share one :func:`_route`."""
    G, pid, rid, chain = L.G, L.pid, L.rid, L.chain
    o3 = np.lexsort((t[L.idx], pid))
    new_run = np.r_[True, (pid[o3][1:] != pid[o3][:-1]) | (chain[o3][1:] != chain[o3][:-1])]
    run_of = np.empty(len(o3), np.int64)
    run_of[o3] = np.cumsum(new_run) - 1
    run_chain = chain[o3][new_run]
    run_road = rid[o3][new_run]
    run_pid = pid[o3][new_run]
    run_end = np.r_[np.flatnonzero(run_pid[1:] != run_pid[:-1]) + 1, len(run_pid)]
    run_last = run_end[np.searchsorted(run_end, np.arange(len(run_pid)), side="right")]
    need = np.unique(run_of[tails])
    need = need[np.array([len(G.succ[c]) > 0 for c in run_chain[need]], bool)]
    vptr = np.zeros(len(run_pid) + 1, np.int64)
    vch: list[int] = []
    ven: list[float] = []
    vdi: list[float] = []
    memo: dict[tuple, list] = {}
    counts = np.zeros(len(run_pid), np.int64)
    for r in need.tolist():
        fut = tuple(zip(run_chain[r + 1:run_last[r]].tolist(),
                        run_road[r + 1:run_last[r]].tolist()))
        mk = (int(run_chain[r]), fut)
        if mk not in memo:
            memo[mk] = _route(G, mk[0], fut, route_range)
        ent = memo[mk]
        counts[r] = len(ent)
        for c, e, d in ent:
            vch.append(c)
            ven.append(e)
            vdi.append(d)
    # entries of run r are at [vptr[r], vptr[r + 1]) in run order of `need`
    vptr[1:] = np.cumsum(counts)
    vch_a, ven_a, vdi_a = (np.asarray(x, float) for x in (vch, ven, vdi))
    vch_a = vch_a.astype(np.int64)
    tr = run_of[tails]
    rep, k = ragged(counts[tr])
    e = vptr[tr][rep] + k
    return rep, vch_a[e], ven_a[e], vdi_a[e]


def _route(G: LaneGraph, start: int, future: tuple[tuple[int, str], ...], reach: float
           ) -> list[tuple[int, float, float]]:
    """The chains a participant in chain ``start`` enters beyond its end, as ``(chain,
    entry_u, distance from the end of start to the entry)``, up to ``reach`` m.

    ``future``: the participant's later stretches in one chain each, as ``(chain, road at their
    start)`` in time order. At each chain end with several continuations the participant's own
    route decides: the first later stretch that is on one of the continuations (or, failing an
    exact lane match, on a road one of them runs on: it took that branch but its lane was matched
    to a neighbouring lane). Where none is (the recording ends before, or it leaves the lane
    sideways for good), all continuations are searched and the nearest vehicle wins. At merges
    the continuation is unique."""
    best: dict[int, tuple[float, float]] = {}
    stack = [(start, 0.0, 0)]  # chain, distance at its end, next index into `future`
    while stack:
        x, d_end, k = stack.pop()
        cands = G.succ[x]
        if not cands or d_end > reach:
            continue
        names = {c for c, _ in cands}
        chosen: set[int] | None = None
        nk = len(future)
        for j in range(k, len(future)):
            fc, fr = future[j]
            by_road = {c for c in names if fr in G.roads[c]}
            if fc in names or by_road:
                chosen, nk = ({fc} if fc in names else by_road), j + 1
                break
        for c, entry in cands:
            if chosen is not None and c not in chosen:
                continue
            if c in best and best[c][1] <= d_end:
                continue
            best[c] = (entry, d_end)
            stack.append((c, d_end + float(G.length[c]) - entry, nk))
    return [(c, e, d) for c, (e, d) in sorted(best.items())]
