"""``derived/interactions``: lane leaders/followers, neighbours and conflicting pairs with TTC,
gap, THW, DHW and closing speed, each per time step.

Lane relations come from the road coordinates (``road_id``, ``lane_id``, ``road_s``). Lanes are
chained along the direction of travel across lane sections and roads wherever the map's links give
a unique continuation (:func:`lane_graph`); each sample gets a *chain* and a travel coordinate
``u`` along it, and one sort by ``(time, chain, u)`` gives every leader within a chain. The
frontmost sample of a chain at a time step looks on beyond the chain's end along its *route*
(diverges, junction entries, merges): where the chain has several continuations, the one the
participant itself occupies later in the recording (by lane, else by road); where its later
samples show none (the recording ends first, or it leaves the lane sideways), all of them,
nearest vehicle first; up to ``route_range`` beyond the chain's end. Followers mirror leaders, so a vehicle just past a merge
has one follower per approaching lane. Left and right neighbours are the lead (front level with or
ahead of the participant's front) and the lag (front behind it) in the adjacent lanes, found along
the adjacent lane's chain within ``neighbour_range``.

Conventions (docs/derive.md):

- ``gap``: net bumper-to-bumper clearance along the lane, ``u_leader - u_follower - (L_l + L_f)/2``
  (centre reference points, lengths from ``participants``); negative where the footprints overlap
  longitudinally (side by side for neighbours).
- ``thw``: net time headway ``gap / v_follower`` (null where the follower does not move forward);
  ``dhw``: gross distance headway front-to-front, ``gap + L_leader``. In a ``leader`` row the
  headways are the participant's own, in a ``follower`` row those of the follower behind it.
- ``dhw`` of a neighbour row: the signed front-to-front distance along the lanes, the
  neighbour's front minus the participant's (>= 0: lead, < 0: lag).
- ``closing_speed``: ``v_follower - v_leader`` along the lane for lane pairs, the range rate
  ``-d|Δp|/dt`` for neighbours and conflicting pairs (positive = approaching).
- ``ttc`` (``lane_1d``): ``gap / closing_speed`` when closing, with ``ttc_std`` by the delta method
  from the position, velocity and length uncertainties; null when not closing. Extra columns
  ``ttc_ca``/``ttc_ca_std``: the constant-acceleration variant (vehicles do not reverse), with
  accelerations from ``derived/kinematics``.
- ``ttc`` (``box_2d``): first contact time of the two oriented rectangles under constant velocity
  (exact, separating axes on the relative motion), for pairs found within ``search_radius`` on a
  vectorised spatial grid per time step that are not lane leader/follower; ``ttc_std`` from Monte
  Carlo samples of positions, velocities, headings and sizes. ``conflicting`` rows are those pairs
  with a finite 2D TTC up to ``horizon`` that are not neighbours.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.errors import FormatError
from aveas_format.schema.columns import MAY, MUST, col, enum_col, gaussian, pid_col, time_col
from aveas_format.schema.enums import Relation, TtcKind
from aveas_format.schema.tables import derived_table


class InteractionsParams(Params):
    """Parameters of ``interactions``."""

    neighbour_range: float = Field(100.0, gt=0, description="largest distance (m) along the "
                                   "lanes between the fronts of a participant and its left/right "
                                   "lead or lag")
    search_radius: float = Field(120.0, gt=0, description="centre distance (m) within which "
                                 "pairs are candidates for a 2D conflict (those that cannot "
                                 "touch within `horizon` at their relative speed are dropped)")
    horizon: float = Field(10.0, gt=0, description="largest 2D TTC (s) reported for conflicting "
                           "pairs")
    samples: int = Field(32, ge=0, description="Monte Carlo samples for the 2D ttc_std (0: none)")
    seed: int = Field(0, description="random seed of the Monte Carlo samples")
    time_resolution: float = Field(1e-6, gt=0, description="times closer than this (s) are one "
                                   "time step")
    box_2d: bool = Field(True, description="compute 2D TTC for non-lane pairs")
    max_heading_deviation: float = Field(1.0, gt=0, description="samples whose heading deviates "
                                         "more than this (rad) from their lane's direction of "
                                         "travel take part in 2D conflicts only")
    route_range: float = Field(250.0, gt=0, description="how far (m) beyond the end of its lane "
                               "chain a leader is searched along the participant's route (across "
                               "diverges, merges and junctions)")
    velocities: Literal["auto", "states", "smoothed"] = Field(
        "auto", description="velocity along the direction of motion: the states' (measured) or "
        "derived/kinematics' smoothed speed; auto: the one with the smaller std per sample")


# --- 1D TTC ----------------------------------------------------------------------------------------

def ttc_constant_velocity(gap, v_follower, v_leader):
    """1D TTC under constant velocities: ``gap / (v_f - v_l)`` when closing, else +inf."""
    gap, vf, vl = np.broadcast_arrays(*(np.asarray(a, float) for a in (gap, v_follower, v_leader)))
    dv = vf - vl
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((dv > 0) & (gap >= 0), gap / dv, np.inf)


def _first_root(A, B, C, t0, t1):
    """Smallest t in [t0, t1] with A + B t + C t² <= 0 (inf where none), elementwise."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        g0 = A + B * t0 + C * t0 * t0
        out = np.where(g0 <= 0, t0, np.inf)
        lin = np.abs(C) < 1e-12
        r_lin = np.where(B < 0, -A / B, np.inf)
        disc = B * B - 4 * A * C
        sq = np.sqrt(np.maximum(disc, 0.0))
        # numerically stable pair of roots
        qq = -0.5 * (B + np.copysign(sq, B))
        r1 = np.where(qq != 0, qq / C, np.inf)
        r2 = np.where(qq != 0, A / qq, np.inf)
        r1 = np.where(disc >= 0, r1, np.inf)
        r2 = np.where(disc >= 0, r2, np.inf)
        cand = np.stack([np.where(lin, r_lin, r1), np.where(lin, np.inf, r2)])
    cand = np.where((cand >= t0) & (cand <= t1), cand, np.inf)
    return np.minimum(out, cand.min(axis=0))


def ttc_constant_acceleration(gap, v_follower, a_follower, v_leader, a_leader):
    """1D TTC with constant accelerations where vehicles stop rather than reverse (+inf if never).

    ``gap(t) = gap + x_l(t) - x_f(t)``, ``x(t) = v t + a t²/2`` until the vehicle stops."""
    g, vf, af, vl, al = np.broadcast_arrays(*(np.asarray(a, float) for a in
                                              (gap, v_follower, a_follower, v_leader, a_leader)))
    with np.errstate(divide="ignore", invalid="ignore"):
        Tf = np.where((af < 0) & (vf > 0), -vf / af, np.where((vf <= 0) & (af <= 0), 0.0, np.inf))
        Tl = np.where((al < 0) & (vl > 0), -vl / al, np.where((vl <= 0) & (al <= 0), 0.0, np.inf))
    b1 = np.minimum(Tf, Tl)
    b2 = np.maximum(Tf, Tl)
    out = np.full(g.shape, np.inf)
    with np.errstate(invalid="ignore", over="ignore"):
        return _ttc_ca_pieces(g, vf, af, vl, al, Tf, Tl, b1, b2, out)


def _ttc_ca_pieces(g, vf, af, vl, al, Tf, Tl, b1, b2, out):
    for lo, hi in ((np.zeros_like(g), b1), (b1, b2), (b2, np.full_like(g, np.inf))):
        mid = np.where(np.isfinite(hi), 0.5 * (lo + hi), lo + 1.0)
        f_moving = mid < Tf
        l_moving = mid < Tl
        # x(t) = c0 + c1 t + c2 t²
        xf = (np.where(f_moving, 0.0, vf * Tf + 0.5 * af * Tf * Tf), np.where(f_moving, vf, 0.0),
              np.where(f_moving, 0.5 * af, 0.0))
        xl = (np.where(l_moving, 0.0, vl * Tl + 0.5 * al * Tl * Tl), np.where(l_moving, vl, 0.0),
              np.where(l_moving, 0.5 * al, 0.0))
        xf = tuple(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0) for c in xf)
        xl = tuple(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0) for c in xl)
        A = g + xl[0] - xf[0]
        B = xl[1] - xf[1]
        C = xl[2] - xf[2]
        valid = lo < hi
        r = _first_root(A, B, C, lo, np.where(np.isfinite(hi), hi, 1e300))
        out = np.where(valid & (r < out), r, out)
    return np.where(g < 0, np.inf, out)


# --- 2D TTC of oriented rectangles -----------------------------------------------------------------

def ttc_boxes(ax, ay, ah, al, aw, avx, avy, bx, by, bh, bl, bw, bvx, bvy):
    """Exact first-contact time of two oriented rectangles moving at constant velocity without
    rotating (0 if they overlap now, +inf if never), elementwise over pairs.

    Separating-axis theorem on the relative motion: on each of the four edge normals the
    projections overlap during one interval of t; the rectangles touch during the intersection of
    the four intervals (closed sets: touching counts as contact)."""
    arrs = np.broadcast_arrays(*(np.asarray(a, float) for a in
                                 (ax, ay, ah, al, aw, avx, avy, bx, by, bh, bl, bw, bvx, bvy)))
    ax, ay, ah, al, aw, avx, avy, bx, by, bh, bl, bw, bvx, bvy = arrs
    dx, dy = bx - ax, by - ay
    wx, wy = bvx - avx, bvy - avy
    ca, sa, cb, sb = np.cos(ah), np.sin(ah), np.cos(bh), np.sin(bh)
    t_in = np.zeros(dx.shape)
    t_out = np.full(dx.shape, np.inf)
    never = np.zeros(dx.shape, bool)
    for nx, ny in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        ra = 0.5 * al * np.abs(nx * ca + ny * sa) + 0.5 * aw * np.abs(-nx * sa + ny * ca)
        rb = 0.5 * bl * np.abs(nx * cb + ny * sb) + 0.5 * bw * np.abs(-nx * sb + ny * cb)
        R = ra + rb
        d0 = nx * dx + ny * dy
        dv = nx * wx + ny * wy
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lo = np.where(dv > 0, (-R - d0) / dv, (R - d0) / dv)
            hi = np.where(dv > 0, (R - d0) / dv, (-R - d0) / dv)
        still = dv == 0
        lo = np.where(still, -np.inf, lo)
        hi = np.where(still, np.inf, hi)
        never |= still & (np.abs(d0) > R)
        t_in = np.maximum(t_in, lo)
        t_out = np.minimum(t_out, hi)
    hit = ~never & (t_in <= t_out) & (t_out >= 0)
    return np.where(hit, np.maximum(t_in, 0.0), np.inf)


# --- lane chains -----------------------------------------------------------------------------------

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


# --- per-sample preparation -------------------------------------------------------------------------

def _num(table: pa.Table, name: str, default: float | None = None) -> np.ndarray:
    from aveas_format.io.arrow import column_numpy

    if name not in table.column_names:
        return np.full(table.num_rows, np.nan if default is None else default)
    v = column_numpy(table, name)
    return v if default is None else np.where(np.isfinite(v), v, default)


def _sizes(rec, pid: np.ndarray) -> dict[str, np.ndarray]:
    p = rec.participants
    ids = p.column("participant_id").to_numpy()
    order = np.argsort(ids)
    pos = np.searchsorted(ids[order], pid)
    pos = np.clip(pos, 0, len(ids) - 1)
    found = ids[order][pos] == pid
    if not found.all():
        bad = int(pid[~found][0])
        raise FormatError(f"derivation interactions: table states: participant {bad} is not in "
                          "table participants")
    rows = order[pos]
    out = {}
    for c, d in (("length", None), ("width", None), ("length_std", 0.0), ("width_std", 0.0)):
        out[c] = _num(p, c, d)[rows]
    return out


def _accel(rec, derived: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           np.ndarray]:
    """ax, ay and their std per states row: the measured ``ax``/``ay`` of states where present,
    otherwise ``derived`` (those of derived/kinematics; NaN where neither has them)."""
    s = rec.states
    measured = tuple(_num(s, c) for c in ("ax", "ay", "ax_std", "ay_std"))
    have = np.isfinite(measured[0]) & np.isfinite(measured[1])
    return tuple(np.where(have, m, d) for m, d in zip(measured, derived))


def _kinematics_columns(rec, pid: np.ndarray, t: np.ndarray, cols: tuple[str, ...]):
    """Columns of derived/kinematics per states row (NaN where it has no such row or no table)."""
    k = rec.derived.get("kinematics")
    n = len(t)
    if k is None or not set(cols) <= set(k.column_names):
        return (np.full(n, np.nan),) * len(cols)
    kp = k.column("participant_id").to_numpy()
    kt = _num(k, "time")
    if len(kp) == n and np.array_equal(kp, pid) and np.array_equal(kt, t):
        rows = np.arange(n)
        ok = np.ones(n, bool)
    elif len(kp) == 0:
        return (np.full(n, np.nan),) * len(cols)
    else:
        korder = np.lexsort((kt, kp))
        kp, kt = kp[korder], kt[korder]
        rows = np.searchsorted(np.rec.fromarrays([kp, kt]), np.rec.fromarrays([pid, t]))
        rows = np.clip(rows, 0, len(kp) - 1)
        ok = (kp[rows] == pid) & (kt[rows] == t)
        rows = korder[rows]
    return tuple(np.where(ok, _num(k, c)[rows], np.nan) for c in cols)


def _smoothed_velocities(S: _Samples, mode: str) -> int:
    """Replace the along-motion component of the states' velocity by derived/kinematics' smoothed
    speed (with its std), keeping the across-motion component and its variance, where ``mode`` is
    ``smoothed``, or ``auto`` and the smoothed std is the smaller. Only samples moving at >= 0.5
    m/s (a defined direction of motion). Returns the number of samples replaced."""
    speed, speed_std = S.k_speed, S.k_speed_std
    v = np.hypot(S.vx, S.vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        c, sn = S.vx / v, S.vy / v
    cxy = S.rv * S.svx * S.svy
    var_along = c * c * S.svx ** 2 + sn * sn * S.svy ** 2 + 2 * c * sn * cxy
    var_across = sn * sn * S.svx ** 2 + c * c * S.svy ** 2 - 2 * c * sn * cxy
    use = (v >= 0.5) & np.isfinite(speed) & np.isfinite(speed_std)
    if mode == "auto":
        use &= speed_std ** 2 < var_along
    if not use.any():
        return 0
    c, sn, sa, sw = c[use], sn[use], speed_std[use] ** 2, np.maximum(var_across[use], 0.0)
    S.vx, S.vy, S.svx, S.svy, S.rv = (np.array(a, np.float64) for a in (S.vx, S.vy, S.svx, S.svy, S.rv))
    S.vx[use], S.vy[use] = speed[use] * c, speed[use] * sn
    vxx, vyy, vxy = sa * c * c + sw * sn * sn, sa * sn * sn + sw * c * c, (sa - sw) * c * sn
    S.svx[use], S.svy[use] = np.sqrt(vxx), np.sqrt(vyy)
    with np.errstate(invalid="ignore", divide="ignore"):
        S.rv[use] = np.where((vxx > 0) & (vyy > 0), vxy / np.sqrt(vxx * vyy), 0.0)
    return int(use.sum())


class _Samples:
    """The states rows as numpy arrays plus what the pair computations need."""

    def __init__(self, rec, p: InteractionsParams) -> None:
        s = rec.states
        self.pid = s.column("participant_id").to_numpy()
        self.t = _num(s, "time")
        self.x, self.y = _num(s, "x"), _num(s, "y")
        self.h = _num(s, "heading", 0.0)
        self.vx, self.vy = _num(s, "vx", 0.0), _num(s, "vy", 0.0)
        self.sx, self.sy = _num(s, "x_std", 0.0), _num(s, "y_std", 0.0)
        self.rxy = _num(s, "xy_corr", 0.0)
        self.svx, self.svy = _num(s, "vx_std", 0.0), _num(s, "vy_std", 0.0)
        self.rv = _num(s, "vxvy_corr", 0.0)
        self.sh = _num(s, "heading_std", 0.0)
        size = _sizes(rec, self.pid)
        self.L, self.W = size["length"], size["width"]
        self.sL, self.sW = size["length_std"], size["width_std"]
        kin = _kinematics_columns(rec, self.pid, self.t,
                                  ("ax", "ay", "ax_std", "ay_std", "speed", "speed_std"))
        self.ax, self.ay, self.sax, self.say = _accel(rec, kin[:4])
        self.k_speed, self.k_speed_std = kin[4:]  # smoothed speed (see _smoothed_velocities)
        tk = np.round(self.t / p.time_resolution).astype(np.int64)
        self.tstep = np.unique(tk, return_inverse=True)[1].ravel()
        self.n = len(self.t)


def _var_along(S: _Samples, i, c, sn):
    """Variance of position and velocity projected on the unit vector (c, sn)."""
    vp = (c * S.sx[i]) ** 2 + (sn * S.sy[i]) ** 2 + 2 * c * sn * S.rxy[i] * S.sx[i] * S.sy[i]
    vv = (c * S.svx[i]) ** 2 + (sn * S.svy[i]) ** 2 + 2 * c * sn * S.rv[i] * S.svx[i] * S.svy[i]
    va = (c * S.sax[i]) ** 2 + (sn * S.say[i]) ** 2
    return vp, vv, va


# --- lane relations -----------------------------------------------------------------------------------

def _lane_rows(rec, S: _Samples, p: InteractionsParams) -> dict[str, np.ndarray]:
    """Leader/follower rows (along lane chains and, past a chain's end, along each participant's
    route) and left/right neighbour rows (lead and lag in the adjacent lanes)."""
    s = rec.states
    if not {"road_id", "lane_id", "road_s"} <= set(s.column_names):
        return {}
    road = s.column("road_id")
    road = road.cast(pa.string()) if pa.types.is_dictionary(road.type) else road
    road_np = np.asarray(road.to_numpy(zero_copy_only=False), dtype=object)
    lane = _num(s, "lane_id")
    rs = _num(s, "road_s")
    on = np.array([r is not None for r in road_np], dtype=bool) & np.isfinite(lane) & np.isfinite(rs) & (lane != 0)
    if not on.any():
        return {}
    net = rec.map
    G = lane_graph(net)
    chains = G.chains
    idx = np.flatnonzero(on)
    rid = road_np[idx].astype(str)
    lid = lane[idx].astype(np.int64)
    sv = rs[idx]
    # section index, chain and travel coordinate per sample, and the same in the adjacent lanes
    # (left, right of the direction of travel); a loop over roads and lane keys, not samples
    n = len(idx)
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
        c, off, d = _chain_lookup(chains, r, si, lid[m])
        chain[m], direction[m] = c, d
        along = np.where(d > 0, sv[m] - starts[si], ends[si] - sv[m])
        u[m] = off + along
        hdg[m] = np.asarray(net.reference_line(r, sv[m])[2])
        for k, side in enumerate((+1, -1)):
            # left of the direction of travel: towards larger lane ids for right lanes (dir +1)
            adj = lid[m] + side * d
            ok = (c >= 0) & (adj != 0) & (np.sign(adj) == np.sign(lid[m]))
            ca, offa, da = _chain_lookup(chains, r, si, np.where(ok, adj, 0))
            ok &= (ca >= 0) & (da == d)
            adj_chain[k, m] = np.where(ok, ca, -1)
            adj_u[k, m] = np.where(ok, offa + along, np.nan)
    good = chain >= 0
    theta = hdg + np.where(direction < 0, np.pi, 0.0)
    good &= np.abs(np.angle(np.exp(1j * (S.h[idx] - theta)))) <= p.max_heading_deviation
    idx, rid, chain, u, theta = idx[good], rid[good], chain[good], u[good], theta[good]
    adj_chain, adj_u = adj_chain[:, good], adj_u[:, good]
    if not len(idx):
        return {}
    c, sn = np.cos(theta), np.sin(theta)
    v_along = S.vx[idx] * c + S.vy[idx] * sn
    a_along = S.ax[idx] * c + S.ay[idx] * sn
    vp, vv, va = _var_along(S, idx, c, sn)
    ts = S.tstep[idx]
    pid = S.pid[idx]
    rows: dict[str, list] = {k: [] for k in ("i", "j", "rel", "gap", "gap_var", "closing",
                                             "ttc", "ttc_std", "thw", "dhw", "ttc_ca",
                                             "ttc_ca_std")}
    # --- leaders and followers --------------------------------------------------------------
    a, b, du = _leaders(G, S, idx, pid, ts, rid, chain, u, p)
    if len(a):
        fi, li = idx[a], idx[b]
        gap = du - 0.5 * (S.L[li] + S.L[fi])
        gvar = vp[a] + vp[b] + 0.25 * (S.sL[li] ** 2 + S.sL[fi] ** 2)
        dv = v_along[a] - v_along[b]
        dvvar = vv[a] + vv[b]
        ttc = ttc_constant_velocity(gap, v_along[a], v_along[b])
        with np.errstate(divide="ignore", invalid="ignore"):
            ttc_std = np.sqrt(gvar / dv ** 2 + gap ** 2 * dvvar / dv ** 4)
        ttc_ca = ttc_constant_acceleration(gap, v_along[a], a_along[a], v_along[b], a_along[b])
        ttc_ca_std = _ttc_ca_std(gap, v_along[a], a_along[a], v_along[b], a_along[b], ttc_ca,
                                 gvar, vv[a], va[a], vv[b], va[b])
        with np.errstate(divide="ignore", invalid="ignore"):
            thw = np.where((v_along[a] > 0) & (gap >= 0), gap / v_along[a], np.inf)
        dhw = gap + S.L[li]
        for (i, j, rel) in ((fi, li, "leader"), (li, fi, "follower")):
            rows["i"].append(i)
            rows["j"].append(j)
            rows["rel"].append(np.full(len(i), rel, object))
            rows["gap"].append(gap)
            rows["gap_var"].append(gvar)
            rows["closing"].append(dv)
            rows["ttc"].append(ttc)
            rows["ttc_std"].append(np.where(np.isfinite(ttc), ttc_std, np.nan))
            rows["thw"].append(thw)
            rows["dhw"].append(dhw)
            rows["ttc_ca"].append(ttc_ca)
            rows["ttc_ca_std"].append(ttc_ca_std)
    # --- neighbours: lead and lag in the adjacent lanes ---------------------------------------
    nch = max(G.n, 1)
    key = ts.astype(np.int64) * nch + chain
    front = u + 0.5 * S.L[idx]
    o2 = np.lexsort((front, key))
    k_sorted, f_sorted = key[o2], front[o2]
    for k, rel in enumerate(("left_neighbour", "right_neighbour")):
        q = np.flatnonzero(adj_chain[k] >= 0)
        if not len(q):
            continue
        gq = ts[q].astype(np.int64) * nch + adj_chain[k, q]
        lo = np.searchsorted(k_sorted, gq, side="left")
        hi = np.searchsorted(k_sorted, gq, side="right")
        has = hi > lo
        q, lo, hi = q[has], lo[has], hi[has]
        fq = adj_u[k, q] + 0.5 * S.L[idx[q]]  # own front, in the adjacent lane's coordinate
        pos = lo + _searchsorted_segments(f_sorted, lo, hi, fq)
        for sel, at in ((pos < hi, pos), (pos > lo, pos - 1)):  # lead (front level or ahead), lag
            qq, other = q[sel], o2[at[sel]]
            dh = front[other] - fq[sel]
            near = (np.abs(dh) <= p.neighbour_range) & (pid[other] != pid[qq])
            qq, other, dh = qq[near], other[near], dh[near]
            if not len(qq):
                continue
            i, j = idx[qq], idx[other]
            gap = np.abs(u[other] - adj_u[k, qq]) - 0.5 * (S.L[i] + S.L[j])
            gvar = vp[qq] + vp[other] + 0.25 * (S.sL[i] ** 2 + S.sL[j] ** 2)
            rows["i"].append(i)
            rows["j"].append(j)
            rows["rel"].append(np.full(len(i), rel, object))
            rows["gap"].append(gap)
            rows["gap_var"].append(gvar)
            rows["closing"].append(_range_rate(S, i, j))
            nan = np.full(len(i), np.nan)
            rows["ttc"].append(np.full(len(i), np.inf))
            rows["ttc_std"].append(nan)
            rows["thw"].append(nan)
            rows["dhw"].append(dh)
            rows["ttc_ca"].append(np.full(len(i), np.inf))
            rows["ttc_ca_std"].append(nan)
    if not rows["i"]:
        return {}
    out = {k: np.concatenate(v) for k, v in rows.items()}
    out["kind"] = np.where(np.isin(out["rel"], ["leader", "follower"]), "lane_1d", None)
    return out


def _chain_lookup(chains: dict[tuple[str, int, int], tuple[int, float, int]], road_id: str,
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


def _leaders(G: LaneGraph, S: _Samples, idx: np.ndarray, pid: np.ndarray, ts: np.ndarray,
             rid: np.ndarray, chain: np.ndarray, u: np.ndarray, p: InteractionsParams
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Follower/leader pairs ``(a, b, du)`` (positions in the lane samples, ``du``: centre
    distance along the lanes).

    Within a lane chain the leader is the next sample by ``u`` at the same time step (one sort).
    The last sample of a chain at a time step looks beyond the chain's end along its route
    (:func:`_route`): the nearest sample, within ``route_range`` of the chain's end, among the
    chains the route enters."""
    nch = max(G.n, 1)
    key = ts.astype(np.int64) * nch + chain
    order = np.lexsort((u, key))
    ks, us = key[order], u[order]
    same = ks[:-1] == ks[1:]
    a, b = order[:-1][same], order[1:][same]
    du = u[b] - u[a]
    tails = order[np.r_[~same, True]] if len(order) else np.zeros(0, np.int64)
    if not len(tails) or not any(G.succ):
        return a, b, du
    # route variants, one per run of a participant in one chain
    o3 = np.lexsort((S.t[idx], pid))
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
            memo[mk] = _route(G, mk[0], fut, p.route_range)
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
    cnt = counts[tr]
    rep = np.repeat(np.arange(len(tails)), cnt)
    e = vptr[tr][rep] + (np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    q = tails[rep]
    gk = ts[q].astype(np.int64) * nch + vch_a[e]
    lo = np.searchsorted(ks, gk, side="left")
    hi = np.searchsorted(ks, gk, side="right")
    pos = lo + _searchsorted_segments(us, lo, hi, ven_a[e])
    found = pos < hi
    cand = order[np.minimum(pos, len(order) - 1)]
    dist = vdi_a[e] + u[cand] - ven_a[e]
    ok = found & (dist <= p.route_range) & (pid[cand] != pid[q])
    rep, q, cand, dist = rep[ok], q[ok], cand[ok], dist[ok]
    pick = np.lexsort((dist, rep))
    first = pick[np.r_[True, rep[pick][1:] != rep[pick][:-1]]] if len(pick) else pick
    q, cand, dist = q[first], cand[first], dist[first]
    du_x = (G.length[chain[q]] - u[q]) + dist
    return np.r_[a, q], np.r_[b, cand], np.r_[du, du_x]


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


def _searchsorted_segments(a: np.ndarray, lo: np.ndarray, hi: np.ndarray, v: np.ndarray
                           ) -> np.ndarray:
    """For each query, ``searchsorted(a[lo:hi], v)`` (vectorised bisection)."""
    left = lo.copy()
    right = hi.copy()
    while True:
        active = left < right
        if not active.any():
            break
        mid = (left + right) // 2
        go = active & (a[np.minimum(mid, len(a) - 1)] < v)
        left = np.where(go, mid + 1, left)
        right = np.where(active & ~go, mid, right)
    return left - lo


def _range_rate(S: _Samples, i, j):
    dx, dy = S.x[j] - S.x[i], S.y[j] - S.y[i]
    dvx, dvy = S.vx[j] - S.vx[i], S.vy[j] - S.vy[i]
    d = np.hypot(dx, dy)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, -(dx * dvx + dy * dvy) / d, 0.0)


def _ttc_ca_std(g, vf, af, vl, al, ttc, gvar, vfv, afv, vlv, alv):
    """Delta method for the constant-acceleration TTC by central finite differences."""
    base = np.isfinite(ttc)
    var = np.zeros(len(g))
    args = [g, vf, af, vl, al]
    for k, v in enumerate((gvar, vfv, afv, vlv, alv)):
        v = np.nan_to_num(v)
        h = np.maximum(1e-4, 1e-3 * np.abs(args[k]))
        up = list(args)
        dn = list(args)
        up[k] = args[k] + h
        dn[k] = args[k] - h
        with np.errstate(invalid="ignore"):
            d = (ttc_constant_acceleration(*up) - ttc_constant_acceleration(*dn)) / (2 * h)
            var = var + np.where(np.isfinite(d), d * d * v, 0.0)
    return np.where(base & np.isfinite(af) & np.isfinite(al), np.sqrt(var), np.nan)


# --- 2D conflicts ---------------------------------------------------------------------------------

def candidate_pairs(tstep: np.ndarray, x: np.ndarray, y: np.ndarray, radius: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)``, ``i < j`` by row, at the same time step with centre distance <=
    ``radius``: a vectorised uniform grid (cell = radius; the 3x3 neighbourhood of each cell)."""
    n = len(x)
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cx = np.floor((x - x.min()) / radius).astype(np.int64)
    cy = np.floor((y - y.min()) / radius).astype(np.int64)
    ny = int(cy.max()) + 3
    nx = int(cx.max()) + 3
    cell = ((tstep.astype(np.int64) * nx) + (cx + 1)) * ny + (cy + 1)
    order = np.argsort(cell, kind="stable")
    cs = cell[order]
    I, J = [], []
    for ox in (-1, 0, 1):
        for oy in (-1, 0, 1):
            target = cell + ox * ny + oy
            lo = np.searchsorted(cs, target, side="left")
            hi = np.searchsorted(cs, target, side="right")
            cnt = hi - lo
            tot = int(cnt.sum())
            if tot == 0:
                continue
            ii = np.repeat(np.arange(n), cnt)
            jj = order[np.repeat(lo, cnt) + (np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt))]
            keep = ii < jj
            I.append(ii[keep])
            J.append(jj[keep])
    if not I:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(I), np.concatenate(J)
    near = np.hypot(x[j] - x[i], y[j] - y[i]) <= radius
    return i[near], j[near]


def _box_rows(S: _Samples, lane: dict[str, np.ndarray], p: InteractionsParams
              ) -> tuple[dict[str, np.ndarray], dict[tuple[int, int], int]]:
    """2D TTC for candidate pairs that are not lane leader/follower. Returns the conflicting
    rows and the 2D TTC (+std) of every tested pair by (i, j) key for the neighbour rows."""
    i, j = candidate_pairs(S.tstep, S.x, S.y, p.search_radius)
    if lane:
        lf = np.isin(lane["rel"], ["leader", "follower"])
        n = S.n
        lane_keys = np.unique(np.minimum(lane["i"][lf], lane["j"][lf]) * n
                              + np.maximum(lane["i"][lf], lane["j"][lf]))
        k = i * n + j
        pos = np.clip(np.searchsorted(lane_keys, k), 0, max(len(lane_keys) - 1, 0))
        is_lane = (lane_keys[pos] == k) if len(lane_keys) else np.zeros(len(k), bool)
        i, j = i[~is_lane], j[~is_lane]
    # drop pairs that cannot touch within the horizon at their relative speed
    reach = 0.5 * (np.hypot(S.L[i], S.W[i]) + np.hypot(S.L[j], S.W[j]))
    dist = np.hypot(S.x[j] - S.x[i], S.y[j] - S.y[i])
    rel = np.hypot(S.vx[j] - S.vx[i], S.vy[j] - S.vy[i])
    can = dist - reach <= rel * p.horizon
    i, j = i[can], j[can]
    ttc = ttc_boxes(S.x[i], S.y[i], S.h[i], S.L[i], S.W[i], S.vx[i], S.vy[i],
                    S.x[j], S.y[j], S.h[j], S.L[j], S.W[j], S.vx[j], S.vy[j])
    return {"i": i, "j": j, "ttc": ttc}, {}


def _box_std(S: _Samples, i: np.ndarray, j: np.ndarray, p: InteractionsParams) -> np.ndarray:
    """Std of the 2D TTC over Monte Carlo samples of both participants' states and sizes (finite
    samples only; NaN where fewer than half of the samples collide)."""
    if p.samples == 0 or len(i) == 0:
        return np.full(len(i), np.nan)
    rng = np.random.default_rng(p.seed)
    K = p.samples

    def draw(k):
        z1, z2 = rng.standard_normal((2, K, len(k)))
        r = np.clip(S.rxy[k], -0.999, 0.999)
        x = S.x[k] + S.sx[k] * z1
        y = S.y[k] + S.sy[k] * (r * z1 + np.sqrt(1 - r * r) * z2)
        w1, w2 = rng.standard_normal((2, K, len(k)))
        rv = np.clip(S.rv[k], -0.999, 0.999)
        vx = S.vx[k] + S.svx[k] * w1
        vy = S.vy[k] + S.svy[k] * (rv * w1 + np.sqrt(1 - rv * rv) * w2)
        h = S.h[k] + S.sh[k] * rng.standard_normal((K, len(k)))
        L = np.maximum(S.L[k] + S.sL[k] * rng.standard_normal((K, len(k))), 0.1)
        W = np.maximum(S.W[k] + S.sW[k] * rng.standard_normal((K, len(k))), 0.1)
        return x, y, h, L, W, vx, vy

    a = draw(i)
    b = draw(j)
    tt = ttc_boxes(*a, *b)
    fin = np.isfinite(tt)
    cnt = fin.sum(0)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.where(fin, tt, 0.0).sum(0) / cnt
        v = np.where(fin, (tt - m) ** 2, 0.0).sum(0) / np.maximum(cnt - 1, 1)
    return np.where(cnt >= K / 2, np.sqrt(v), np.nan)


# --- the derivation ---------------------------------------------------------------------------------

def compute(rec, p: InteractionsParams) -> pa.Table:
    """The ``derived/interactions`` table of ``rec``."""
    S = _Samples(rec, p)
    if p.velocities != "states":
        _smoothed_velocities(S, p.velocities)
    lane = _lane_rows(rec, S, p)
    parts = []
    if lane:
        parts.append(lane)
    if p.box_2d:
        box, _ = _box_rows(S, lane, p)
        fin = np.isfinite(box["ttc"]) & (box["ttc"] <= p.horizon)
        bi, bj, bt = box["i"][fin], box["j"][fin], box["ttc"][fin]
        bstd = _box_std(S, bi, bj, p)
        n = S.n
        key = np.minimum(bi, bj) * n + np.maximum(bi, bj)
        korder = np.argsort(key)
        ks = key[korder]
        if lane:
            # neighbours get the 2D TTC of their pair
            nb = ~np.isin(lane["rel"], ["leader", "follower"])
            lk = np.minimum(lane["i"], lane["j"]) * n + np.maximum(lane["i"], lane["j"])
            pos = np.clip(np.searchsorted(ks, lk), 0, max(len(ks) - 1, 0))
            hit = nb & (ks[pos] == lk) if len(ks) else np.zeros(len(lk), bool)
            lane["ttc"] = np.where(hit, bt[korder][pos] if len(ks) else np.inf, lane["ttc"])
            lane["ttc_std"] = np.where(hit, bstd[korder][pos] if len(ks) else np.nan,
                                       lane["ttc_std"])
            lane["kind"] = np.where(hit, "box_2d", lane["kind"])
            nk = np.unique(lk[nb])
            pos2 = np.clip(np.searchsorted(nk, key), 0, max(len(nk) - 1, 0))
            is_nb = (nk[pos2] == key) if len(nk) else np.zeros(len(key), bool)
        else:
            is_nb = np.zeros(len(key), bool)
        ci, cj, ct, cs = bi[~is_nb], bj[~is_nb], bt[~is_nb], bstd[~is_nb]
        if len(ci):
            m = len(ci)
            rr = _range_rate(S, ci, cj)
            nan = np.full(2 * m, np.nan)
            parts.append({
                "i": np.r_[ci, cj], "j": np.r_[cj, ci],
                "rel": np.full(2 * m, "conflicting", object),
                "gap": nan, "gap_var": nan, "closing": np.r_[rr, rr], "ttc": np.r_[ct, ct],
                "ttc_std": np.r_[cs, cs], "thw": nan, "dhw": nan,
                "ttc_ca": np.full(2 * m, np.inf), "ttc_ca_std": nan,
                "kind": np.full(2 * m, "box_2d", object),
            })
    if not parts:
        return _table(S, {k: np.zeros(0, t) for k, t in
                          (("i", np.int64), ("j", np.int64), ("rel", object), ("gap", float),
                           ("gap_var", float), ("closing", float), ("ttc", float),
                           ("ttc_std", float), ("thw", float), ("dhw", float), ("ttc_ca", float),
                           ("ttc_ca_std", float), ("kind", object))})
    allr = {k: np.concatenate([q[k] for q in parts]) for k in parts[0]}
    return _table(S, allr)


def _f(v: np.ndarray) -> pa.Array:
    """float64 array with nulls for NaN and +inf (null = undefined / no collision course)."""
    v = np.asarray(v, float)
    return pa.array(v, pa.float64(), mask=~np.isfinite(v))


def _table(S: _Samples, r: dict[str, np.ndarray]) -> pa.Table:
    i, j = r["i"].astype(np.int64), r["j"].astype(np.int64)
    ttc = r["ttc"]
    kind = np.where(np.isfinite(ttc), r["kind"], None)
    t = pa.table({
        "participant_id": pa.array(S.pid[i], pa.int64()),
        "time": pa.array(S.t[i], pa.float64()),
        "other_id": pa.array(S.pid[j], pa.int64()),
        "relation": pa.array(r["rel"].astype(object), pa.string()),
        "ttc": _f(ttc),
        "ttc_std": _f(np.where(np.isfinite(ttc), r["ttc_std"], np.nan)),
        "ttc_kind": pa.array(list(kind), pa.string()),
        "gap": _f(r["gap"]),
        "gap_std": _f(np.sqrt(r["gap_var"])),
        "thw": _f(r["thw"]),
        "dhw": _f(r["dhw"]),
        "closing_speed": _f(r["closing"]),
        "ttc_ca": _f(r["ttc_ca"]),
        "ttc_ca_std": _f(np.where(np.isfinite(r["ttc_ca"]), r["ttc_ca_std"], np.nan)),
    })
    if t.num_rows:
        import pyarrow.compute as pc

        order = pc.sort_indices(t, sort_keys=[("participant_id", "ascending"),
                                              ("time", "ascending"), ("other_id", "ascending"),
                                              ("relation", "ascending")])
        t = t.take(order)
    return t


TABLE = derived_table(
    "interactions",
    doc="Pairwise relations per time step: leaders, followers, neighbours and conflicting "
    "participants with time to collision and headways.",
    key=("participant_id", "time", "other_id", "relation"),
    sort=("participant_id", "time", "other_id"),
    columns=(
        pid_col(),
        time_col(),
        col("other_id", "int64", MUST, "the other participant", minimum=0, nullable=False),
        enum_col("relation", Relation.values(), MUST, "relation of `other_id` to `participant_id`",
                 nullable=False),
        *gaussian("ttc", "s", MAY, "time to collision (null = no collision course)", minimum=0.0),
        enum_col("ttc_kind", TtcKind.values(), MAY, "how `ttc` was computed"),
        *gaussian("ttc_ca", "s", MAY, "time to collision with constant accelerations (vehicles stop "
                  "rather than reverse; null = no collision)", minimum=0.0),
        *gaussian("gap", "m", MAY, "net bumper-to-bumper gap"),
        col("thw", "float64", MAY, "time headway: net gap / speed of the follower (null = infinite)",
            "s", minimum=0.0),
        col("dhw", "float64", MAY, "distance headway: gross front-to-front spacing (gap + leader "
            "length); in left/right_neighbour rows the signed front-to-front distance along the "
            "lane (>= 0: the neighbour leads, < 0: it lags)", "m"),
        col("closing_speed", "float64", MAY, "rate at which the gap closes (positive = closing)",
            "m/s"),
    ),
)

INTERACTIONS = register(Derivation(
    name="interactions",
    spec=TABLE,
    version="1.1.0",
    params=InteractionsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y", "heading", "vx", "vy"),
           "participants": ("participant_id", "length", "width")},
    optional=("derived/kinematics",),
    after=("kinematics",),
    doc="lane leaders/followers and neighbours with gap, THW, DHW, closing speed and 1D TTC "
        "(constant velocity and constant acceleration); 2D TTC of oriented boxes for conflicting "
        "pairs",
    method=lambda p: "lane_1d+box_2d" if p.box_2d else "lane_1d",
))
