"""World -> road coordinates for many points at once.

1. **Index.** Every geometry of every road is cut into chunks of at most ``chunk_length`` metres.
   A chunk's polygon is the convex hull of its reference line offset to the road's outermost
   borders (plus a margin); the polygons go into a :class:`shapely.STRtree` (for geometric
   queries, :meth:`SpatialIndex.query_geometry`). Bulk point queries use a numpy uniform grid over
   the same chunk boxes (:meth:`SpatialIndex.query`): all (point, chunk) candidate pairs at once,
   without creating a shapely point per input.
2. **Exact foot point.** Per candidate, the foot point on the chunk's geometry: closed form for
   lines and arcs, vectorised Newton iterations on the exact geometry for spirals (in s) and
   poly3/paramPoly3 (in the polynomial parameter p). Work is grouped by geometry type, never per
   point.
3. **Lane.** The lane borders at the foot point's s give the lane containing t and the offset from
   its centre. Candidates outside their geometry's s range or outside the road surface are dropped;
   the same road found through two neighbouring chunks is merged.
4. **Choice.** All remaining candidates are kept (junctions overlap: a point can lie on several
   roads); the primary one prefers lanes whose driving direction agrees with the heading (when
   given), non-junction roads, drivable lanes and points nearer the lane centre.
   :func:`project_track` instead chooses by continuity along a trajectory.

Folds: where a point lies beyond the curvature centre of its road (``1 - t * kappa <= 0``, a lane
farther out than the curve radius) the orthogonal projection is not unique; such candidates are
returned with ``fold=True`` rather than silently resolved.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

from aveas_format.numeric import wrap_angle

from .geometry import ARC, LINE, POLY3, PPOLY3, SPIRAL

if TYPE_CHECKING:  # pragma: no cover
    from .core import NetworkCore

_S_TOL = 1e-7  # metres a foot point may lie outside its geometry's s range
#: second pass for points that found no road: foot points up to this far beyond a geometry's
#: end are clamped to it (points in the mm/cm gaps or on the outside of heading kinks between
#: consecutive geometries, which real maps have)
GAP_TOL = 0.05


@dataclass
class Projection:
    """Road coordinates of N points (arrays of length N) plus the flat table of all candidates.

    ``road_id`` is None, ``lane_id`` 0 and the floats NaN where a point is on no road.
    ``n_candidates`` counts the roads (or distinct foot points on one road) the point lies on;
    ``candidates(i)`` lists them, the primary one first.
    """

    road_id: np.ndarray
    lane_id: np.ndarray
    s: np.ndarray
    t: np.ndarray
    lane_offset: np.ndarray
    rel_heading: np.ndarray
    road_heading: np.ndarray
    n_candidates: np.ndarray
    fold: np.ndarray
    #: flat candidate table: ``point`` (index into the N points) and the same columns as above,
    #: sorted by point with each point's primary candidate first.
    table: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.s)

    @property
    def on_road(self) -> np.ndarray:
        return self.n_candidates > 0

    def candidates(self, i: int) -> list[dict[str, Any]]:
        """The candidates of point ``i`` as dicts (primary first)."""
        pt = self.table["point"]
        lo, hi = np.searchsorted(pt, i, side="left"), np.searchsorted(pt, i, side="right")
        keys = [k for k in self.table if k != "point"]
        return [{k: _py(self.table[k][j]) for k in keys} for j in range(lo, hi)]


def _py(v: Any) -> Any:
    return v.item() if isinstance(v, np.generic) else v


# ----------------------------------------------------------------------------------------------
class SpatialIndex:
    """Chunks of all roads in an STRtree (see the module doc)."""

    def __init__(self, net: NetworkCore, chunk_length: float = 10.0, margin: float = 0.25, cell: float = 8.0) -> None:
        pv = net.plan
        lanes = net.lanes
        L = pv.length
        nchunk = np.maximum(1, np.ceil(L / chunk_length)).astype(np.int64)
        nchunk[L <= 0] = 0
        g = np.repeat(np.arange(len(L)), nchunk)
        k = np.arange(len(g)) - np.repeat(np.cumsum(nchunk) - nchunk, nchunk)
        step = L[g] / nchunk[g]
        a = k * step
        b = np.where(k == nchunk[g] - 1, L[g], (k + 1) * step)
        self.g, self.a, self.b = g, a, b
        self.road = pv.road[g]
        # samples along each chunk (slightly beyond its ends so that neighbours overlap)
        m = 7
        ext = np.minimum(0.05, 0.25 * (b - a))
        u = np.linspace(0.0, 1.0, m)
        ds = (a - ext)[:, None] + ((b - a) + 2 * ext)[:, None] * u[None, :]
        gg = np.repeat(g, m)
        dsf = ds.ravel()
        x, y, h, _, _ = pv.evaluate(gg, dsf)
        s_abs = pv.s0[gg] + dsf
        rr = pv.road[gg]
        piece = lanes.find_piece(rr, np.clip(s_abs, 0, net.road_length[rr]))
        bd = lanes.borders(piece, s_abs)
        tl, tr = lanes.extent(bd)
        tl = tl.reshape(-1, m).max(1)
        tr = tr.reshape(-1, m).min(1)
        # piece starts inside a chunk: the borders on both sides of the discontinuity
        ps = lanes.piece_start
        proad = lanes.piece_road
        pg = pv.find(proad, ps)
        cidx = self._chunk_of(pg, ps - pv.s0[pg], nchunk, L)
        for pc in (np.arange(len(ps)), np.maximum(np.arange(len(ps)) - 1, 0)):
            same = lanes.piece_road[pc] == proad
            bd2 = lanes.borders(pc, ps)
            tl2, tr2 = lanes.extent(bd2)
            ok = same & (cidx >= 0)
            np.maximum.at(tl, cidx[ok], tl2[ok])
            np.minimum.at(tr, cidx[ok], tr2[ok])
        self.tl, self.tr = tl, tr
        tl_r = np.repeat(tl + margin, m)
        tr_r = np.repeat(tr - margin, m)
        nx, ny = -np.sin(h), np.cos(h)
        px = np.concatenate([(x + tl_r * nx).reshape(-1, m), (x + tr_r * nx).reshape(-1, m)], axis=1)
        py = np.concatenate([(y + tl_r * ny).reshape(-1, m), (y + tr_r * ny).reshape(-1, m)], axis=1)
        coords = np.stack([px, py], axis=-1)  # (C, 2m, 2)
        mp = shapely.multipoints(coords)
        hulls = shapely.convex_hull(mp)
        # degenerate hulls (zero-width roads) become lines: give them an area
        thin = shapely.area(hulls) <= 0
        if thin.any():
            hulls[thin] = shapely.buffer(hulls[thin], margin)
        self.polygons = hulls
        self.tree = shapely.STRtree(self.polygons)
        self._build_grid(shapely.bounds(hulls), cell)
        # chord of each chunk for the Newton start
        xa, ya, _, _, _ = pv.evaluate(g, a)
        xb, yb, _, _, _ = pv.evaluate(g, b)
        self.xa, self.ya, self.xb, self.yb = xa, ya, xb, yb
        poly = (pv.kind[g] == POLY3) | (pv.kind[g] == PPOLY3)
        self.pa = np.zeros(len(g))
        self.pb = np.zeros(len(g))
        if poly.any():
            self.pa[poly] = pv.p_of_ds(g[poly], a[poly])
            self.pb[poly] = pv.p_of_ds(g[poly], b[poly])
        self._first_chunk = np.cumsum(nchunk) - nchunk
        self._nchunk = nchunk

    @staticmethod
    def _chunk_of(gi: np.ndarray, ds: np.ndarray, nchunk: np.ndarray, length: np.ndarray) -> np.ndarray:
        """Chunk index of local offset ``ds`` on geometry ``gi`` (-1 for empty geometries)."""
        first = np.cumsum(nchunk) - nchunk
        n = nchunk[gi]
        step = np.where(n > 0, length[gi] / np.maximum(n, 1), 1.0)
        k = np.clip(np.floor(ds / np.where(step > 0, step, 1.0)), 0, np.maximum(n - 1, 0)).astype(np.int64)
        return np.where(n > 0, first[gi] + k, -1)

    def _build_grid(self, bb: np.ndarray, cell: float) -> None:
        """A uniform grid over the chunk bounding boxes: cell -> chunks (CSR arrays)."""
        self.bb = bb
        self.x0, self.y0 = float(bb[:, 0].min()), float(bb[:, 1].min())
        self.cell = cell
        i0 = np.floor((bb[:, 0] - self.x0) / cell).astype(np.int64)
        j0 = np.floor((bb[:, 1] - self.y0) / cell).astype(np.int64)
        i1 = np.floor((bb[:, 2] - self.x0) / cell).astype(np.int64)
        j1 = np.floor((bb[:, 3] - self.y0) / cell).astype(np.int64)
        self.nx, self.ny = int(i1.max()) + 1, int(j1.max()) + 1
        ni, nj = i1 - i0 + 1, j1 - j0 + 1
        cnt = ni * nj
        chunk = np.repeat(np.arange(len(bb)), cnt)
        k = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ci = i0[chunk] + k % ni[chunk]
        cj = j0[chunk] + k // ni[chunk]
        key = cj * self.nx + ci
        order = np.argsort(key, kind="stable")
        self.grid_items = chunk[order].astype(np.int32)
        self.grid_start = np.searchsorted(key[order], np.arange(self.nx * self.ny + 1)).astype(np.int64)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        b = shapely.total_bounds(self.polygons)
        return tuple(float(v) for v in b)

    def query(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All (point, chunk) pairs whose chunk bounding box contains the point.

        Equivalent to ``self.tree.query(shapely.points(x, y))`` but done on a numpy grid: creating
        GEOS points alone costs more than the whole grid lookup.
        """
        ci = np.floor((x - self.x0) / self.cell)
        cj = np.floor((y - self.y0) / self.cell)
        inside = (ci >= 0) & (ci < self.nx) & (cj >= 0) & (cj < self.ny)
        cell = np.where(inside, cj * self.nx + ci, 0).astype(np.int64)
        start = self.grid_start[cell]
        cnt = np.where(inside, self.grid_start[cell + 1] - start, 0)
        pt = np.repeat(np.arange(len(x)), cnt)
        off = np.arange(len(pt)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        ch = self.grid_items[np.repeat(start, cnt) + off].astype(np.int64)
        bb = self.bb[ch]
        px, py = x[pt], y[pt]
        ok = (px >= bb[:, 0]) & (px <= bb[:, 2]) & (py >= bb[:, 1]) & (py <= bb[:, 3])
        return pt[ok], ch[ok]

    def query_geometry(self, geoms, predicate: str | None = "intersects") -> tuple[np.ndarray, np.ndarray]:
        """Chunks whose polygon relates to shapely ``geoms`` by ``predicate`` (STRtree)."""
        res = self.tree.query(geoms, predicate=predicate)
        if res.ndim == 1:  # a single geometry
            return np.zeros(len(res), dtype=np.int64), res
        return res[0], res[1]


# ----------------------------------------------------------------------------------------------
def _solve_chunks(net: NetworkCore, idx: SpatialIndex, px: np.ndarray, py: np.ndarray, chunk: np.ndarray):
    """Foot point (local ds on the chunk's geometry) for each (point, chunk) pair.

    Returns ``(ds, rows, ds_extra)``: ``rows`` index pairs that have a second foot point
    ``ds_extra`` (the far side of an arc whose lanes reach beyond its centre).
    """
    pv = net.plan
    g = idx.g[chunk]
    kind = pv.kind[g]
    ds = np.full(len(g), np.nan)
    extra: list[tuple[np.ndarray, np.ndarray]] = []
    for code in np.unique(kind):
        sel = np.flatnonzero(kind == code)
        gi, qx, qy, ci = g[sel], px[sel], py[sel], chunk[sel]
        if code == LINE:
            h0 = pv.h0[gi]
            ds[sel] = (qx - pv.x0[gi]) * np.cos(h0) + (qy - pv.y0[gi]) * np.sin(h0)
        elif code == ARC:
            k = pv.k0[gi]
            big = np.abs(k) > 1e-6
            out = np.empty(len(sel))
            if big.any():
                kb = k[big]
                gb = gi[big]
                R = 1.0 / kb
                h0 = pv.h0[gb]
                cx = pv.x0[gb] - R * np.sin(h0)
                cy = pv.y0[gb] + R * np.cos(h0)
                ang = np.arctan2(qy[big] - cy, qx[big] - cx)
                hc = ang + np.sign(kb) * (np.pi / 2)
                mid = 0.5 * (idx.a[ci[big]] + idx.b[ci[big]])
                hmid = h0 + kb * mid
                hh = hmid + wrap_angle(hc - hmid)
                out[big] = (hh - h0) / kb
                # folds: where the road reaches beyond the centre of curvature, the foot point on
                # the far side of the circle is a solution too (t beyond the radius)
                cb = ci[big]
                inner = np.where(kb > 0, idx.tl[cb] * kb, idx.tr[cb] * kb)
                far = np.flatnonzero(inner >= 1.0)
                if len(far):
                    hf = hmid[far] + wrap_angle(hc[far] + np.pi - hmid[far])
                    extra.append((sel[np.flatnonzero(big)[far]], (hf - h0[far]) / kb[far]))
            if (~big).any():
                nb = ~big
                out[nb] = _newton_ds(pv, gi[nb], qx[nb], qy[nb], _chord_start(idx, ci[nb], qx[nb], qy[nb]))
            ds[sel] = out
        elif code == SPIRAL:
            ds[sel] = _newton_ds(pv, gi, qx, qy, _chord_start(idx, ci, qx, qy))
        else:
            ds[sel] = _newton_p(pv, idx, gi, ci, qx, qy)
    if extra:
        rows = np.concatenate([e[0] for e in extra])
        return ds, rows, np.concatenate([e[1] for e in extra])
    return ds, np.zeros(0, dtype=np.int64), np.zeros(0)


def _chord_start(idx: SpatialIndex, c: np.ndarray, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    dx, dy = idx.xb[c] - idx.xa[c], idx.yb[c] - idx.ya[c]
    d2 = np.maximum(dx * dx + dy * dy, 1e-300)
    u = np.clip(((qx - idx.xa[c]) * dx + (qy - idx.ya[c]) * dy) / d2, 0.0, 1.0)
    return idx.a[c] + u * (idx.b[c] - idx.a[c])


def _newton_ds(pv, g, qx, qy, ds, iters: int = 12):
    """Newton on (P - r(s)) . T(s) = 0 in the local offset ds."""
    L = pv.length[g]
    lo, hi = -0.5 * L - 1.0, 1.5 * L + 1.0
    active = np.arange(len(g))
    for _ in range(iters):
        if len(active) == 0:
            break
        ga, da = g[active], ds[active]
        x, y, h, kap, speed = pv.evaluate(ga, da)
        ex, ey = qx[active] - x, qy[active] - y
        ch, sh = np.cos(h), np.sin(h)
        f = ex * ch + ey * sh
        t = -ex * sh + ey * ch
        den = speed - t * kap
        den = np.where(den > 0.05 * speed, den, speed)  # folds: fall back to a gradient step
        step = f / den
        ds[active] = np.clip(da + step, lo[active], hi[active])
        active = active[np.abs(step) > 1e-11]
    return ds


def _newton_p(pv, idx, g, c, qx, qy, iters: int = 12):
    """Newton on (P - r(p)) . r'(p) = 0 in the polynomial parameter p; returns ds."""
    pa, pb = idx.pa[c], idx.pb[c]
    # start: chord projection mapped linearly to p
    ds0 = _chord_start(idx, c, qx, qy)
    a, b = idx.a[c], idx.b[c]
    w = np.where(b > a, (ds0 - a) / np.where(b > a, b - a, 1.0), 0.0)
    p = pa + w * (pb - pa)
    span = np.abs(pb - pa) + 1e-9
    plo, phi = np.minimum(pa, pb) - 2 * span, np.maximum(pa, pb) + 2 * span
    cf = pv.pc[g]
    h0 = pv.h0[g]
    ch, sh = np.cos(h0), np.sin(h0)
    # the point in the geometry's local (u, v) frame
    lx, ly = qx - pv.x0[g], qy - pv.y0[g]
    U = lx * ch + ly * sh
    V = -lx * sh + ly * ch
    active = np.arange(len(g))
    for _ in range(iters):
        if len(active) == 0:
            break
        q = p[active]
        cc = cf[active]
        u = cc[:, 0] + q * (cc[:, 1] + q * (cc[:, 2] + q * cc[:, 3]))
        v = cc[:, 4] + q * (cc[:, 5] + q * (cc[:, 6] + q * cc[:, 7]))
        du = cc[:, 1] + q * (2 * cc[:, 2] + 3 * q * cc[:, 3])
        dv = cc[:, 5] + q * (2 * cc[:, 6] + 3 * q * cc[:, 7])
        ddu = 2 * cc[:, 2] + 6 * q * cc[:, 3]
        ddv = 2 * cc[:, 6] + 6 * q * cc[:, 7]
        eu, ev = U[active] - u, V[active] - v
        f = eu * du + ev * dv
        sp2 = du * du + dv * dv
        fp = -sp2 + eu * ddu + ev * ddv
        fp = np.where(fp < -0.05 * sp2, fp, -sp2)
        step = -f / fp
        p[active] = np.clip(q + step, plo[active], phi[active])
        active = active[np.abs(step) > 1e-12 * np.maximum(1.0, span[active])]
    return pv.ds_of_p(g, p)


# ----------------------------------------------------------------------------------------------
def _project_batch(net: NetworkCore, x, y, heading, drivable_only: bool, s_tol: float = _S_TOL):
    idx = net.spatial_index
    pv = net.plan
    lanes = net.lanes
    pt, ch = idx.query(x, y)
    qx, qy = x[pt], y[pt]
    ds, rows, ds2 = _solve_chunks(net, idx, qx, qy, ch)
    if len(rows):
        pt, ch, qx, qy = (np.concatenate([a, a[rows]]) for a in (pt, ch, qx, qy))
        ds = np.concatenate([ds, ds2])
    g = idx.g[ch]
    L = pv.length[g]
    # keep a foot point only on the chunk that holds it (its neighbours see the same point)
    ok = (ds >= idx.a[ch] - s_tol) & (ds <= idx.b[ch] + s_tol)
    ok &= (ds >= -s_tol) & (ds <= L + s_tol)
    road = pv.road[g]
    s = pv.s0[g] + np.clip(ds, 0.0, L)
    ok &= (s >= -_S_TOL) & (s <= net.road_length[road] + _S_TOL)
    sel = np.flatnonzero(ok)
    pt, g, ds, road, s, qx, qy, ch = pt[sel], g[sel], ds[sel], road[sel], s[sel], qx[sel], qy[sel], ch[sel]
    ds = np.clip(ds, 0.0, pv.length[g])
    rx, ry, rh, kap, speed = pv.evaluate(g, ds)
    ex, ey = qx - rx, qy - ry
    t = -ex * np.sin(rh) + ey * np.cos(rh)
    # cheap rejection by the chunk's lateral extent before evaluating lane borders
    sel = np.flatnonzero((t <= idx.tl[ch] + 0.1) & (t >= idx.tr[ch] - 0.1))
    pt, road, s, t, rh, kap, speed = pt[sel], road[sel], s[sel], t[sel], rh[sel], kap[sel], speed[sel]
    s = np.clip(s, 0.0, net.road_length[road])
    piece = lanes.find_piece(road, s)
    bd = lanes.borders(piece, s)
    lane_id, lane_off, inner, outer, ltype = lanes.locate(bd, t)
    keep = lane_id != 0
    if drivable_only:
        keep &= net.drivable_code[np.maximum(ltype, 0)] & (ltype >= 0)
    sel = np.flatnonzero(keep)
    pt, road, s, t, rh, kap, speed = pt[sel], road[sel], s[sel], t[sel], rh[sel], kap[sel], speed[sel]
    lane_id, lane_off, ltype = lane_id[sel], lane_off[sel], ltype[sel]
    width = np.abs(outer[sel] - inner[sel])
    fold = (speed - t * kap) <= 0
    # merge duplicates: same point, same road, same s (a foot point on a chunk boundary)
    nroad = len(net.road_list)
    order = np.argsort(pt * nroad + road, kind="stable")
    pt, road, s, t, rh, lane_id, lane_off, ltype, width, fold = (
        a[order] for a in (pt, road, s, t, rh, lane_id, lane_off, ltype, width, fold)
    )
    if len(pt) > 1:
        dup = np.zeros(len(pt), dtype=bool)
        dup[1:] = (pt[1:] == pt[:-1]) & (road[1:] == road[:-1]) & (np.abs(s[1:] - s[:-1]) < 1e-6)
        if dup.any():
            sel = np.flatnonzero(~dup)
            pt, road, s, t, rh, lane_id, lane_off, ltype, width, fold = (
                a[sel] for a in (pt, road, s, t, rh, lane_id, lane_off, ltype, width, fold)
            )
    # rank candidates
    if heading is not None:
        hq = heading[pt]
        rel = wrap_angle(hq - rh)
        rht = net.road_rht[road]
        with_flow = np.where((lane_id < 0) == rht, rel, wrap_angle(rel - np.pi))
        cost = np.abs(with_flow)
    else:
        rel = np.full(len(pt), np.nan)
        cost = np.zeros(len(pt))
    cost = cost + 0.5 * net.road_in_junction[road]
    cost = cost + 0.25 * ~(net.drivable_code[np.maximum(ltype, 0)] & (ltype >= 0))
    cost = cost + 0.1 * np.abs(lane_off) / np.maximum(width, 0.01) + 2.0 * fold
    order = np.argsort(pt * 16.0 + np.minimum(cost, 15.0), kind="stable")
    cols = dict(
        point=pt,
        road=road,
        lane_id=lane_id,
        s=s,
        t=t,
        lane_offset=lane_off,
        rel_heading=rel,
        road_heading=rh,
        fold=fold,
        cost=cost,
    )
    res = {k: v[order] for k, v in cols.items()}
    if s_tol < GAP_TOL:
        hit = np.zeros(len(x), dtype=bool)
        hit[res["point"]] = True
        miss = np.flatnonzero(~hit)
        if len(miss):
            more = _project_batch(
                net, x[miss], y[miss], None if heading is None else heading[miss], drivable_only, GAP_TOL
            )
            if len(more["point"]):
                more["point"] = miss[more["point"]]
                res = {k: np.concatenate([res[k], more[k]]) for k in res}
                order = np.argsort(res["point"], kind="stable")
                res = {k: v[order] for k, v in res.items()}
    return res


def project(
    net: NetworkCore, x, y, heading=None, *, drivable_only: bool = False, batch: int = 65536, threads: int | None = None
) -> Projection:
    """Vectorised world -> road for the points ``(x, y)`` (see the module doc)."""
    x = np.ascontiguousarray(x, dtype=np.float64).ravel()
    y = np.ascontiguousarray(y, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError("x and y must have the same length")
    hd = None if heading is None else np.broadcast_to(np.asarray(heading, dtype=np.float64), x.shape).ravel()
    n = len(x)
    _ = net.spatial_index  # build once, outside the threads
    starts = list(range(0, n, batch)) or [0]

    def run(i0: int):
        sl = slice(i0, min(n, i0 + batch))
        res = _project_batch(net, x[sl], y[sl], None if hd is None else hd[sl], drivable_only)
        res["point"] = res["point"] + i0
        return res

    nthreads = threads if threads is not None else min(len(starts), max(1, min(4, os.cpu_count() or 1)))
    if nthreads > 1 and len(starts) > 1:
        with ThreadPoolExecutor(nthreads) as ex:
            parts = list(ex.map(run, starts))
    else:
        parts = [run(i0) for i0 in starts]
    table = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    return _assemble(net, n, table)


def _assemble(net: NetworkCore, n: int, table: dict[str, np.ndarray]) -> Projection:
    pt = table["point"]
    counts = np.bincount(pt, minlength=n) if len(pt) else np.zeros(n, dtype=np.int64)
    first = np.ones(len(pt), dtype=bool)
    if len(pt) > 1:
        first[1:] = pt[1:] != pt[:-1]
    fi = np.flatnonzero(first)
    prim = pt[fi]
    road_idx = np.full(n, -1, dtype=np.int64)
    road_idx[prim] = table["road"][fi]

    def col(name, fill, dtype):
        out = np.full(n, fill, dtype=dtype)
        out[prim] = table[name][fi]
        return out

    ids = net.road_id_array
    out_table = {
        "point": pt,
        "road_id": ids[table["road"]] if len(pt) else np.zeros(0, dtype=object),
        "lane_id": table["lane_id"].astype(np.int16),
        "s": table["s"],
        "t": table["t"],
        "lane_offset": table["lane_offset"],
        "rel_heading": table["rel_heading"],
        "road_heading": table["road_heading"],
        "fold": table["fold"],
    }
    return Projection(
        road_id=ids[road_idx],
        lane_id=col("lane_id", 0, np.int16),
        s=col("s", np.nan, np.float64),
        t=col("t", np.nan, np.float64),
        lane_offset=col("lane_offset", np.nan, np.float64),
        rel_heading=col("rel_heading", np.nan, np.float64),
        road_heading=col("road_heading", np.nan, np.float64),
        n_candidates=counts.astype(np.int64),
        fold=col("fold", False, bool),
        table=out_table,
    )


# ----------------------------------------------------------------------------------------------
def project_track(net: NetworkCore, x, y, heading=None, time=None, track_id=None, **kw) -> Projection:
    """World -> road along trajectories, choosing among candidates by continuity.

    Points are ordered by ``(track_id, time)`` (input order where not given). For a point on
    several roads the chosen candidate is scored by: being on the road of the nearest earlier
    (and later) unambiguous sample of the same track, being a road linked to those roads
    (predecessor/successor or junction connection), and agreement of ``heading`` with the lane's
    driving direction. All candidates stay in ``Projection.table`` (the chosen one first).
    """
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    n = len(x)
    tm = np.arange(n, dtype=np.float64) if time is None else np.asarray(time, dtype=np.float64).ravel()
    tid = (
        np.zeros(n, dtype=np.int64)
        if track_id is None
        else np.unique(np.asarray(track_id).ravel(), return_inverse=True)[1]
    )
    order = np.lexsort((np.arange(n), tm, tid))
    hd = None if heading is None else np.broadcast_to(np.asarray(heading, dtype=np.float64), x.shape).ravel()[order]
    proj = project(net, x[order], y[order], hd, **kw)
    tab = proj.table
    pt = tab["point"]
    if len(pt):
        road = net.road_index_of(tab["road_id"])
        ncand = proj.n_candidates
        # road of the primary candidate where unambiguous, -1 elsewhere
        fixed = np.full(n, -1, dtype=np.int64)
        prim_rows = np.searchsorted(pt, np.arange(n))
        unamb = ncand == 1
        fixed[unamb] = road[prim_rows[unamb]]
        tidx = tid[order]
        prev = _fill(fixed, tidx, forward=True)
        nxt = _fill(fixed, tidx, forward=False)
        p_prev, p_next = prev[pt], nxt[pt]
        score = 2.0 * (road == p_prev) + 2.0 * (road == p_next)
        score += 1.0 * net.linked(road, p_prev) + 1.0 * net.linked(road, p_next)
        if hd is not None:
            rel = tab["rel_heading"]
            rht = net.road_rht[road]
            with_flow = np.where((tab["lane_id"] < 0) == rht, rel, wrap_angle(rel - np.pi))
            score -= np.abs(with_flow) / np.pi
        rank = np.lexsort((-score, pt))
        tab = {k: v[rank] for k, v in tab.items()}
        # rebuild primary columns
        proj = _rebuild(proj, tab, n)
    # back to input order
    inv = np.empty(n, dtype=np.int64)
    inv[order] = np.arange(n)
    return _reorder(proj, order, inv)


def _fill(fixed: np.ndarray, tid: np.ndarray, forward: bool) -> np.ndarray:
    """Forward (or backward) fill of ``fixed`` (-1 = missing) within each track."""
    n = len(fixed)
    if n == 0:
        return fixed
    idx = np.arange(n)
    if forward:
        pos = np.where(fixed >= 0, idx, -1)
        pos = np.maximum.accumulate(pos)
        start = np.r_[0, np.flatnonzero(np.diff(tid)) + 1]
        track_start = np.repeat(start, np.diff(np.r_[start, n]))
        good = pos >= track_start
        return np.where(good, fixed[np.maximum(pos, 0)], -1)
    rev = _fill(fixed[::-1], tid[::-1], True)
    return rev[::-1]


def _rebuild(proj: Projection, tab: dict[str, np.ndarray], n: int) -> Projection:
    pt = tab["point"]
    first = np.ones(len(pt), dtype=bool)
    first[1:] = pt[1:] != pt[:-1]
    fi = np.flatnonzero(first)
    prim = pt[fi]
    out = Projection(
        road_id=proj.road_id.copy(),
        lane_id=proj.lane_id.copy(),
        s=proj.s.copy(),
        t=proj.t.copy(),
        lane_offset=proj.lane_offset.copy(),
        rel_heading=proj.rel_heading.copy(),
        road_heading=proj.road_heading.copy(),
        n_candidates=proj.n_candidates,
        fold=proj.fold.copy(),
        table=tab,
    )
    for name in ("road_id", "lane_id", "s", "t", "lane_offset", "rel_heading", "road_heading", "fold"):
        getattr(out, name)[prim] = tab[name][fi]
    return out


def _reorder(proj: Projection, order: np.ndarray, inv: np.ndarray) -> Projection:
    """Map a projection computed on points[order] back to the input order."""
    tab = dict(proj.table)
    tab["point"] = order[tab["point"]]
    srt = np.argsort(tab["point"], kind="stable")
    tab = {k: v[srt] for k, v in tab.items()}
    return Projection(
        road_id=proj.road_id[inv],
        lane_id=proj.lane_id[inv],
        s=proj.s[inv],
        t=proj.t[inv],
        lane_offset=proj.lane_offset[inv],
        rel_heading=proj.rel_heading[inv],
        road_heading=proj.road_heading[inv],
        n_candidates=proj.n_candidates[inv],
        fold=proj.fold[inv],
        table=tab,
    )


__all__ = ["Projection", "SpatialIndex", "project", "project_track"]
