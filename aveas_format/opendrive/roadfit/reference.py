"""The reference line: a G2 clothoid spline fitted to a polyline (:func:`fit_reference_line`).

The reference line is fitted to the *centre-most* input line (the middle one across the road;
``reference=`` picks another). Its curvature is a continuous piecewise-linear function of s, i.e.
a chain of OpenDRIVE ``<spiral>`` records; heading and curvature are continuous everywhere (G2),
unlike paramPoly3 pieces, which would need explicit tangent constraints and are only G1. Knots
start every ``knot_spacing`` m; the start point, start heading and knot curvatures are found by
Levenberg-Marquardt on the orthogonal distances of the polyline's points to the curve (analytic
Jacobian, foot points re-found at every step; :mod:`.spline`), with a small penalty on the
curvature's kinks (which also makes sparse annotations, a few vertices per curve, well posed).
Knot intervals the curve cannot follow (RMS distance above ``tolerance`` and twice the input's
noise) are halved. Then the curvature profile is simplified (Ramer-Douglas-Peucker on
(s, curvature)), pieces near zero curvature become ``line`` records and near-constant ones ``arc``
records, and this simpler model is refitted with its transition points free; it is kept when its
error grows no more than the removed parameters explain with the noise. So a road built from
lines, arcs and clothoids comes back as lines, arcs and clothoids. The result is trimmed to the
foot points of the reference polyline's first and last points and chained exactly (each record
starts at the evaluated end of the previous one).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.errors import MapError
from aveas_format.opendrive.model import Geometry, Header, Lane, LaneSection, Road
from aveas_format.opendrive.roadfit.checks import as_line
from aveas_format.opendrive.roadfit.spline import KnotProblem, Problem, Spline


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


def _piece_rms(sp: Spline, s: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    i = sp.piece(s)[0]
    cnt = np.bincount(i, minlength=sp.K)
    ss = np.bincount(i, weights=e * e, minlength=sp.K)
    return np.sqrt(ss / np.maximum(cnt, 1)), cnt


def _initial(pts: np.ndarray, sp: Spline, margin: float, smoothing: float, ridge: float):
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


def _geometries(sp: Spline, st: dict, kinds: list[str], sa: float, sb: float) -> list[Geometry]:
    """The spline restricted to [sa, sb] as line/arc/spiral records (starts set by chaining)."""
    from aveas_format.opendrive.builder import chain_geometries

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
    return chain_geometries(geoms, float(r[0, 0]), float(r[0, 1]), float(th[0]))


def probe_road(geoms: list[Geometry], width: float, road_id: str = "fit") -> Road:
    """A road along ``geoms`` with one lane of ``width`` on each side (for projections)."""
    length = float(sum(g.length for g in geoms))
    w = np.array([[0.0, width, 0.0, 0.0, 0.0]])
    sec = LaneSection(s=0.0, left=[Lane(id=1, type="driving", widths=w)], center=Lane(id=0),
                      right=[Lane(id=-1, type="driving", widths=w)])
    return Road(id=road_id, length=length, geometries=geoms, lane_sections=[sec])


def probe_network(geoms: list[Geometry], width: float):
    """A network of that one road: world -> road projections onto the fitted reference line."""
    from aveas_format.opendrive.network import RoadNetwork

    road = probe_road(geoms, width)
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
    pts = as_line(points, label)
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
    sp = Spline(np.linspace(0.0, L, K + 1), step)
    ridge = 1e-4
    anchor, th0, k, s = _initial(pts, sp, margin, smoothing, ridge)
    x = np.r_[0.0, th0, k]
    min_piece = max(1.0, 2.0 * float(np.median(seg)))
    noise = _noise(pts)
    sp, prob, x, e, s = _refine(pts, sp, anchor, x, s, step, smoothing, ridge,
                                max(tolerance, 2.0 * noise), min_piece)
    free = (prob, x, e, s)
    kinds = ["spiral"] * sp.K
    snapped = False
    if snap:
        simpler = _snap(pts, sp, free, step, noise, snap_tolerance, knot_spacing)
        if simpler is not None:
            sp, free, kinds = simpler
            snapped = True
    prob, x, e, s = free
    a, th0, k = prob.unpack(x)
    st = sp.state(prob.anchor, a, th0, k, jac=False)
    ends = sp.foot(st, pts[[0, -1]], s[[0, -1]], iters=30)
    sa, sb = float(ends[0]), float(ends[1])
    if not sb > sa:
        raise MapError(f"{label}: the fitted line has no length (are the points ordered?)")
    geoms = _geometries(sp, st, kinds, sa, sb)
    # errors on the exact, chained geometry
    net = probe_network(geoms, 2.0 + float(np.max(np.abs(e))))
    pr = net.world_to_road(pts[:, 0], pts[:, 1])
    t = pr.t[np.isfinite(pr.t)]
    rms = float(np.sqrt(np.mean(t * t))) if len(t) else float("nan")
    mx = float(np.max(np.abs(t))) if len(t) else float("nan")
    counts: dict[str, int] = {}
    for g in geoms:
        counts[g.kind] = counts.get(g.kind, 0) + 1
    return ReferenceFit(geoms, float(sum(g.length for g in geoms)), rms, mx, snapped, counts, noise)


def _refine(pts: np.ndarray, sp: Spline, anchor: np.ndarray, x: np.ndarray, s: np.ndarray,
            step: float, smoothing: float, ridge: float, limit: float, min_piece: float):
    """Fit the free spline and halve the knot intervals whose points' RMS distance exceeds
    ``limit`` (down to ``min_piece``), at most 8 times: (spline, problem, x, residuals, feet)."""
    for _ in range(8):  # refine where the curve cannot follow the points
        prob = Problem(sp, pts, anchor, np.eye(sp.K + 1), smoothing, ridge)
        x, e, s = prob.solve(x, s)
        rms_p, cnt = _piece_rms(sp, s, e)
        valid = cnt >= 3
        bad = valid & (rms_p > limit) & (sp.D >= 2 * min_piece)
        if not bad.any() or sp.K > 4 * len(pts):
            break
        knots = np.union1d(sp.knots, 0.5 * (sp.knots[:-1] + sp.knots[1:])[bad])
        k = sp.kappa(knots, x[2:])  # the same curve on the finer knots
        sp = Spline(knots, step)
        x = np.r_[x[:2], k]
    return sp, prob, x, e, s


def _snap(pts: np.ndarray, sp: Spline, free: tuple, step: float, noise: float,
          snap_tolerance: float, knot_spacing: float):
    """Simplify the free fit's curvature profile (fewer knots), tie lines and arcs and refit with
    the knots free; accept when the error grows no more than the removed parameters explain with
    the input's noise: (spline, (problem, x, residuals, feet), kinds), or None."""
    prob, x, e, s = free
    a, th0, k = prob.unpack(x)
    n = len(pts)
    rms2_free = float(np.mean(e * e))
    rms_pf, _ = _piece_rms(sp, s, e)
    eps = 8.0 * max(snap_tolerance, noise) / knot_spacing**2
    for _ in range(5):
        idx = _simplify(sp.knots, k, eps)
        if len(idx) - 1 > max(8, sp.K // 3):
            break  # not much simpler than the free fit: keep that
        sp_c = Spline(sp.knots[idx], step)
        A, kinds_c = _ties(k[idx], eps)
        # start: the heading profile closest to the free fit's (positions follow closely)
        M = np.concatenate([np.ones((len(sp.nodes), 1)), sp_c.phi(sp.nodes) @ A], 1)
        sol = np.linalg.lstsq(M, sp.Pn @ k, rcond=None)[0]
        prob_c = KnotProblem(sp_c, pts, prob.anchor, A, step)
        xc, ec, sc = prob_c.solve(np.r_[a, th0 + sol[0], sol[1:], sp_c.knots[1:-1]], s)
        sp_c = prob_c.spline(xc)
        allowed = 3.0 * max(0, sp.K + 1 - A.shape[1] - (sp_c.K - 1)) / n * noise**2 + 1e-6
        rms_pc, cnt = _piece_rms(sp, sc, ec)
        local_ok = not np.any((cnt > 0) & (rms_pc > rms_pf + max(snap_tolerance, noise)))
        if float(np.mean(ec * ec)) <= rms2_free + allowed and local_ok:
            return sp_c, (prob_c, xc, ec, sc), kinds_c
        eps /= 2.0
    return None
