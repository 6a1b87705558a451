"""Fit an OpenDRIVE road to annotated polylines (lane centres or lane borders / markings).

For maps annotated on an orthophoto, and for converters whose sources give lanes as polylines
(accident reconstructions, highD's lane markings)::

    from aveas_format.opendrive.fit import fit_road, road_from_lane_markings

    fit = road_from_lane_markings([m0, m1, m2, m3], driving="right")   # (N, 2) arrays, left to right
    fit.xodr                      # OpenDRIVE 1.6 text (XSD-valid)
    fit.network()                 # the RoadNetwork (load_map of the text)
    fit.rms, fit.max_error        # reference line vs. the polyline it was fitted to [m]

    fit = fit_road([c0, c1, c2], kind="centres", driving="both", left_lanes=1)

**Reference line: a G2 clothoid spline.** The reference line is fitted to the *centre-most*
input line (the middle one across the road; ``reference=`` picks another). Its curvature is a
continuous piecewise-linear function of s, i.e. a chain of OpenDRIVE ``<spiral>`` records; heading
and curvature are continuous everywhere (G2), unlike paramPoly3 pieces, which would need explicit
tangent constraints and are only G1. Knots start every ``knot_spacing`` m; the start point, start
heading and knot curvatures are found by Levenberg-Marquardt on the orthogonal distances of the
polyline's points to the curve (analytic Jacobian, foot points re-found at every step), with a
small penalty on the curvature's kinks (which also makes sparse annotations, a few vertices per
curve, well posed). Knot intervals the curve cannot follow (RMS distance above ``tolerance`` and
twice the input's noise) are halved. Then the curvature profile is simplified
(Ramer-Douglas-Peucker on (s, curvature)), pieces near zero curvature become ``line`` records and
near-constant ones ``arc`` records, and this simpler model is refitted with its transition points
free; it is kept when its error grows no more than the removed parameters explain with the noise.
So a road built from lines, arcs and clothoids comes back as lines, arcs and clothoids. The result
is trimmed to the foot points of the reference polyline's first and last points and chained
exactly (each record starts at the evaluated end of the previous one).

**Lanes.** Every input point is projected onto the fitted reference line with the engine's exact
world -> road projection, giving t(s) per input line. Each line's t(s) is fitted by a penalised
least-squares cubic B-spline (knots every ``width_spacing`` m); lane borders are these splines
(``kind="borders"``) or, for lane centres, the midpoints between neighbouring centres (the
outermost borders half the neighbouring lane spacing further out; ``lane_width`` for a single
centre line). As all splines share their knots, the lane widths (differences of borders) and the
lane offset (t of the border between the directions, zero when the reference line is that
border) are exact piecewise cubics: one ``<width>`` record per lane and knot interval, one
``<laneOffset>`` record per interval, in a single lane section.

Input errors (fewer than 2 points, non-finite values, points out of order, a self-intersecting
line, lines that cross or do not run alongside the reference line, lines farther from the
reference line than its curve radius) raise :class:`~aveas_format.errors.MapError` (a
ValueError) naming the line (``lines[i]``/``markings[i]``) and where.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MapError
from .model import Geometry, Header, Lane, LaneSection, Poly3Record, Road, RoadMark, RoadType

__all__ = ["ReferenceFit", "RoadFit", "fit_reference_line", "fit_road", "road_from_lane_markings"]


# ----------------------------------------------------------------------------------------------
# input checks
def _as_line(obj: Any, label: str) -> np.ndarray:
    """An (N, 2) float array of distinct consecutive points, checked (see the module doc)."""
    try:
        a = np.asarray(obj, dtype=np.float64)
    except (TypeError, ValueError):
        raise MapError(f"{label}: expected an (N, 2) array of x, y numbers") from None
    if a.ndim != 2 or a.shape[1] not in (2, 3):
        raise MapError(f"{label}: expected an (N, 2) array of x, y; got shape {a.shape}")
    a = a[:, :2]
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MapError(f"{label}: point {i} ({a[i, 0]}, {a[i, 1]}) is not finite")
    orig = np.arange(len(a))
    if len(a) > 1:
        keep = np.r_[True, np.hypot(*np.diff(a, axis=0).T) > 1e-9]
        a, orig = a[keep], orig[keep]
    if len(a) < 2:
        raise MapError(f"{label}: has {len(a)} distinct point(s); a line needs at least 2")
    seg = np.diff(a, axis=0)
    ln = np.hypot(seg[:, 0], seg[:, 1])
    if len(a) > 2:
        cos = (seg[:-1] * seg[1:]).sum(1) / (ln[:-1] * ln[1:])
        back = np.flatnonzero(cos < -0.5)
        if len(back):
            i = int(back[0]) + 1
            ang = float(np.degrees(np.arccos(np.clip(cos[back[0]], -1, 1))))
            raise MapError(
                f"{label}: the points are not ordered along the line: the direction turns by "
                f"{ang:.0f} deg at point {int(orig[i])} ({a[i, 0]:.3f}, {a[i, 1]:.3f})"
            )
    if len(a) > 3:
        _check_simple(a, label)
    return a


def _check_simple(a: np.ndarray, label: str) -> None:
    import shapely

    if shapely.LineString(a).is_simple:
        return
    segs = shapely.linestrings(np.stack([a[:-1], a[1:]], axis=1))
    tree = shapely.STRtree(segs)
    i, j = tree.query(segs, predicate="intersects")
    far = np.abs(i - j) > 1
    if far.any():
        k = int(np.flatnonzero(far)[0])
        p = shapely.intersection(segs[i[k]], segs[j[k]])
        x, y = shapely.get_coordinates(p)[0]
        a0, a1 = sorted((int(i[k]), int(j[k])))
        raise MapError(
            f"{label}: intersects itself near ({x:.3f}, {y:.3f}) (segments {a0} and {a1})"
        )
    raise MapError(f"{label}: intersects itself")


# ----------------------------------------------------------------------------------------------
# the clothoid spline: curvature piecewise linear in s, heading and position by integration
class _Spline:
    """Curvature linear between knots ``s_0 = 0 < s_1 < ... < s_K = L``; heading and position by
    integration from a free start point and heading.

    Positions are integrated with Simpson's rule on a grid of at most ``step`` m (exact to ~1e-9 m
    for road curvatures: the integrand is cos/sin of a quadratic in s).
    """

    def __init__(self, knots: np.ndarray, step: float) -> None:
        self.knots = np.asarray(knots, dtype=np.float64)
        self.L = float(self.knots[-1])
        self.K = len(self.knots) - 1
        self.D = np.diff(self.knots)
        n_sub = np.maximum(1, np.ceil(self.D / step)).astype(np.int64)
        nodes = [self.knots[:1]]
        for i in range(self.K):
            nodes.append(np.linspace(self.knots[i], self.knots[i + 1], n_sub[i] + 1)[1:])
        self.nodes = np.concatenate(nodes)
        self.nodes[-1] = self.L
        self.mids = 0.5 * (self.nodes[:-1] + self.nodes[1:])
        contrib = np.zeros((self.K, self.K + 1))
        rows = np.arange(self.K)
        contrib[rows, rows] = 0.5 * self.D
        contrib[rows, rows + 1] = 0.5 * self.D
        self.base = np.concatenate([np.zeros((1, self.K + 1)), np.cumsum(contrib, 0)])
        self.Pn = self.phi(self.nodes)
        self.Pm = self.phi(self.mids)

    def piece(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        i = np.clip(np.searchsorted(self.knots, u, side="right") - 1, 0, self.K - 1)
        return i, u - self.knots[i]

    def phi(self, u: np.ndarray) -> np.ndarray:
        """(len(u), K+1): d heading(u) / d knot curvature."""
        i, d = self.piece(np.asarray(u, dtype=np.float64))
        out = self.base[i].copy()
        rows = np.arange(len(i))
        q = d * d / (2 * self.D[i])
        out[rows, i] += d - q
        out[rows, i + 1] += q
        return out

    def kappa(self, u: np.ndarray, k: np.ndarray) -> np.ndarray:
        i, d = self.piece(u)
        return k[i] + (k[i + 1] - k[i]) * d / self.D[i]

    def state(self, anchor: np.ndarray, a: float, th0: float, k: np.ndarray, jac: bool) -> dict:
        """Positions (and their derivatives by the knot curvatures) at the grid nodes."""
        thn = th0 + self.Pn @ k
        thm = th0 + self.Pm @ k
        fn = np.stack([np.cos(thn), np.sin(thn)], 1)
        fm = np.stack([np.cos(thm), np.sin(thm)], 1)
        n0 = np.array([-np.sin(th0), np.cos(th0)])
        r0 = anchor + a * n0
        h = np.diff(self.nodes)[:, None]
        R = r0 + np.concatenate([np.zeros((1, 2)), np.cumsum((h / 6.0) * (fn[:-1] + 4 * fm + fn[1:]), 0)])
        st = {"k": k, "th0": th0, "a": a, "r0": r0, "n0": n0, "fn": fn, "R": R}
        if jac:
            gn = np.stack([-np.sin(thn), np.cos(thn)], 1)[:, None, :] * self.Pn[:, :, None]
            gm = np.stack([-np.sin(thm), np.cos(thm)], 1)[:, None, :] * self.Pm[:, :, None]
            dsteps = (h[:, :, None] / 6.0) * (gn[:-1] + 4 * gm + gn[1:])
            st["gn"] = gn
            st["dR"] = np.concatenate([np.zeros((1,) + gn.shape[1:]), np.cumsum(dsteps, 0)])
        return st

    def at(self, st: dict, s: np.ndarray, jac: bool = False):
        """Position, heading, curvature (and d position / d knot curvatures) at s in [0, L]."""
        m = np.clip(np.searchsorted(self.nodes, s, side="right") - 1, 0, len(self.nodes) - 2)
        d = s - self.nodes[m]
        k, th0 = st["k"], st["th0"]
        Pmid, Ps = self.phi(self.nodes[m] + d / 2), self.phi(s)
        thmid, ths = th0 + Pmid @ k, th0 + Ps @ k
        fmid = np.stack([np.cos(thmid), np.sin(thmid)], 1)
        fs = np.stack([np.cos(ths), np.sin(ths)], 1)
        r = st["R"][m] + (d / 6.0)[:, None] * (st["fn"][m] + 4 * fmid + fs)
        out = [r, ths, self.kappa(s, k)]
        if jac:
            gmid = np.stack([-np.sin(thmid), np.cos(thmid)], 1)[:, None, :] * Pmid[:, :, None]
            gs = np.stack([-np.sin(ths), np.cos(ths)], 1)[:, None, :] * Ps[:, :, None]
            out.append(st["dR"][m] + (d / 6.0)[:, None, None] * (st["gn"][m] + 4 * gmid + gs))
        return out

    def foot(self, st: dict, p: np.ndarray, s: np.ndarray, iters: int = 8) -> np.ndarray:
        """Foot points of p on the curve by Newton from s (clamped to [0, L])."""
        s = np.clip(s, 0.0, self.L)
        for _ in range(iters):
            r, th, kap = self.at(st, s)
            d = p - r
            c, sn = np.cos(th), np.sin(th)
            along = d[:, 0] * c + d[:, 1] * sn
            side = -d[:, 0] * sn + d[:, 1] * c
            den = np.maximum(1.0 - kap * side, 0.1)
            step = along / den
            s = np.clip(s + step, 0.0, self.L)
            if np.max(np.abs(step)) < 1e-10:
                break
        return s


class _Problem:
    """Least squares of the point-to-curve distances with knot ties ``k = A q`` (Levenberg-Marquardt
    on the normal equations; the foot points are re-found at every evaluation)."""

    def __init__(self, sp: _Spline, pts: np.ndarray, anchor: np.ndarray, A: np.ndarray,
                 smoothing: float, ridge: float) -> None:
        self.sp, self.pts, self.anchor, self.A = sp, pts, anchor, A
        K, D = sp.K, sp.D
        # penalty on the curvature's kinks at inner knots, scaled to a lateral displacement
        rows = []
        for j in range(1, K):
            dbar = 0.5 * (D[j - 1] + D[j])
            r = np.zeros(K + 1)
            r[j - 1], r[j], r[j + 1] = 1 / D[j - 1], -(1 / D[j - 1] + 1 / D[j]), 1 / D[j]
            rows.append(r * dbar**3)
        dens = np.sqrt(max(1.0, len(pts) / K))
        D2 = np.array(rows).reshape(-1, K + 1) * (smoothing * dens)
        dk = np.r_[D[0], 0.5 * (D[:-1] + D[1:]), D[-1]]
        self.P = np.concatenate([D2, ridge * np.diag(dk**2)]) @ A

    def unpack(self, x: np.ndarray) -> tuple[float, float, np.ndarray]:
        return float(x[0]), float(x[1]), self.A @ x[2:]

    def evaluate(self, x: np.ndarray, s: np.ndarray, jac: bool = True):
        """Residuals (distances, then penalties), Jacobian and foot points at parameters x."""
        sp = self.sp
        a, th0, k = self.unpack(x)
        st = sp.state(self.anchor, a, th0, k, jac=jac)
        s = sp.foot(st, self.pts, s)
        out = sp.at(st, s, jac=jac)
        r, th = out[0], out[1]
        d = self.pts - r
        nv = np.stack([-np.sin(th), np.cos(th)], 1)
        e = (d * nv).sum(1)
        ends = (s <= 0.0) | (s >= sp.L)
        if ends.any():
            dist = np.hypot(d[ends, 0], d[ends, 1])
            sgn = np.where(e[ends] < 0, -1.0, 1.0)
            nv[ends] = sgn[:, None] * d[ends] / np.maximum(dist, 1e-12)[:, None]
            e[ends] = sgn * dist
        res = np.concatenate([e, self.P @ x[2:]])
        if not jac:
            return res, None, s
        drk = out[3]
        dra = np.broadcast_to(st["n0"], r.shape)
        rel = r - st["r0"]
        drt = np.stack([-rel[:, 1], rel[:, 0]], 1) + a * np.array([-np.cos(th0), -np.sin(th0)])
        drq = np.matmul(drk.transpose(0, 2, 1), self.A)  # (n, 2, Q)
        J = -np.concatenate(
            [(nv * dra).sum(1)[:, None], (nv * drt).sum(1)[:, None], (drq * nv[:, :, None]).sum(1)], 1
        )
        Jf = np.concatenate([J, np.concatenate([np.zeros((len(self.P), 2)), self.P], 1)])
        return res, Jf, s

    def limit(self, x: np.ndarray, step: np.ndarray) -> np.ndarray:
        """A step the parameters can take (the knot positions' one keeps their order)."""
        return step

    def solve(self, x0: np.ndarray, s0: np.ndarray, iters: int = 60):
        """Levenberg-Marquardt from x0: (x, point residuals, foot points)."""
        x = np.asarray(x0, dtype=np.float64).copy()
        r, J, s = self.evaluate(x, s0)
        cost = float(r @ r)
        lam = 1e-4
        for _ in range(iters):
            JTJ, g = J.T @ J, J.T @ r
            dg = np.diag(JTJ).copy()
            dg[dg <= 0] = 1.0
            while True:
                try:
                    step = np.linalg.solve(JTJ + lam * np.diag(dg), -g)
                except np.linalg.LinAlgError:
                    step = None
                if step is not None and np.all(np.isfinite(step)):
                    step = self.limit(x, step)
                    r2, J2, s2 = self.evaluate(x + step, s)
                    c2 = float(r2 @ r2)
                    if c2 <= cost:
                        break
                lam *= 4.0
                if lam > 1e10:
                    return x, r[: len(self.pts)], s
            x = x + step
            done = cost - c2 <= 1e-10 * cost + 1e-20
            r, J, s, cost = r2, J2, s2, c2
            lam = max(lam / 4.0, 1e-12)
            if done:
                break
        return x, r[: len(self.pts)], s


class _KnotProblem(_Problem):
    """The tied problem with the inner knots' positions free as well (no penalties): parameters
    ``(a, th0, q, inner knots)``; the knots' columns of the Jacobian by forward differences."""

    def __init__(self, sp: _Spline, pts: np.ndarray, anchor: np.ndarray, A: np.ndarray, step: float) -> None:
        super().__init__(sp, pts, anchor, A, 0.0, 0.0)
        self.P = np.zeros((0, A.shape[1]))
        self.nq = A.shape[1]
        self.step = step
        self.min_gap = 0.5
        self._cache: dict[bytes, _Spline] = {sp.knots.tobytes(): sp}

    def spline(self, x: np.ndarray) -> _Spline | None:
        knots = np.r_[0.0, x[2 + self.nq:], self.sp.L]
        if np.any(np.diff(knots) < self.min_gap):
            return None
        key = knots.tobytes()
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = _Spline(knots, self.step)
        return self._cache[key]

    def unpack(self, x: np.ndarray) -> tuple[float, float, np.ndarray]:
        return float(x[0]), float(x[1]), self.A @ x[2:2 + self.nq]

    def limit(self, x: np.ndarray, step: np.ndarray) -> np.ndarray:
        i0 = 2 + self.nq
        if len(x) == i0:
            return step
        knots = np.r_[0.0, x[i0:], self.sp.L]
        gap = np.diff(knots)
        room = 0.4 * np.minimum(gap[:-1], gap[1:])
        step = step.copy()
        step[i0:] = np.clip(step[i0:], -room, room)
        return step

    def evaluate(self, x: np.ndarray, s: np.ndarray, jac: bool = True):
        sp = self.spline(x)
        if sp is None:
            return np.full(len(self.pts), np.inf), None, s
        base, self.sp = self.sp, sp
        try:
            res, J, s_new = _Problem.evaluate(self, x[: 2 + self.nq], s, jac)
            if jac:
                cols = []
                for j in range(2 + self.nq, len(x)):
                    h = 1e-3
                    xh = x.copy()
                    xh[j] += h
                    sph = self.spline(xh)
                    if sph is None:
                        xh[j] -= 2 * h
                        h = -h
                        sph = self.spline(xh)
                    self.sp = sph
                    rh = _Problem.evaluate(self, xh[: 2 + self.nq], s_new, False)[0]
                    cols.append((rh - res) / h)
                    self.sp = sp
                if cols:
                    J = np.concatenate([J, np.stack(cols, 1)], 1)
        finally:
            self.sp = base
        return res, J, s_new


@dataclass
class ReferenceFit:
    """A fitted reference line: exact, chained ``geometries`` and the fit's errors [m]."""

    geometries: list[Geometry]
    length: float
    rms: float
    max_error: float
    snapped: bool = False
    #: number of geometries per kind (``line``, ``arc``, ``spiral``)
    kinds: dict[str, int] = field(default_factory=dict)
    #: robust estimate of the input's noise: median RMS residual of parabolas through 7 points [m]
    noise: float = 0.0


def _simplify(knots: np.ndarray, k: np.ndarray, eps: float) -> np.ndarray:
    """Indices of the knots kept by Ramer-Douglas-Peucker on the curvature profile (s, k): every
    dropped knot's curvature is within ``eps`` of the linear interpolation of the kept ones."""
    keep = np.zeros(len(k), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(k) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        u = (knots[i + 1:j] - knots[i]) / (knots[j] - knots[i])
        dev = np.abs(k[i + 1:j] - (k[i] + u * (k[j] - k[i])))
        m = int(np.argmax(dev))
        if dev[m] > eps:
            keep[i + 1 + m] = True
            stack += [(i, i + 1 + m), (i + 1 + m, j)]
    return np.flatnonzero(keep)


def _ties(k: np.ndarray, eps: float) -> tuple[np.ndarray, list[str]]:
    """Tie matrix A (k = A q) of a simplified curvature profile: pieces whose curvatures are
    within ``eps`` of 0 become lines (both knots 0), pieces within ``eps`` of constant arcs (knots
    tied, as long as every tied group's curvatures stay within ``eps`` of each other)."""
    K = len(k) - 1
    Z = K + 1  # the zero group
    parent = list(range(K + 2))
    lo = list(k) + [0.0]
    hi = list(k) + [0.0]

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def union(i: int, j: int) -> bool:
        ri, rj = find(i), find(j)
        if ri == rj:
            return True
        nlo, nhi = min(lo[ri], lo[rj]), max(hi[ri], hi[rj])
        zero = Z in (ri, rj)
        if (max(abs(nlo), abs(nhi)) if zero else nhi - nlo) >= eps:
            return False
        root, other = (Z, ri if rj == Z else rj) if zero else (min(ri, rj), max(ri, rj))
        parent[other] = root
        lo[root], hi[root] = nlo, nhi
        return True

    for i in range(K):  # lines first: they pin curvatures to 0
        if max(abs(k[i]), abs(k[i + 1])) < eps and union(i, Z):
            union(i + 1, Z)
    for i in sorted(range(K), key=lambda i: abs(k[i] - k[i + 1])):
        if abs(k[i] - k[i + 1]) < eps:
            union(i, i + 1)
    roots = sorted({find(i) for i in range(K + 1)} - {Z})
    col = {r: c for c, r in enumerate(roots)}
    A = np.zeros((K + 1, len(roots)))
    for i in range(K + 1):
        r = find(i)
        if r != Z:
            A[i, col[r]] = 1.0
    kinds = []
    for i in range(K):
        ri, rj = find(i), find(i + 1)
        kinds.append("line" if ri == rj == Z else "arc" if ri == rj else "spiral")
    return A, kinds


def _piece_rms(sp: _Spline, s: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    i = sp.piece(s)[0]
    cnt = np.bincount(i, minlength=sp.K)
    ss = np.bincount(i, weights=e * e, minlength=sp.K)
    return np.sqrt(ss / np.maximum(cnt, 1)), cnt


def _initial(pts: np.ndarray, sp: _Spline, margin: float, smoothing: float, ridge: float):
    """Start values from a linear fit of the polyline's segment headings."""
    seg = np.diff(pts, axis=0)
    ln = np.hypot(seg[:, 0], seg[:, 1])
    c = np.r_[0.0, np.cumsum(ln)]
    phi = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    mid = margin + 0.5 * (c[:-1] + c[1:])
    w = ln / ln.mean()
    K = sp.K
    M = np.concatenate([np.ones((len(mid), 1)), sp.phi(np.clip(mid, 0, sp.L))], 1) * w[:, None]
    D2 = np.zeros((max(K - 1, 0), K + 2))
    for j in range(K - 1):
        D2[j, j + 1:j + 4] = (1.0, -2.0, 1.0)
    dbar = float(np.mean(sp.D))
    reg = np.concatenate([smoothing * dbar * D2 * np.sqrt(max(1.0, len(mid) / K)),
                          np.c_[np.zeros((K + 1, 1)), ridge * dbar * np.eye(K + 1)]])
    sol = np.linalg.lstsq(np.concatenate([M, reg]), np.concatenate([phi * w, np.zeros(len(reg))]),
                          rcond=None)[0]
    th0, k = float(sol[0]), sol[1:]
    st = sp.state(np.zeros(2), 0.0, th0, k, jac=False)
    r_m = sp.at(st, np.array([margin]))[0][0]
    anchor = pts[0] - r_m
    return anchor, th0, k, margin + c


def _geometries(sp: _Spline, st: dict, kinds: list[str], sa: float, sb: float) -> list[Geometry]:
    """The spline restricted to [sa, sb] as line/arc/spiral records (starts set by chaining)."""
    from .builder import _chain

    k = st["k"]
    cuts = [sa] + [float(u) for u in sp.knots[1:-1] if sa < u < sb] + [sb]
    pieces = []
    for u0, u1 in zip(cuts[:-1], cuts[1:]):
        i = int(sp.piece(np.array([0.5 * (u0 + u1)]))[0][0])
        k0, k1 = (float(v) for v in sp.kappa(np.array([u0, u1]), k))
        if kinds[i] == "line":
            k0 = k1 = 0.0
        pieces.append([u0, u1, kinds[i], k0, k1])
    # fold pieces shorter than 0.1 m into a neighbour (the neighbour's kind and curvature go on)
    while len(pieces) > 1:
        short = [j for j, p in enumerate(pieces) if p[1] - p[0] < 0.1]
        if not short:
            break
        j = short[0]
        if j + 1 < len(pieces):
            nb = pieces[j + 1]
            nb[0] = pieces[j][0]
            if nb[2] == "spiral":
                nb[3] = pieces[j][3]
        else:
            nb = pieces[j - 1]
            nb[1] = pieces[j][1]
            if nb[2] == "spiral":
                nb[4] = pieces[j][4]
        del pieces[j]
    merged: list[list] = []
    for p in pieces:
        if merged and p[2] == merged[-1][2]:
            q = merged[-1]
            if p[2] in ("line", "arc") and abs(p[3] - q[3]) < 1e-15:
                q[1] = p[1]
                continue
            # consecutive clothoid pieces with one curvature rate: one clothoid (moves < 1e-7 m)
            r0, r1 = (q[4] - q[3]) / (q[1] - q[0]), (p[4] - p[3]) / (p[1] - p[0])
            if p[2] == "spiral" and abs(r1 - r0) * (p[1] - q[0]) ** 3 / 6.0 < 1e-7:
                q[1], q[4] = p[1], p[4]
                continue
        merged.append(p)
    geoms = []
    for u0, u1, kind, k0, k1 in merged:
        if kind == "line":
            geoms.append(Geometry(0.0, 0.0, 0.0, 0.0, u1 - u0, "line"))
        elif kind == "arc":
            geoms.append(Geometry(0.0, 0.0, 0.0, 0.0, u1 - u0, "arc", {"curvature": k0}))
        else:
            geoms.append(Geometry(0.0, 0.0, 0.0, 0.0, u1 - u0, "spiral", {"curv_start": k0, "curv_end": k1}))
    r, th, _ = sp.at(st, np.array([sa]))
    return _chain(geoms, float(r[0, 0]), float(r[0, 1]), float(th[0]))


def _probe_road(geoms: list[Geometry], width: float, road_id: str = "fit") -> Road:
    length = float(sum(g.length for g in geoms))
    w = np.array([[0.0, width, 0.0, 0.0, 0.0]])
    sec = LaneSection(s=0.0, left=[Lane(id=1, type="driving", widths=w)], center=Lane(id=0),
                      right=[Lane(id=-1, type="driving", widths=w)])
    return Road(id=road_id, length=length, geometries=geoms, lane_sections=[sec])


def _probe(geoms: list[Geometry], width: float):
    from .network import RoadNetwork

    road = _probe_road(geoms, width)
    return RoadNetwork(Header(), {road.id: road}, {})


def _noise(pts: np.ndarray, w: int = 7) -> float:
    """Robust noise estimate of a polyline: the median RMS residual of parabolas fitted to
    windows of ``w`` consecutive points (each in the frame of its chord)."""
    if len(pts) < w + 2:
        return 0.0
    win = np.lib.stride_tricks.sliding_window_view(pts, (w, 2))[:, 0]  # (M, w, 2)
    ch = win[:, -1] - win[:, 0]
    ln = np.maximum(np.hypot(ch[:, 0], ch[:, 1]), 1e-12)
    c, s = ch[:, 0] / ln, ch[:, 1] / ln
    rel = win - win[:, :1]
    u = rel[..., 0] * c[:, None] + rel[..., 1] * s[:, None]
    v = -rel[..., 0] * s[:, None] + rel[..., 1] * c[:, None]
    u = u / ln[:, None]
    V = np.stack([np.ones_like(u), u, u * u], -1)  # (M, w, 3)
    coef = np.linalg.solve(np.einsum("mwi,mwj->mij", V, V) + 1e-12 * np.eye(3), np.einsum("mwi,mw->mi", V, v)[..., None])[..., 0]
    res = v - np.einsum("mwi,mi->mw", V, coef)
    return float(np.median(np.sqrt((res * res).sum(1) / (w - 3))))


def fit_reference_line(
    points: Any,
    *,
    knot_spacing: float = 20.0,
    tolerance: float = 0.005,
    smoothing: float = 0.05,
    snap: bool = True,
    snap_tolerance: float = 0.01,
    label: str = "points",
) -> ReferenceFit:
    """Fit a G2 clothoid spline (line/arc/spiral records) to a polyline (see the module doc).

    ``points``: (N, 2) x, y ordered along the road (N >= 2). ``knot_spacing``: metres between
    curvature knots to start with; knot intervals whose points' RMS distance exceeds
    ``tolerance`` m and twice the input's noise (:attr:`ReferenceFit.noise`) are halved, down to 1 m or two point spacings (curvature jumps, tight bends). ``smoothing``: weight
    of the penalty on the curvature's kinks at the knots. ``snap``: tie near-straight and
    near-constant-curvature pieces to ``line``/``arc`` records where that keeps the error.
    """
    pts = _as_line(points, label)
    if knot_spacing <= 0 or tolerance <= 0:
        raise ValueError("knot_spacing and tolerance must be positive")
    seg = np.hypot(*np.diff(pts, axis=0).T)
    total = float(seg.sum())
    if len(pts) == 2:
        d = pts[1] - pts[0]
        geoms = [Geometry(0.0, float(pts[0, 0]), float(pts[0, 1]), float(np.arctan2(d[1], d[0])), total, "line")]
        return ReferenceFit(geoms, total, 0.0, 0.0, True, {"line": 1})
    margin = 2.0 + 0.01 * total
    L = total + 2 * margin
    K = max(1, int(np.ceil(L / knot_spacing)))
    step = max(1.0, L / 2000.0)
    sp = _Spline(np.linspace(0.0, L, K + 1), step)
    ridge = 1e-4
    anchor, th0, k, s = _initial(pts, sp, margin, smoothing, ridge)
    x = np.r_[0.0, th0, k]
    min_piece = max(1.0, 2.0 * float(np.median(seg)))
    noise = _noise(pts)
    for _ in range(8):  # refine where the curve cannot follow the points
        prob = _Problem(sp, pts, anchor, np.eye(sp.K + 1), smoothing, ridge)
        x, e, s = prob.solve(x, s)
        rms_p, cnt = _piece_rms(sp, s, e)
        valid = cnt >= 3
        bad = valid & (rms_p > max(tolerance, 2.0 * noise)) & (sp.D >= 2 * min_piece)
        if not bad.any() or sp.K > 4 * len(pts):
            break
        knots = np.union1d(sp.knots, 0.5 * (sp.knots[:-1] + sp.knots[1:])[bad])
        k = sp.kappa(knots, x[2:])  # the same curve on the finer knots
        sp = _Spline(knots, step)
        x = np.r_[x[:2], k]
    free = (prob, x, e, s)
    a, th0, k = prob.unpack(x)
    kinds = ["spiral"] * sp.K
    snapped = False
    if snap:
        # simplify the curvature profile (fewer knots), tie lines and arcs, refit; accept when the
        # error grows no more than the removed parameters explain with the input's noise
        n = len(pts)
        rms2_free = float(np.mean(e * e))
        rms_pf, _ = _piece_rms(sp, s, e)
        eps = 8.0 * max(snap_tolerance, noise) / knot_spacing**2
        for _ in range(5):
            idx = _simplify(sp.knots, k, eps)
            if len(idx) - 1 > max(8, sp.K // 3):
                break  # not much simpler than the free fit: keep that
            sp_c = _Spline(sp.knots[idx], step)
            A, kinds_c = _ties(k[idx], eps)
            # start: the heading profile closest to the free fit's (positions follow closely)
            M = np.concatenate([np.ones((len(sp.nodes), 1)), sp_c.phi(sp.nodes) @ A], 1)
            sol = np.linalg.lstsq(M, sp.Pn @ k, rcond=None)[0]
            prob_c = _KnotProblem(sp_c, pts, anchor, A, step)
            xc, ec, sc = prob_c.solve(np.r_[a, th0 + sol[0], sol[1:], sp_c.knots[1:-1]], s)
            sp_c = prob_c.spline(xc)
            allowed = 3.0 * max(0, sp.K + 1 - A.shape[1] - (sp_c.K - 1)) / n * noise**2 + 1e-6
            rms_pc, cnt = _piece_rms(sp, sc, ec)
            local_ok = not np.any((cnt > 0) & (rms_pc > rms_pf + max(snap_tolerance, noise)))
            if float(np.mean(ec * ec)) <= rms2_free + allowed and local_ok:
                sp, free, kinds, snapped = sp_c, (prob_c, xc, ec, sc), kinds_c, True
                break
            eps /= 2.0
    prob, x, e, s = free
    a, th0, k = prob.unpack(x)
    st = sp.state(prob.anchor, a, th0, k, jac=False)
    ends = sp.foot(st, pts[[0, -1]], s[[0, -1]], iters=30)
    sa, sb = float(ends[0]), float(ends[1])
    if not sb > sa:
        raise MapError(f"{label}: the fitted line has no length (are the points ordered?)")
    geoms = _geometries(sp, st, kinds, sa, sb)
    # errors on the exact, chained geometry
    net = _probe(geoms, 2.0 + float(np.max(np.abs(e))))
    pr = net.world_to_road(pts[:, 0], pts[:, 1])
    t = pr.t[np.isfinite(pr.t)]
    rms = float(np.sqrt(np.mean(t * t))) if len(t) else float("nan")
    mx = float(np.max(np.abs(t))) if len(t) else float("nan")
    counts: dict[str, int] = {}
    for g in geoms:
        counts[g.kind] = counts.get(g.kind, 0) + 1
    return ReferenceFit(geoms, float(sum(g.length for g in geoms)), rms, mx, snapped, counts, noise)


# ----------------------------------------------------------------------------------------------
# lanes
def _signed_offsets(ref: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Signed distance (positive left) of pts from the polyline ref (shapely foot points)."""
    import shapely

    line = shapely.LineString(ref)
    pos = shapely.line_locate_point(line, shapely.points(pts))
    foot = shapely.get_coordinates(shapely.line_interpolate_point(line, pos))
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(ref, axis=0).T))]
    i = np.clip(np.searchsorted(cum, pos, side="right") - 1, 0, len(ref) - 2)
    tan = ref[i + 1] - ref[i]
    d = pts - foot
    cross = tan[:, 0] * d[:, 1] - tan[:, 1] * d[:, 0]
    return np.sign(cross) * np.hypot(d[:, 0], d[:, 1])


def _pspline(s: np.ndarray, t: np.ndarray, L: float, spacing: float, lam: float):
    """Penalised cubic B-spline of t(s) on [0, L]: (knots, coefficients)."""
    from scipy.interpolate import BSpline

    n_int = max(1, int(round(L / spacing)))
    inner = np.linspace(0.0, L, n_int + 1)
    knots = np.r_[[0.0] * 3, inner, [L] * 3]
    nc = len(knots) - 4
    B = BSpline.design_matrix(np.clip(s, 0.0, L), knots, 3).toarray()
    w = lam * np.sqrt(max(1.0, len(s) / nc))
    D2 = np.diff(np.eye(nc), 2, axis=0) * w
    D1 = np.diff(np.eye(nc), 1, axis=0) * 1e-3
    M = np.concatenate([B, D2, D1])
    c = np.linalg.lstsq(M, np.r_[t, np.zeros(len(D2) + len(D1))], rcond=None)[0]
    return knots, c


def _pieces(knots: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints and (a, b, c, d) per interval of a cubic B-spline (local power basis)."""
    from scipy.interpolate import BSpline, PPoly

    pp = PPoly.from_spline(BSpline(knots, c, 3))
    x = pp.x
    keep = np.flatnonzero(x[1:] > x[:-1])
    return x[keep], pp.c[::-1, keep].T  # rows (a, b, c, d)


def _records(brk: np.ndarray, coef: np.ndarray, length: float, tol: float = 1e-9) -> np.ndarray:
    """Rows (start, a, b, c, d) of a piecewise cubic, with coefficients that move it by less than
    ``tol`` m over their interval set to 0 and intervals that continue the previous cubic merged."""
    from .lanes import shift_poly

    ends = np.r_[brk[1:], length]
    span = np.maximum(ends - brk, 1e-12)
    coef = coef.copy()
    for p in (1, 2, 3):
        coef[np.abs(coef[:, p]) * span**p < tol, p] = 0.0
    rows = [[float(brk[0]), *coef[0]]]
    for j in range(1, len(brk)):
        prev = np.array(rows[-1][1:])
        cont = shift_poly(prev, brk[j] - rows[-1][0])
        u = np.linspace(0.0, span[j], 5)
        if np.max(np.abs(np.polyval(cont[::-1], u) - np.polyval(coef[j][::-1], u))) < tol:
            continue
        rows.append([float(brk[j]), *coef[j]])
    return np.array(rows)


@dataclass
class RoadFit:
    """A fitted road: the OpenDRIVE text and what was fitted.

    ``rms``/``max_error``: distances of the reference polyline's points from the fitted reference
    line [m]. ``reference``: input index of that polyline. ``order``: input indices left to right.
    ``lane_ids``: lane ids left to right. ``line_lane``: for lane centres, the lane id of each input
    line (in input order); for borders, None. ``line_rms``: per input line, RMS of its points'
    lateral distances from the fitted border/centre line [m].
    """

    xodr: str
    road: Road
    reference_line: ReferenceFit
    reference: int
    order: list[int]
    lane_ids: list[int]
    line_lane: list[int] | None
    line_rms: list[float]

    @property
    def rms(self) -> float:
        return self.reference_line.rms

    @property
    def max_error(self) -> float:
        return self.reference_line.max_error

    def network(self):
        """The fitted road as a :class:`~.network.RoadNetwork`."""
        from . import load_map

        return load_map(self.xodr)

    def write(self, path: str | Path) -> Path:
        """Write the OpenDRIVE text to ``path``."""
        from aveas_format.safeio import write_text_atomic

        return write_text_atomic(path, self.xodr)


def fit_road(
    lines: Sequence[Any],
    *,
    kind: str = "centres",
    driving: str = "right",
    left_lanes: int | None = None,
    reference: int | None = None,
    ordered: bool = False,
    lane_width: float = 3.5,
    lane_types: Sequence[str] | None = None,
    mark_types: Sequence[str] | None = None,
    knot_spacing: float = 20.0,
    tolerance: float = 0.005,
    width_spacing: float = 25.0,
    smoothing: float = 0.05,
    snap: bool = True,
    road_id: str = "1",
    name: str = "fitted_road",
    road_type: str | None = None,
    speed_limit: float | None = None,
    geo_reference: str | None = None,
    label: str = "lines",
) -> RoadFit:
    """Fit one OpenDRIVE road (one lane section) to roughly parallel polylines.

    ``lines``: (N, 2) arrays in the local frame, each ordered along the road; the reference line
    runs in the direction of the reference polyline. ``kind``: ``"centres"`` (lane centre lines)
    or ``"borders"`` (lane borders / markings, n borders make n - 1 lanes). ``driving``:
    ``"right"`` (a one-way carriageway: every lane right of the centre lane, ids -1, -2, ...,
    driving along the reference line under right-hand traffic) or ``"both"`` (``left_lanes``
    lanes left of the centre lane, default half of them, the extra one going right).
    ``reference``: input index of the polyline the reference line is fitted to (default the
    centre-most). ``ordered``: the lines are given left to right (as seen along the reference
    polyline) and that order is checked; otherwise they are sorted by their lateral position.
    ``lane_width``: width of the lane of a single centre line. ``lane_types`` (left to right,
    default ``driving``) and ``mark_types`` (borders left to right, default solid outside and
    between the directions, broken elsewhere). ``knot_spacing``/``tolerance``/``smoothing``/``snap``:
    see :func:`fit_reference_line`; ``width_spacing``: metres between the knots of the lateral
    splines. Returns a :class:`RoadFit`; raises :class:`~aveas_format.errors.MapError` for
    malformed input.
    """
    if kind not in ("centres", "centers", "borders"):
        raise ValueError(f"kind must be 'centres' or 'borders', not {kind!r}")
    if driving not in ("right", "both"):
        raise ValueError(f"driving must be 'right' or 'both', not {driving!r}")
    if width_spacing <= 0 or lane_width <= 0:
        raise ValueError("width_spacing and lane_width must be positive")
    borders_in = kind == "borders"
    lines = list(lines) if not isinstance(lines, np.ndarray) or lines.ndim == 3 else [lines]
    n = len(lines)
    if n < (2 if borders_in else 1):
        raise MapError(f"{label}: need at least {2 if borders_in else 1} line(s), got {n}")
    arrs = [_as_line(ln, f"{label}[{i}]") for i, ln in enumerate(lines)]

    # lateral order from a preliminary reference (the longest line)
    lens = [float(np.hypot(*np.diff(a, axis=0).T).sum()) for a in arrs]
    pre = int(np.argmax(lens))
    med = np.array([float(np.median(_signed_offsets(arrs[pre], a))) if i != pre else 0.0
                    for i, a in enumerate(arrs)])
    order = [int(i) for i in np.argsort(-med, kind="stable")]
    if ordered and order != list(range(n)):
        bad = next(j for j in range(n) if order[j] != j)
        raise MapError(
            f"{label}: must be ordered left to right (as seen along {label}[{pre}]); "
            f"{label}[{order[bad]}] lies left of {label}[{bad}]"
        )
    n_lanes = n - 1 if borders_in else n
    if driving == "right":
        z = 0
    else:
        nl = n_lanes // 2 if left_lanes is None else int(left_lanes)
        if not 0 <= nl <= n_lanes:
            raise ValueError(f"left_lanes must be between 0 and {n_lanes}")
        z = nl
    if reference is None:
        cands = [(n - 1) // 2] if n % 2 else [n // 2 - 1, n // 2]
        target = z if borders_in else z - 0.5
        ref_pos = min(cands, key=lambda c: (abs(c - target), c))
        reference = order[ref_pos]
    if not 0 <= reference < n:
        raise ValueError(f"reference must be an index into {label} (0..{n - 1})")
    ref_pos = order.index(reference)

    ref = fit_reference_line(arrs[reference], knot_spacing=knot_spacing, tolerance=tolerance, smoothing=smoothing,
                             snap=snap, label=f"{label}[{reference}]")
    geoms = ref.geometries
    L = ref.length
    # project every line onto the exact reference line
    reach = max(float(np.max(np.abs(_signed_offsets(arrs[reference], a)))) for a in arrs) + 2.0
    kmax = max([abs(g.params.get("curvature", 0.0)) for g in geoms]
               + [max(abs(g.params.get("curv_start", 0.0)), abs(g.params.get("curv_end", 0.0))) for g in geoms])
    if reach * kmax >= 0.98:
        raise MapError(
            f"{label}: lines lie up to {reach - 2:.1f} m from the reference line {label}[{reference}], "
            f"beyond its tightest curve radius ({1 / kmax:.1f} m); fit the road in parts or pick "
            "another reference"
        )
    probe = _probe(geoms, reach)
    samples = []
    for i, a in enumerate(arrs):
        pr = probe.world_to_road(a[:, 0], a[:, 1])
        ok = np.isfinite(pr.s)
        if ok.sum() < 2:
            raise MapError(
                f"{label}[{i}]: does not run alongside the reference line {label}[{reference}] "
                f"(only {int(ok.sum())} of its points lie within its s range 0..{L:.1f} m)"
            )
        si, ti = pr.s[ok], pr.t[ok]
        if i == reference:
            ti = np.zeros_like(ti)
        srt = np.argsort(si)
        samples.append((si[srt], ti[srt]))
    # crossing lines: compare neighbours where both are observed
    grid = np.linspace(0.0, L, max(3, int(L / 1.0) + 1))
    for j in range(n - 1):
        (sa, ta), (sb, tb) = samples[order[j]], samples[order[j + 1]]
        lo, hi = max(sa[0], sb[0]), min(sa[-1], sb[-1])
        g = grid[(grid >= lo) & (grid <= hi)]
        if len(g) == 0:
            continue
        gap = np.interp(g, sa, ta) - np.interp(g, sb, tb)
        if gap.min() <= 0.05:
            at = float(g[int(np.argmin(gap))])
            x, y, _, _ = probe.road_to_world("fit", [at], [float(np.interp(at, sa, ta))])[:4]
            raise MapError(
                f"{label}[{order[j]}] and {label}[{order[j + 1]}] cross or touch near s={at:.1f} m "
                f"({x[0]:.2f}, {y[0]:.2f}); lines must keep their order across the road"
            )
    fits = []
    for i in range(n):
        knots, c = _pspline(*samples[i], L, width_spacing, 0.05)
        fits.append(np.zeros_like(c) if i == reference else c)
    from scipy.interpolate import BSpline

    line_rms = []
    for i in range(n):
        s_i, t_i = samples[i]
        r = BSpline(knots, fits[i], 3)(s_i) - t_i
        line_rms.append(float(np.sqrt(np.mean(r * r))))
    # border splines left to right (B-spline coefficients: linear in the lines)
    C = [fits[i] for i in order]
    if borders_in:
        B = C
    elif n == 1:
        B = [C[0] + lane_width / 2, C[0] - lane_width / 2]
    else:
        B = [1.5 * C[0] - 0.5 * C[1]] + [0.5 * (C[j - 1] + C[j]) for j in range(1, n)] + [1.5 * C[-1] - 0.5 * C[-2]]
    nb = len(B)
    if mark_types is not None and len(mark_types) != nb:
        raise ValueError(f"mark_types needs {nb} entries (one per border, left to right)")
    if lane_types is not None and len(lane_types) != nb - 1:
        raise ValueError(f"lane_types needs {nb - 1} entries (one per lane, left to right)")
    # widths must stay positive
    dense = np.linspace(0.0, L, max(3, int(L / 0.5) + 1))
    vals = np.array([BSpline(knots, b, 3)(dense) for b in B])
    widths = vals[:-1] - vals[1:]
    if widths.min() <= 0.05:
        j, m = np.unravel_index(int(np.argmin(widths)), widths.shape)
        raise MapError(
            f"{label}: the lane between borders {j} and {j + 1} (left to right) has width "
            f"{widths[j, m]:.3f} m at s={dense[m]:.1f} m; lines must not cross"
        )
    brk, _ = _pieces(knots, B[0])
    coef = [_pieces(knots, b)[1] for b in B]
    offset_is_ref = borders_in and ref_pos == z
    lane_offset = (
        []
        if offset_is_ref
        else [Poly3Record(*(float(v) for v in row)) for row in _records(brk, coef[z], L)]
    )

    def mark(b: int) -> RoadMark:
        if mark_types is not None:
            typ = mark_types[b]
        else:
            typ = "solid" if b in (0, nb - 1) or (b == z and 0 < z < nb - 1) else "broken"
        change = "none" if typ == "solid" else "both"
        return RoadMark(0.0, typ, {"weight": "standard", "color": "standard", "width": "0.15",
                                   "laneChange": change})

    left, right = [], []
    for j in range(nb - 1):  # lane between borders j and j+1
        lid = (z - j) if j < z else -(j - z + 1)
        outer = j if lid > 0 else j + 1
        inner = j + 1 if lid > 0 else j
        wcoef = coef[outer] - coef[inner] if lid > 0 else coef[inner] - coef[outer]
        rows = _records(brk, wcoef, L)
        lane = Lane(id=lid, type=lane_types[j] if lane_types is not None else "driving",
                    widths=rows, road_marks=[mark(outer)])
        (left if lid > 0 else right).append(lane)
    left.sort(key=lambda ln: ln.id)
    right.sort(key=lambda ln: -ln.id)
    sec = LaneSection(s=0.0, left=left, center=Lane(id=0, type="none", road_marks=[mark(z)]), right=right)
    types = []
    if road_type is not None or speed_limit is not None:
        types = [RoadType(0.0, road_type or "town", None,
                          None if speed_limit is None else repr(float(speed_limit)),
                          None if speed_limit is None else "m/s")]
    road = Road(id=str(road_id), length=L, name=name, types=types, geometries=geoms,
                lane_offset=lane_offset, lane_sections=[sec])
    from .builder import roads_xodr

    xodr = roads_xodr([road], name=name, geo_reference=geo_reference)
    lane_ids = [(z - j) if j < z else -(j - z + 1) for j in range(nb - 1)]
    line_lane = None
    if not borders_in:
        line_lane = [0] * n
        for pos, i in enumerate(order):
            line_lane[i] = lane_ids[pos]
    return RoadFit(xodr, road, ref, int(reference), order, lane_ids, line_lane, line_rms)


def road_from_lane_markings(
    markings: Sequence[Any],
    driving: str = "right",
    *,
    left_lanes: int | None = None,
    mark_types: Sequence[str] | None = None,
    **kw: Any,
) -> RoadFit:
    """A road from lane marking (border) polylines ordered left to right along the road.

    n markings make n - 1 lanes. ``driving="right"``: one carriageway, all lanes right of the
    reference line (ids -1 .. -(n-1), driving along the markings' direction). ``driving="both"``:
    ``left_lanes`` lanes (default: half, the extra one going right) lie left of the centre
    marking. ``mark_types``: one road mark type per marking (``solid``, ``broken``, ...). Other
    keywords go to :func:`fit_road` (``reference``, ``knot_spacing``, ``geo_reference``, ...).
    """
    return fit_road(markings, kind="borders", driving=driving, left_lanes=left_lanes, ordered=True,
                    mark_types=mark_types, label=kw.pop("label", "markings"), **kw)
