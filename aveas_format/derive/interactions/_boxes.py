"""2D time to collision of oriented boxes for pairs that are not lane leader and follower.

Candidate pairs come from a vectorised uniform grid per time step (:func:`candidate_pairs`, within
``search_radius``); pairs that cannot touch within ``horizon`` at their relative speed are dropped;
:func:`ttc_boxes` gives the exact first contact of the two rectangles under constant velocity
(separating axes on the relative motion) and :func:`box_std` its std from Monte Carlo samples of
positions, velocities, headings and sizes. :func:`box_conflicts` gives the neighbour rows of the
lane relations their 2D TTC and turns the other pairs with a TTC up to ``horizon`` into
``conflicting`` rows.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from aveas_format.derive._samples import Samples, ragged
from aveas_format.derive.interactions._velocities import range_rate

if TYPE_CHECKING:
    from aveas_format.derive.interactions import InteractionsParams


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
            if int(cnt.sum()) == 0:
                continue
            ii, pos = ragged(cnt)
            jj = order[lo[ii] + pos]
            keep = ii < jj
            I.append(ii[keep])
            J.append(jj[keep])
    if not I:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(I), np.concatenate(J)
    near = np.hypot(x[j] - x[i], y[j] - y[i]) <= radius
    return i[near], j[near]


def pair_key(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """One integer per unordered pair of rows (``n``: the number of rows)."""
    return np.minimum(i, j) * n + np.maximum(i, j)


def lookup(sorted_keys: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``k``: its position in ``sorted_keys`` (clipped to the array) and whether it is
    there."""
    pos = np.clip(np.searchsorted(sorted_keys, k), 0, max(len(sorted_keys) - 1, 0))
    found = (sorted_keys[pos] == k) if len(sorted_keys) else np.zeros(len(k), bool)
    return pos, found


def box_rows(S: Samples, lane: dict[str, np.ndarray], p: InteractionsParams
             ) -> dict[str, np.ndarray]:
    """2D TTC (``i``, ``j``, ``ttc``) of the candidate pairs that are not lane leader/follower and
    can touch within the horizon."""
    i, j = candidate_pairs(S.tstep, S.x, S.y, p.search_radius)
    if lane:
        lf = np.isin(lane["rel"], ["leader", "follower"])
        lane_keys = np.unique(pair_key(lane["i"][lf], lane["j"][lf], S.n))
        _, is_lane = lookup(lane_keys, pair_key(i, j, S.n))
        i, j = i[~is_lane], j[~is_lane]
    # drop pairs that cannot touch within the horizon at their relative speed
    reach = 0.5 * (np.hypot(S.L[i], S.W[i]) + np.hypot(S.L[j], S.W[j]))
    dist = np.hypot(S.x[j] - S.x[i], S.y[j] - S.y[i])
    rel = np.hypot(S.vx[j] - S.vx[i], S.vy[j] - S.vy[i])
    can = dist - reach <= rel * p.horizon
    i, j = i[can], j[can]
    ttc = ttc_boxes(S.x[i], S.y[i], S.h[i], S.L[i], S.W[i], S.vx[i], S.vy[i],
                    S.x[j], S.y[j], S.h[j], S.L[j], S.W[j], S.vx[j], S.vy[j])
    return {"i": i, "j": j, "ttc": ttc}


def box_std(S: Samples, i: np.ndarray, j: np.ndarray, p: InteractionsParams) -> np.ndarray:
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


def box_conflicts(S: Samples, lane: dict[str, np.ndarray], p: InteractionsParams
                  ) -> dict[str, np.ndarray]:
    """The 2D TTC (up to ``horizon``, with its std) of the pairs :func:`box_rows` finds: the
    neighbour rows of ``lane`` take that of their pair (``lane`` is updated in place), the other
    pairs become ``conflicting`` rows, one per direction (returned; empty if there are none)."""
    box = box_rows(S, lane, p)
    fin = np.isfinite(box["ttc"]) & (box["ttc"] <= p.horizon)
    bi, bj, bt = box["i"][fin], box["j"][fin], box["ttc"][fin]
    bstd = box_std(S, bi, bj, p)
    key = pair_key(bi, bj, S.n)
    korder = np.argsort(key)
    ks = key[korder]
    if lane:
        # neighbours get the 2D TTC of their pair
        nb = ~np.isin(lane["rel"], ["leader", "follower"])
        lk = pair_key(lane["i"], lane["j"], S.n)
        pos, found = lookup(ks, lk)
        hit = nb & found
        lane["ttc"] = np.where(hit, bt[korder][pos] if len(ks) else np.inf, lane["ttc"])
        lane["ttc_std"] = np.where(hit, bstd[korder][pos] if len(ks) else np.nan,
                                   lane["ttc_std"])
        lane["kind"] = np.where(hit, "box_2d", lane["kind"])
        _, is_nb = lookup(np.unique(lk[nb]), key)
    else:
        is_nb = np.zeros(len(key), bool)
    ci, cj, ct, cs = bi[~is_nb], bj[~is_nb], bt[~is_nb], bstd[~is_nb]
    if not len(ci):
        return {}
    m = len(ci)
    rr = range_rate(S, ci, cj)
    nan = np.full(2 * m, np.nan)
    return {
        "i": np.r_[ci, cj], "j": np.r_[cj, ci],
        "rel": np.full(2 * m, "conflicting", object),
        "gap": nan, "gap_var": nan, "closing": np.r_[rr, rr], "ttc": np.r_[ct, ct],
        "ttc_std": np.r_[cs, cs], "thw": nan, "dhw": nan,
        "ttc_ca": np.full(2 * m, np.inf), "ttc_ca_std": nan,
        "kind": np.full(2 * m, "box_2d", object),
    }
