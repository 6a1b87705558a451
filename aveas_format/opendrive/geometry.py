"""Exact, vectorised evaluation of OpenDRIVE reference lines and road profiles.

All plan-view geometries of a network are compiled into flat numpy arrays (one row per
``<geometry>``); :meth:`PlanView.evaluate` takes arrays of geometry indices and local offsets ``ds``
and evaluates each geometry type on its own subset at once:

- ``line``: closed form.
- ``arc``: closed form through ``sinc`` (exact and stable down to zero curvature).
- ``spiral`` (clothoid, curvature linear in s): Fresnel integrals (:func:`scipy.special.fresnel`)
  where they are accurate; where the curvature rate is tiny (the Fresnel form divides by it and
  loses digits, e.g. ``curvStart == curvEnd``) a 16-node Gauss-Legendre quadrature of
  ``(cos, sin)`` of the quadratic heading, which is exact to ~1e-13 m for heading changes of
  several radians.
- ``poly3`` (deprecated): ``v(u)`` in the local frame, ``s`` the true arc length; ``u(s)`` by
  inverting the arc length (a per-geometry table + Gauss-Legendre on the partial panel + Newton).
- ``paramPoly3``: ``pRange="arcLength"``: p in [0, length]; the curve's true arc length ``A(p)`` is
  computed and the point at ``s`` is the one at arc length ``s * A(length) / length`` (p read as
  true arc length rescaled to the geometry's length, as esmini does; reading p literally as s
  shifts points by cm on real maps). ``pRange="normalized"``: p in [0, 1], read the same way:
  the point at ``s`` is the one at true arc length ``s * A(1) / length``. Both are what esmini
  (``ParamPoly3::calcS2PMap``) and libOpenDRIVE (its arc-length table) compute; reading normalized
  p linearly as ``ds / length`` (the letter of the standard) differs from them by up to 0.13 m on
  a real RoadRunner-style map (docs/opendrive.md gives the agreement measured).

``evaluate`` also returns ``kappa`` (d heading / d s) and ``speed`` (|d position / d s|, 1 for all
types but paramPoly3, where it is close to 1), which the Newton projection needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import fresnel

from .model import Poly3Record, Road

KIND_CODES = {"line": 0, "arc": 1, "spiral": 2, "poly3": 3, "paramPoly3": 4}
LINE, ARC, SPIRAL, POLY3, PPOLY3 = range(5)
# poly modes: poly3 (p is the true arc length), paramPoly3 (p rescaled by arc length; its range
# [0, p_max] is [0, length] for pRange arcLength and [0, 1] for normalized)
MODE_TRUE_ARC, MODE_RESCALED_ARC = 0, 1

_GL16_X, _GL16_W = np.polynomial.legendre.leggauss(16)
_GL8_X, _GL8_W = np.polynomial.legendre.leggauss(8)
_N_PANELS = 64
_FRESNEL_TOL = 1e-10  # metres: use Fresnel where its rounding error estimate is below this


def polyval3(coef: np.ndarray, ds: np.ndarray) -> np.ndarray:
    """``a + b ds + c ds^2 + d ds^3`` with coef[..., 0..3] broadcast against ds."""
    return coef[..., 0] + ds * (coef[..., 1] + ds * (coef[..., 2] + ds * coef[..., 3]))


def polyder3(coef: np.ndarray, ds: np.ndarray) -> np.ndarray:
    return coef[..., 1] + ds * (2 * coef[..., 2] + ds * 3 * coef[..., 3])


@dataclass
class SegmentedIndex:
    """Lookup of "the last record starting at or before s" for many (road, s) at once.

    Records of all roads are concatenated road by road; ``start`` holds each record's start s and
    ``road_first``/``road_count`` each road's slice. Roads without records get ``road_count == 0``.
    """

    start: np.ndarray  # (R,) record start s
    road_first: np.ndarray  # (n_roads,) index of the first record of each road
    road_count: np.ndarray  # (n_roads,)
    sigma: np.ndarray  # (R,) start + road offset, increasing

    @classmethod
    def build(cls, starts_per_road: list[np.ndarray], road_offset: np.ndarray) -> SegmentedIndex:
        counts = np.array([len(x) for x in starts_per_road], dtype=np.int64)
        first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        start = np.concatenate(starts_per_road) if counts.sum() else np.zeros(0)
        roadidx = np.repeat(np.arange(len(counts)), counts)
        sigma = start + road_offset[roadidx] if len(start) else np.zeros(0)
        # keep sigma non-decreasing even for records that start before 0 or after the road's end
        sigma = np.maximum.accumulate(sigma) if len(sigma) else sigma
        return cls(start=start, road_first=first, road_count=counts, sigma=sigma)

    def find(self, road: np.ndarray, s: np.ndarray, road_offset: np.ndarray) -> np.ndarray:
        """Record index for each (road, s); -1 where the road has no record."""
        if len(self.sigma) == 0:
            return np.full(np.shape(s), -1, dtype=np.int64)
        idx = np.searchsorted(self.sigma, road_offset[road] + s, side="right") - 1
        lo = self.road_first[road]
        hi = lo + self.road_count[road] - 1
        idx = np.minimum(np.maximum(idx, lo), hi)
        return np.where(self.road_count[road] > 0, idx, -1)


class Profile:
    """A per-road piecewise cubic in s (elevation, superelevation, laneOffset), vectorised."""

    def __init__(self, records_per_road: list[list[Poly3Record]], road_offset: np.ndarray) -> None:
        self.road_offset = road_offset
        starts = [np.array([r.s for r in recs], dtype=np.float64) for recs in records_per_road]
        self.index = SegmentedIndex.build(starts, road_offset)
        coefs = [np.array([r.coef for r in recs], dtype=np.float64).reshape(-1, 4) for recs in records_per_road]
        self.coef = np.concatenate(coefs) if coefs else np.zeros((0, 4))

    def __call__(self, road: np.ndarray, s: np.ndarray) -> np.ndarray:
        idx = self.index.find(road, s, self.road_offset)
        ok = idx >= 0
        j = np.where(ok, idx, 0)
        if len(self.coef) == 0:
            return np.zeros(np.shape(s))
        ds = s - self.index.start[j]
        return np.where(ok, polyval3(self.coef[j], ds), 0.0)

    def derivative(self, road: np.ndarray, s: np.ndarray) -> np.ndarray:
        idx = self.index.find(road, s, self.road_offset)
        ok = idx >= 0
        j = np.where(ok, idx, 0)
        if len(self.coef) == 0:
            return np.zeros(np.shape(s))
        ds = s - self.index.start[j]
        return np.where(ok, polyder3(self.coef[j], ds), 0.0)


class PlanView:
    """All ``<geometry>`` records of a network as flat arrays, evaluated vectorised."""

    def __init__(self, roads: list[Road], road_offset: np.ndarray) -> None:
        geoms = [(ri, g) for ri, road in enumerate(roads) for g in road.geometries]
        n = len(geoms)
        self.road_offset = road_offset
        self.road = np.array([ri for ri, _ in geoms], dtype=np.int64)
        self.s0 = np.array([g.s for _, g in geoms], dtype=np.float64)
        self.x0 = np.array([g.x for _, g in geoms], dtype=np.float64)
        self.y0 = np.array([g.y for _, g in geoms], dtype=np.float64)
        self.h0 = np.array([g.hdg for _, g in geoms], dtype=np.float64)
        self.length = np.array([g.length for _, g in geoms], dtype=np.float64)
        self.kind = np.array([KIND_CODES[g.kind] for _, g in geoms], dtype=np.int8)
        self.line = [g.line for _, g in geoms]
        self.k0 = np.zeros(n)
        self.k1 = np.zeros(n)
        # polynomial coefficients (aU, bU, cU, dU, aV, bV, cV, dV) for poly3 / paramPoly3
        self.pc = np.zeros((n, 8))
        self.pmode = np.zeros(n, dtype=np.int8)
        normalized: list[int] = []
        for i, (_, g) in enumerate(geoms):
            p = g.params
            if g.kind == "arc":
                self.k0[i] = self.k1[i] = p["curvature"]
            elif g.kind == "spiral":
                self.k0[i], self.k1[i] = p["curv_start"], p["curv_end"]
            elif g.kind == "poly3":
                self.pc[i] = (0.0, 1.0, 0.0, 0.0, p["a"], p["b"], p["c"], p["d"])
                self.pmode[i] = MODE_TRUE_ARC
            elif g.kind == "paramPoly3":
                self.pc[i] = [p[k] for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")]
                self.pmode[i] = MODE_RESCALED_ARC
                if p["p_range"] != "arcLength":
                    normalized.append(i)
        # the range of the polynomial parameter p: [0, length], or [0, 1] for pRange normalized
        self.p_max = self.length.copy()
        self.p_max[normalized] = 1.0
        self.index = SegmentedIndex.build(
            [np.array([g.s for g in road.geometries], dtype=np.float64) for road in roads], road_offset
        )
        self._prepare_spirals()
        self._prepare_polys()

    # -- set-up ----------------------------------------------------------------------------------
    def _prepare_spirals(self) -> None:
        """Per spiral: rate c, and whether the Fresnel form is accurate (else Gauss-Legendre)."""
        n = len(self.kind)
        # geometries shorter than 1e-9 m keep their start curvature (no rate can be defined)
        L = np.where(self.length > 1e-9, self.length, 1.0)
        self.c = np.where((self.kind == SPIRAL) & (self.length > 1e-9), (self.k1 - self.k0) / L, 0.0)
        self.use_fresnel = np.zeros(n, dtype=bool)
        self.f_scale = np.zeros(n)
        self.f_sign = np.ones(n)
        self.f_phi = np.zeros(n)
        self.f_t0 = np.zeros(n)
        self.f_C0 = np.zeros(n)
        self.f_S0 = np.zeros(n)
        sp = np.flatnonzero(self.kind == SPIRAL)
        if len(sp) == 0:
            return
        c = self.c[sp]
        k0 = self.k0[sp]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            absc = np.abs(c)
            scale = np.sqrt(np.pi / absc)
            phi = self.h0[sp] - k0 * k0 / (2 * c)
            t0 = (k0 / c) * np.sqrt(absc / np.pi)
            t1 = (self.length[sp] + k0 / c) * np.sqrt(absc / np.pi)
            err = 4e-16 * scale * (1.0 + np.abs(phi) + t0 * t0 + t1 * t1)
        good = (absc > 0) & np.isfinite(err) & (err < _FRESNEL_TOL)
        self.use_fresnel[sp] = good
        S0, C0 = fresnel(np.where(good, t0, 0.0))
        self.f_scale[sp] = np.where(good, scale, 0.0)
        self.f_sign[sp] = np.where(c < 0, -1.0, 1.0)
        self.f_phi[sp] = np.where(good, phi, 0.0)
        self.f_t0[sp] = np.where(good, t0, 0.0)
        self.f_C0[sp] = C0
        self.f_S0[sp] = S0

    def _prepare_polys(self) -> None:
        """Arc-length tables for poly3 and paramPoly3: A(p) at 64 panels over [0, p_max]."""
        n = len(self.kind)
        self.ptab = np.zeros((n, _N_PANELS + 1))
        self.p_total = np.ones(n)  # A(p_max): true arc length over p in [0, p_max]
        self.p_h = np.ones(n)
        pi = np.flatnonzero((self.kind == POLY3) | (self.kind == PPOLY3))
        if len(pi) == 0:
            return
        L = np.maximum(self.p_max[pi], 1e-12)
        h = L / _N_PANELS
        self.p_h[pi] = h
        # integrate |r'(p)| over each panel with 8-node Gauss-Legendre
        a = np.arange(_N_PANELS)[None, :, None] * h[:, None, None]
        nodes = a + (h[:, None, None] / 2) * (_GL8_X[None, None, :] + 1)
        sp = self._pspeed(pi[:, None, None], nodes)
        panel = (sp * _GL8_W[None, None, :]).sum(-1) * (h[:, None] / 2)
        tab = np.concatenate([np.zeros((len(pi), 1)), np.cumsum(panel, axis=1)], axis=1)
        self.ptab[pi] = tab
        self.p_total[pi] = tab[:, -1]

    # -- polynomial helpers ------------------------------------------------------------------------
    def _pderiv(self, g: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        c = self.pc[g]
        du = c[..., 1] + p * (2 * c[..., 2] + 3 * p * c[..., 3])
        dv = c[..., 5] + p * (2 * c[..., 6] + 3 * p * c[..., 7])
        ddu = 2 * c[..., 2] + 6 * p * c[..., 3]
        ddv = 2 * c[..., 6] + 6 * p * c[..., 7]
        return du, dv, ddu, ddv

    def _pspeed(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        c = self.pc[g]
        du = c[..., 1] + p * (2 * c[..., 2] + 3 * p * c[..., 3])
        dv = c[..., 5] + p * (2 * c[..., 6] + 3 * p * c[..., 7])
        return np.hypot(du, dv)

    def arc_of_p(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        """True arc length A(p) from p=0 for table-backed polys (vectorised)."""
        h = self.p_h[g]
        k = np.clip(np.floor(p / h), 0, _N_PANELS - 1).astype(np.int64)
        a = k * h
        half = (p - a) / 2
        nodes = a[:, None] + half[:, None] * (_GL8_X[None, :] + 1)
        sp = self._pspeed(g[:, None], nodes)
        return self.ptab[g, k] + (sp * _GL8_W[None, :]).sum(-1) * half

    def p_of_ds(self, g: np.ndarray, ds: np.ndarray) -> np.ndarray:
        """The polynomial parameter p at local offset ds (see the module doc for the modes)."""
        L = np.maximum(self.length[g], 1e-12)
        target = np.where(self.pmode[g] == MODE_RESCALED_ARC, ds * self.p_total[g] / L, ds)
        # initial guess: linear in the table
        q = target * self.p_max[g] / self.p_total[g]
        for _ in range(8):
            f = self.arc_of_p(g, q) - target
            q = q - f / np.maximum(self._pspeed(g, q), 1e-12)
            if np.all(np.abs(f) < 1e-12):
                break
        return q

    def ds_of_p(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`p_of_ds`."""
        L = np.maximum(self.length[g], 1e-12)
        arc = self.arc_of_p(g, p)
        return np.where(self.pmode[g] == MODE_RESCALED_ARC, arc * L / self.p_total[g], arc)

    def ds_per_p(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        """d(ds)/dp."""
        L = np.maximum(self.length[g], 1e-12)
        sp = self._pspeed(g, p)
        return np.where(self.pmode[g] == MODE_RESCALED_ARC, sp * L / self.p_total[g], sp)

    def eval_p(self, g: np.ndarray, p: np.ndarray):
        """x, y, heading, d heading/dp, |dr/dp| of a poly geometry at parameter p."""
        c = self.pc[g]
        u = c[:, 0] + p * (c[:, 1] + p * (c[:, 2] + p * c[:, 3]))
        v = c[:, 4] + p * (c[:, 5] + p * (c[:, 6] + p * c[:, 7]))
        du, dv, ddu, ddv = self._pderiv(g, p)
        h0 = self.h0[g]
        ch, sh = np.cos(h0), np.sin(h0)
        x = self.x0[g] + u * ch - v * sh
        y = self.y0[g] + u * sh + v * ch
        sp2 = np.maximum(du * du + dv * dv, 1e-300)
        hdg = h0 + np.arctan2(dv, du)
        dh_dp = (du * ddv - dv * ddu) / sp2
        return x, y, hdg, dh_dp, np.sqrt(sp2)

    # -- evaluation --------------------------------------------------------------------------------
    def find(self, road: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Geometry index for each (road, s)."""
        return self.index.find(road, s, self.road_offset)

    def evaluate(self, g: np.ndarray, ds: np.ndarray):
        """Evaluate geometries ``g`` at local offsets ``ds`` (arrays of equal shape, 1-D).

        Returns ``x, y, hdg, kappa, speed`` with kappa = d hdg / d s and speed = |d r / d s|.
        """
        g = np.asarray(g, dtype=np.int64)
        ds = np.asarray(ds, dtype=np.float64)
        n = len(ds)
        x = np.empty(n)
        y = np.empty(n)
        hdg = np.empty(n)
        kap = np.zeros(n)
        speed = np.ones(n)
        kind = self.kind[g]
        if n == 0:
            return x, y, hdg, kap, speed
        for code in np.unique(kind):
            m = kind == code
            if m.all():
                sel = slice(None)
            else:
                sel = np.flatnonzero(m)
            gi, d = g[sel], ds[sel]
            if code == LINE:
                h0 = self.h0[gi]
                x[sel] = self.x0[gi] + d * np.cos(h0)
                y[sel] = self.y0[gi] + d * np.sin(h0)
                hdg[sel] = h0
            elif code == ARC:
                k = self.k0[gi]
                h0 = self.h0[gi]
                chord = d * np.sinc(k * d / (2 * np.pi))
                mid = h0 + k * d / 2
                x[sel] = self.x0[gi] + chord * np.cos(mid)
                y[sel] = self.y0[gi] + chord * np.sin(mid)
                hdg[sel] = h0 + k * d
                kap[sel] = k
            elif code == SPIRAL:
                xs, ys, hs, ks = self._spiral(gi, d)
                x[sel], y[sel], hdg[sel], kap[sel] = xs, ys, hs, ks
            else:
                p = self.p_of_ds(gi, d)
                xs, ys, hs, dh_dp, _ = self.eval_p(gi, p)
                dsdp = self.ds_per_p(gi, p)
                dpds = 1.0 / np.maximum(dsdp, 1e-300)
                x[sel], y[sel], hdg[sel] = xs, ys, hs
                kap[sel] = dh_dp * dpds
                speed[sel] = self._pspeed(gi, p) * dpds
        return x, y, hdg, kap, speed

    def _spiral(self, g: np.ndarray, d: np.ndarray):
        k0 = self.k0[g]
        c = self.c[g]
        h0 = self.h0[g]
        hdg = h0 + d * (k0 + 0.5 * c * d)
        kap = k0 + c * d
        x = np.empty_like(d)
        y = np.empty_like(d)
        uf = self.use_fresnel[g]
        if uf.any():
            f = np.flatnonzero(uf)
            gf = g[f]
            scale = self.f_scale[gf]
            sgn = self.f_sign[gf]
            phi = self.f_phi[gf]
            t = (d[f] + k0[f] / c[f]) * (1.0 / scale)
            S, C = fresnel(t)
            dC = C - self.f_C0[gf]
            dS = S - self.f_S0[gf]
            cp, sp = np.cos(phi), np.sin(phi)
            x[f] = self.x0[gf] + scale * (cp * dC - sgn * sp * dS)
            y[f] = self.y0[gf] + scale * (sp * dC + sgn * cp * dS)
        if not uf.all():
            q = np.flatnonzero(~uf)
            gq, dq = g[q], d[q]
            u = (dq[:, None] / 2) * (_GL16_X[None, :] + 1)
            th = h0[q, None] + u * (k0[q, None] + 0.5 * c[q, None] * u)
            w = _GL16_W[None, :] * (dq[:, None] / 2)
            x[q] = self.x0[gq] + (np.cos(th) * w).sum(-1)
            y[q] = self.y0[gq] + (np.sin(th) * w).sum(-1)
        return x, y, hdg, kap

    def at(self, road: np.ndarray, s: np.ndarray):
        """x, y, hdg, kappa, speed of the reference line of roads ``road`` at ``s``."""
        g = self.find(road, s)
        return self.evaluate(g, s - self.s0[g]) + (g,)

    def end_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, hdg at the end of every geometry."""
        x, y, h, _, _ = self.evaluate(np.arange(len(self.kind)), self.length.copy())
        return x, y, h


__all__ = ["PlanView", "Profile", "SegmentedIndex", "polyval3"]
