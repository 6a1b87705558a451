"""The clothoid spline and its least-squares problems, the model behind the reference-line fit
(:mod:`.reference`).

``Spline``: curvature piecewise linear in s between knots, heading and position by integration
from a free start point and heading (Simpson's rule), with the derivatives by the knot curvatures.
``Problem``: the orthogonal distances of polyline points to the curve, plus penalties on the
curvature's kinks, minimised by Levenberg-Marquardt (analytic Jacobian, foot points re-found at
every evaluation) with knot curvatures tied as ``k = A q``. ``KnotProblem``: the tied problem
with the inner knots' positions free as well.
"""

from __future__ import annotations

import numpy as np


class Spline:
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


class Problem:
    """Least squares of the point-to-curve distances with knot ties ``k = A q`` (Levenberg-Marquardt
    on the normal equations; the foot points are re-found at every evaluation)."""

    def __init__(self, sp: Spline, pts: np.ndarray, anchor: np.ndarray, A: np.ndarray,
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


class KnotProblem(Problem):
    """The tied problem with the inner knots' positions free as well (no penalties): parameters
    ``(a, th0, q, inner knots)``; the knots' columns of the Jacobian by forward differences."""

    def __init__(self, sp: Spline, pts: np.ndarray, anchor: np.ndarray, A: np.ndarray, step: float) -> None:
        super().__init__(sp, pts, anchor, A, 0.0, 0.0)
        self.P = np.zeros((0, A.shape[1]))
        self.nq = A.shape[1]
        self.step = step
        self.min_gap = 0.5
        self._cache: dict[bytes, Spline] = {sp.knots.tobytes(): sp}

    def spline(self, x: np.ndarray) -> Spline | None:
        knots = np.r_[0.0, x[2 + self.nq:], self.sp.L]
        if np.any(np.diff(knots) < self.min_gap):
            return None
        key = knots.tobytes()
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = Spline(knots, self.step)
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
            res, J, s_new = Problem.evaluate(self, x[: 2 + self.nq], s, jac)
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
                    rh = Problem.evaluate(self, xh[: 2 + self.nq], s_new, False)[0]
                    cols.append((rh - res) / h)
                    self.sp = sp
                if cols:
                    J = np.concatenate([J, np.stack(cols, 1)], 1)
        finally:
            self.sp = base
        return res, J, s_new
