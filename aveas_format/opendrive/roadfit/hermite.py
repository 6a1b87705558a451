"""A reference line along a polyline with its end points and end headings prescribed: a G1 chain
of ``paramPoly3`` (cubic Hermite) and ``line`` records within a stated tolerance
(:func:`hermite_chain`).

Where roads meet, their lanes must meet (ASAM qc-opendrive checks the contact points of linked
lanes to 1 cm): the end of one road and the start of the next share a point and a heading. The
clothoid fit of :mod:`.reference` is free at both ends; this chain is not. It starts and ends at
the polyline's end points with the given headings (default: the polyline's own), and in between
passes through knots chosen on a smoothed copy of the polyline (positions and headings of a local
quadratic fit over +-``smooth`` metres; the tolerance is measured against that copy), each piece a cubic Hermite curve between two knots with
tangents of the chord's length (``pRange="normalized"``). A piece is split at its worst point
until every point of the polyline between its knots lies within ``tol`` of it. Pieces whose
points lie within ``tol / 4`` of their chord become ``line`` records, their knots taking the
chord's heading (so the chain stays G1). Each record's length is the cubic's true arc length
(Gauss-Legendre, 1e-9 m), as qc-opendrive checks it (``road.geometry.parampoly3.length_match``).
"""

from __future__ import annotations

import numpy as np
import shapely

from aveas_format.opendrive.model import Geometry

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)


def resample(points: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step`` m along a polyline (its ends kept) and their arc length."""
    pts = np.asarray(points, dtype=np.float64)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.r_[True, seg > 1e-9]
    pts = pts[keep]
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(pts, axis=0).T))]
    if len(pts) < 2:
        return pts, cum
    n = max(2, int(np.ceil(cum[-1] / step)) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.column_stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])]), s


def smoothed(points: np.ndarray, s: np.ndarray, smooth: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions and tangent directions of a weighted quadratic fit of x(s), y(s) over +-``smooth``
    m around every point (at least its two neighbours), vectorised over points; the two end points
    stay where they are."""
    n = len(points)
    if n == 2 or smooth <= 0:
        d = np.gradient(points, s, axis=0) if n > 2 else np.repeat((points[1:] - points[:1]), 2, 0)
        return points.copy(), np.arctan2(d[:, 1], d[:, 0])
    ds = float(np.median(np.diff(s)))
    k = max(2, int(np.ceil(smooth / max(ds, 1e-9))))
    idx = np.arange(n)[:, None] + np.arange(-k, k + 1)[None, :]
    valid = (idx >= 0) & (idx < n)
    idx = np.clip(idx, 0, n - 1)
    u = np.where(valid, s[idx] - s[:, None], 0.0)
    w = np.where(valid, 1.0 - (np.abs(u) / (smooth + ds)) ** 2, 0.0)
    w = np.maximum(w, 0.0) + valid * 1e-9
    V = np.stack([np.ones_like(u), u, u * u], -1) * np.sqrt(w)[..., None]
    A = np.einsum("nki,nkj->nij", V, V) + 1e-12 * np.eye(3)
    pos, der = [], []
    for c in (0, 1):
        rhs = np.einsum("nki,nk->ni", V, points[idx, c] * np.sqrt(w))
        sol = np.linalg.solve(A, rhs[..., None])[:, :, 0]
        pos.append(sol[:, 0])
        der.append(sol[:, 1])
    out = np.column_stack(pos)
    out[[0, -1]] = points[[0, -1]]
    return out, np.arctan2(der[1], der[0])


def _poly(p0: np.ndarray, h0: float, p1: np.ndarray, h1: float) -> np.ndarray:
    """paramPoly3 coefficients (aU, bU, cU, dU, aV, bV, cV, dV) in the frame of p0/h0 of the cubic
    Hermite curve from (p0, h0) to (p1, h1) with tangents as long as the chord."""
    c, s = np.cos(h0), np.sin(h0)
    d = p1 - p0
    ex, ey = d[0] * c + d[1] * s, -d[0] * s + d[1] * c
    L = float(np.hypot(ex, ey))
    dh = h1 - h0
    t0 = np.array([L, 0.0])
    t1 = np.array([L * np.cos(dh), L * np.sin(dh)])
    r1 = np.array([ex, ey])
    b, cc, dd = t0, -2 * t0 + 3 * r1 - t1, t0 - 2 * r1 + t1
    return np.array([0.0, b[0], cc[0], dd[0], 0.0, b[1], cc[1], dd[1]])


def _eval(coef: np.ndarray, p: np.ndarray) -> np.ndarray:
    u = coef[0] + p * (coef[1] + p * (coef[2] + p * coef[3]))
    v = coef[4] + p * (coef[5] + p * (coef[6] + p * coef[7]))
    return np.column_stack([u, v])


def arc_length(coef: np.ndarray, panels: int = 8) -> float:
    """True arc length of a paramPoly3 over p in [0, 1] (Gauss-Legendre on ``panels`` panels)."""
    a = np.arange(panels)[:, None] / panels
    p = (a + (_GL_X[None, :] + 1) / (2 * panels)).ravel()
    du = coef[1] + p * (2 * coef[2] + 3 * p * coef[3])
    dv = coef[5] + p * (2 * coef[6] + 3 * p * coef[7])
    return float((np.hypot(du, dv) * np.tile(_GL_W, panels)).sum() / (2 * panels))


def _world(coef: np.ndarray, p0: np.ndarray, h0: float, p: np.ndarray) -> np.ndarray:
    uv = _eval(coef, p)
    c, s = np.cos(h0), np.sin(h0)
    return np.column_stack([p0[0] + uv[:, 0] * c - uv[:, 1] * s, p0[1] + uv[:, 0] * s + uv[:, 1] * c])


def _max_dev(curve: np.ndarray, pts: np.ndarray) -> tuple[float, int]:
    """Largest distance of ``pts`` from the polyline ``curve``, and which point."""
    if len(pts) == 0:
        return 0.0, -1
    d = shapely.distance(shapely.LineString(curve), shapely.points(pts))
    i = int(np.argmax(d))
    return float(d[i]), i


def _length(points) -> float:
    p = np.asarray(points, dtype=np.float64)[:, :2]
    return max(float(np.hypot(*np.diff(p, axis=0).T).sum()), 1e-6)


def hermite_chain(points: np.ndarray, *, start_heading: float | None = None,
                  end_heading: float | None = None, tol: float = 0.02, smooth: float = 3.0,
                  step: float = 0.5) -> list[Geometry]:
    """``line``/``paramPoly3`` records from the first to the last of ``points`` (see the module
    doc); ``start_heading``/``end_heading`` prescribe the tangent there (radians). Records start at
    s = 0 with their exact start point and heading (the end of the previous record)."""
    pts, s = resample(np.asarray(points, dtype=np.float64)[:, :2], min(step, _length(points) / 4))
    if len(pts) < 2:
        raise ValueError("a reference line needs two distinct points")
    pts, h = smoothed(pts, s, smooth)
    if start_heading is not None or end_heading is not None:
        pts = _bend_ends(pts, s, h, start_heading, end_heading)
        pts, h = smoothed(pts, s, smooth)
    h = np.unwrap(h)
    if start_heading is not None:
        h[0] = h[0] + ((start_heading - h[0] + np.pi) % (2 * np.pi) - np.pi)
    if end_heading is not None:
        h[-1] = h[-1] + ((end_heading - h[-1] + np.pi) % (2 * np.pi) - np.pi)
    fixed = {0: start_heading is not None, len(pts) - 1: end_heading is not None}
    knots = [0, len(pts) - 1]
    lines: set[tuple[int, int]] = set()
    for _ in range(3):
        knots, lines, changed = _refine(pts, h, knots, tol, fixed)
        if not changed:
            break
    return _records(pts, h, knots, lines)


def _bend_ends(pts: np.ndarray, s: np.ndarray, h: np.ndarray, h0: float | None, h1: float | None) -> np.ndarray:
    """The polyline turned about its end points near them (by the difference between the
    prescribed and its own heading there, fading out quadratically over up to 10 m, at most 40 %
    of its length), so that it leaves its ends the prescribed way and the chain needs no hook."""
    out = pts.copy()
    total = float(s[-1])
    blend = min(10.0, 0.4 * total)
    if blend <= 0:
        return out
    for target, own, origin, dist in ((h0, h[0], pts[0], s), (h1, h[-1], pts[-1], total - s)):
        if target is None:
            continue
        delta = (target - own + np.pi) % (2 * np.pi) - np.pi
        w = np.clip(1.0 - dist / blend, 0.0, 1.0) ** 2
        a = delta * w
        rel = out - origin
        c, sn = np.cos(a), np.sin(a)
        out = origin + np.column_stack([rel[:, 0] * c - rel[:, 1] * sn, rel[:, 0] * sn + rel[:, 1] * c])
    return out


def _piece_ok(pts: np.ndarray, h: np.ndarray, i: int, j: int, tol: float) -> tuple[bool, int]:
    coef = _poly(pts[i], h[i], pts[j], h[j])
    m = max(16, 4 * (j - i))
    curve = _world(coef, pts[i], h[i], np.linspace(0.0, 1.0, m))
    dev, k = _max_dev(curve, pts[i + 1:j])
    # loops or cusps show as a curve much longer than the polyline between the knots
    poly_len = float(np.hypot(*np.diff(pts[i:j + 1], axis=0).T).sum())
    too_long = arc_length(coef) > 1.5 * poly_len + 1e-6
    return dev <= tol and not too_long, i + 1 + k if k >= 0 else (i + j) // 2


def _refine(pts, h, knots, tol, fixed):
    """Split pieces until each is within tol; mark straight pieces as lines (their knots take the
    chord heading unless prescribed). Returns (knots, lines, whether headings changed)."""
    out = [knots[0]]
    stack = [(knots[k], knots[k + 1]) for k in range(len(knots) - 1)][::-1]
    while stack:
        i, j = stack.pop()
        ok, worst = _piece_ok(pts, h, i, j, tol)
        if ok or j - i < 2:
            out.append(j)
            continue
        mid = worst if i < worst < j else (i + j) // 2
        stack += [(mid, j), (i, mid)]
    knots = out
    lines = set()
    changed = False
    chord_at: dict[int, float] = {}  # knot -> heading a line already gave it
    for i, j in zip(knots[:-1], knots[1:]):
        d = pts[j] - pts[i]
        chord = float(np.arctan2(d[1], d[0]))
        dev, _ = _max_dev(pts[[i, j]], pts[i + 1:j])
        straight = dev <= tol / 4
        for k in (i, j):
            off = (h[k] - chord + np.pi) % (2 * np.pi) - np.pi
            if fixed.get(k) and abs(off) > 1e-4:
                straight = False
        if i in chord_at and abs((chord_at[i] - chord + np.pi) % (2 * np.pi) - np.pi) > 1e-9:
            straight = False  # two lines in a row must share their direction (no kink)
        if straight:
            lines.add((i, j))
            chord_at[j] = chord
            for k in (i, j):
                off = (h[k] - chord + np.pi) % (2 * np.pi) - np.pi
                if abs(off) > 1e-12:
                    h[k] = h[k] - off
                    changed = True
    return knots, lines, changed


def _records(pts, h, knots, lines) -> list[Geometry]:
    out: list[Geometry] = []
    s = 0.0
    for i, j in zip(knots[:-1], knots[1:]):
        p0 = pts[i]
        if (i, j) in lines:
            L = float(np.hypot(*(pts[j] - p0)))
            prev = out[-1] if out else None
            if prev is not None and prev.kind == "line" and abs(prev.hdg - float(h[i])) < 1e-9:
                prev.length += L  # one line, not two in a row (qc-opendrive: redundant geometry)
                s += L
                continue
            out.append(Geometry(s, float(p0[0]), float(p0[1]), float(h[i]), L, "line"))
        else:
            coef = _poly(p0, h[i], pts[j], h[j])
            L = arc_length(coef)
            params = dict(zip(("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV"), (float(c) for c in coef)))
            params["p_range"] = "normalized"
            out.append(Geometry(s, float(p0[0]), float(p0[1]), float(h[i]), L, "paramPoly3", params))
        s += out[-1].length
    return out


__all__ = ["arc_length", "hermite_chain", "resample", "smoothed"]
