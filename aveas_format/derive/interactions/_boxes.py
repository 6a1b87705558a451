"""2D time to collision of oriented boxes for pairs that are not lane leader and follower.

Candidate pairs are those that could touch within ``horizon`` at their relative speed
(:func:`candidate_pairs`: swept boxes on a vectorised uniform grid per time step; optionally also
within ``search_radius`` of each other); pairs that cannot touch within ``horizon`` at their
relative speed are dropped;
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
from aveas_format.derive.interactions._pairs import KIND, REL, along_lane
from aveas_format.derive.interactions._surrogates import box_surrogates, sample_std
from aveas_format.derive.interactions._velocities import range_rate, range_rate_var
from aveas_format.numeric import keyed_normals

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


def candidate_pairs(tstep: np.ndarray, x: np.ndarray, y: np.ndarray, vx: np.ndarray,
                    vy: np.ndarray, reach: np.ndarray, horizon: float, cell: float = 40.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(i, j)``, ``i < j``, at the same time step that could touch within
    ``horizon`` s at constant velocity: a necessary condition, exact in the relative speed.

    Per time step the samples are seen in a frame moving at the step's mean velocity ``u``; in it
    each sample sweeps the segment from its centre ``p`` to ``p + (v - u) horizon``. Two footprints
    (discs of radius ``reach``: half their diagonals) that touch at some ``t <= horizon`` lie in the
    bounding boxes of their swept segments grown by ``reach``, so pairs whose boxes do not overlap
    can never touch; on a one-way highway the boxes are short (the speed differences), while two
    opposing streams get long boxes (their large relative speed), which is what the horizon asks
    for. The boxes are found on a vectorised uniform grid (``cell`` m; each box is entered in the
    cells it covers and a pair is reported once, in the cell of its overlap's lower corner)."""
    n = len(x)
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    if n < 2:
        return empty
    ts = np.asarray(tstep, np.int64)
    cnt = np.bincount(ts).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.bincount(ts, vx) / cnt
        uy = np.bincount(ts, vy) / cnt
    ex, ey = (vx - ux[ts]) * horizon, (vy - uy[ts]) * horizon
    x0 = np.minimum(x, x + ex) - reach
    x1 = np.maximum(x, x + ex) + reach
    y0 = np.minimum(y, y + ey) - reach
    y1 = np.maximum(y, y + ey) + reach
    ox, oy = float(np.min(x0)), float(np.min(y0))
    c0x = np.floor((x0 - ox) / cell).astype(np.int64)
    c1x = np.floor((x1 - ox) / cell).astype(np.int64)
    c0y = np.floor((y0 - oy) / cell).astype(np.int64)
    c1y = np.floor((y1 - oy) / cell).astype(np.int64)
    nx = c1x - c0x + 1
    ny_ = c1y - c0y + 1
    k, pos = ragged(nx * ny_)
    gx = c0x[k] + pos // ny_[k]
    gy = c0y[k] + pos % ny_[k]
    wy = int(c1y.max()) + 1
    wx = int(c1x.max()) + 1
    key = (ts[k] * wx + gx) * wy + gy
    order = np.argsort(key, kind="stable")
    ks, kk = key[order], k[order]
    brk = np.r_[True, ks[1:] != ks[:-1]]
    start = np.flatnonzero(brk)
    size = np.diff(np.r_[start, len(ks)])
    multi = size > 1
    start, size = start[multi], size[multi]
    I, J = [], []
    # all pairs within each cell: cell c with m members gives m(m-1)/2 pairs (in chunks)
    npairs = size * (size - 1) // 2
    for lo, hi in _chunk_ranges(npairs, 4_000_000):
        grp, q = ragged(npairs[lo:hi])
        m = size[lo:hi][grp]
        # q-th pair (a < b) of m members, row-major over a
        a = (m - 0.5 - np.sqrt((m - 0.5) ** 2 - 2.0 * q)).astype(np.int64)
        a = np.clip(a, 0, m - 2)
        first_q = a * (2 * m - a - 1) // 2
        fix = first_q > q
        a = np.where(fix, a - 1, a)
        first_q = a * (2 * m - a - 1) // 2
        nxt = (a + 1) * (2 * m - a - 2) // 2
        up = q >= nxt
        a = np.where(up, a + 1, a)
        first_q = a * (2 * m - a - 1) // 2
        b = a + 1 + (q - first_q)
        s0 = start[lo:hi][grp]
        i, j = kk[s0 + a], kk[s0 + b]
        cellx = gx[order[s0 + a]]
        celly = gy[order[s0 + a]]
        # the boxes overlap, and this cell holds the lower corner of their overlap
        ok = ((x0[i] <= x1[j]) & (x0[j] <= x1[i]) & (y0[i] <= y1[j]) & (y0[j] <= y1[i])
              & (cellx == np.maximum(c0x[i], c0x[j])) & (celly == np.maximum(c0y[i], c0y[j])))
        I.append(np.minimum(i[ok], j[ok]))
        J.append(np.maximum(i[ok], j[ok]))
    if not I:
        return empty
    return np.concatenate(I), np.concatenate(J)


def _chunk_ranges(counts: np.ndarray, budget: int) -> list[tuple[int, int]]:
    """Consecutive ranges of items holding about ``budget`` of ``counts`` each."""
    if not len(counts):
        return []
    group = (np.cumsum(counts) - counts) // max(budget, 1)
    cut = np.r_[0, np.flatnonzero(np.diff(group)) + 1, len(counts)]
    return list(zip(cut[:-1].tolist(), cut[1:].tolist()))


def pair_key(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    """One integer per unordered pair of rows (``n``: the number of rows)."""
    return np.minimum(i, j) * n + np.maximum(i, j)


def lookup(sorted_keys: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``k``: its position in ``sorted_keys`` (clipped to the array) and whether it is
    there."""
    pos = np.clip(np.searchsorted(sorted_keys, k), 0, max(len(sorted_keys) - 1, 0))
    found = (sorted_keys[pos] == k) if len(sorted_keys) else np.zeros(len(k), bool)
    return pos, found


def box_rows(S: Samples, lane: dict[str, np.ndarray], p: InteractionsParams,
             active: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """2D TTC (``i``, ``j``, ``ttc``) of the candidate pairs that are not lane leader/follower and
    can touch within the horizon (among the rows ``active``, whole time steps; None: all)."""
    act = np.arange(S.n) if active is None else np.flatnonzero(active)
    reach_all = 0.5 * np.hypot(S.L[act], S.W[act])
    i, j = candidate_pairs(S.tstep[act], S.x[act], S.y[act], S.vx[act], S.vy[act], reach_all,
                           p.horizon)
    i, j = act[i], act[j]
    if p.search_radius is not None:
        near = np.hypot(S.x[j] - S.x[i], S.y[j] - S.y[i]) <= p.search_radius
        i, j = i[near], j[near]
    if lane:
        lf = along_lane(lane["rel"])
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


def _draw(S: Samples, k: np.ndarray, other: np.ndarray, K: int, seed: int):
    """``K`` Monte Carlo draws of the states of rows ``k`` (in pairs with rows ``other``): x, y,
    heading, length, width, vx, vy (each ``(K, len(k))``). The draws of a row depend only on the
    seed, the two participants and the time (:func:`~aveas_format.numeric.keyed_normals`), so the
    std of a pair at a time does not depend on which other rows are derived with it (time
    windows, cut-outs)."""
    tkey = np.round(S.t[k] * 1e6).astype(np.int64)
    z = keyed_normals(seed, (S.pid[k], S.pid[other], tkey), 7 * K).reshape(7, K, len(k))
    z1, z2, w1, w2 = z[:4]
    r = np.clip(S.rxy[k], -0.999, 0.999)
    x = S.x[k] + S.sx[k] * z1
    y = S.y[k] + S.sy[k] * (r * z1 + np.sqrt(1 - r * r) * z2)
    rv = np.clip(S.rv[k], -0.999, 0.999)
    vx = S.vx[k] + S.svx[k] * w1
    vy = S.vy[k] + S.svy[k] * (rv * w1 + np.sqrt(1 - rv * rv) * w2)
    h = S.h[k] + S.sh[k] * z[4]
    L = np.maximum(S.L[k] + S.sL[k] * z[5], 0.1)
    W = np.maximum(S.W[k] + S.sW[k] * z[6], 0.1)
    return x, y, h, L, W, vx, vy


def ttc_draws(S: Samples, i: np.ndarray, j: np.ndarray, samples: int, seed: int):
    """``samples`` Monte Carlo draws of the 2D TTC of the pairs ``(i, j)`` (``(samples, pairs)``,
    inf where a draw never touches) and the draws of both participants' states (:func:`_draw`:
    keyed by the seed, the pair and the time, so a pair's draws do not depend on the other rows)."""
    a = _draw(S, i, j, samples, seed)
    b = _draw(S, j, i, samples, seed)
    return ttc_boxes(*a, *b), a, b


def box_std(S: Samples, i: np.ndarray, j: np.ndarray, p: InteractionsParams
            ) -> dict[str, np.ndarray]:
    """Std of the 2D TTC and of the surrogates derived from it (``ttc``, ``drac``, ``mdrac``,
    ``psd_i``, ``psd_j``: PSD of either participant) over Monte Carlo samples of both
    participants' states and sizes (finite samples only; NaN where fewer than half of the
    samples are finite)."""
    keys = ("ttc", "drac", "mdrac", "psd_i", "psd_j")
    if p.samples == 0 or len(i) == 0:
        return {k: np.full(len(i), np.nan) for k in keys}
    tt, a, b = ttc_draws(S, i, j, p.samples, p.seed)
    w = np.hypot(b[5] - a[5], b[6] - a[6])
    drac, mdrac, psd_i = box_surrogates(tt, w, np.hypot(a[5], a[6]), p.reaction_time,
                                        p.max_deceleration)
    psd_j = box_surrogates(tt, w, np.hypot(b[5], b[6]), p.reaction_time, p.max_deceleration)[2]
    return {k: sample_std(v) for k, v in zip(keys, (tt, drac, mdrac, psd_i, psd_j))}


def _surrogate_values(S: Samples, i: np.ndarray, j: np.ndarray, ttc: np.ndarray,
                      p: InteractionsParams) -> dict[str, np.ndarray]:
    """``drac``, ``mdrac``, ``psd_i``, ``psd_j`` of pairs (i, j) with box TTC ``ttc``."""
    w = np.hypot(S.vx[j] - S.vx[i], S.vy[j] - S.vy[i])
    drac, mdrac, psd_i = box_surrogates(ttc, w, np.hypot(S.vx[i], S.vy[i]), p.reaction_time,
                                        p.max_deceleration)
    psd_j = box_surrogates(ttc, w, np.hypot(S.vx[j], S.vy[j]), p.reaction_time,
                           p.max_deceleration)[2]
    return {"drac": drac, "mdrac": mdrac, "psd_i": psd_i, "psd_j": psd_j}


def box_conflicts(S: Samples, lane: dict[str, np.ndarray], p: InteractionsParams,
                  active: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The 2D TTC (up to ``horizon``, with its std) and the surrogates derived from it of the
    pairs :func:`box_rows` finds: the neighbour rows of ``lane`` take those of their pair
    (``lane`` is updated in place), the other pairs become ``conflicting`` rows, one per direction
    (returned; empty if there are none); ``active``: :func:`box_rows`."""
    box = box_rows(S, lane, p, active)
    fin = np.isfinite(box["ttc"]) & (box["ttc"] <= p.horizon)
    bi, bj, bt = box["i"][fin], box["j"][fin], box["ttc"][fin]
    sd = box_std(S, bi, bj, p)
    val = _surrogate_values(S, bi, bj, bt, p)
    key = pair_key(bi, bj, S.n)
    korder = np.argsort(key)
    ks = key[korder]
    if lane:
        # neighbours get the 2D TTC (and surrogates) of their pair
        nb = ~along_lane(lane["rel"])
        lk = pair_key(lane["i"], lane["j"], S.n)
        pos, found = lookup(ks, lk)
        hit = nb & found
        at = korder[pos] if len(ks) else np.zeros(len(lk), np.int64)
        # the row's participant is the pair's i or j: its own PSD
        is_i = (bi[at] == lane["i"]) if len(ks) else np.ones(len(lk), bool)

        def take(v: np.ndarray) -> np.ndarray:
            return v[at] if len(ks) else np.full(len(lk), np.nan)

        lane["ttc"] = np.where(hit, take(bt) if len(ks) else np.inf, lane["ttc"])
        lane["ttc_std"] = np.where(hit, take(sd["ttc"]), lane["ttc_std"])
        for k in ("drac", "mdrac"):
            lane[k] = np.where(hit, take(val[k]), lane[k])
            lane[f"{k}_std"] = np.where(hit, take(sd[k]), lane[f"{k}_std"])
        lane["psd"] = np.where(hit, np.where(is_i, take(val["psd_i"]), take(val["psd_j"])),
                               lane["psd"])
        lane["psd_std"] = np.where(hit, np.where(is_i, take(sd["psd_i"]), take(sd["psd_j"])),
                                   lane["psd_std"])
        lane["kind"] = np.where(hit, KIND["box_2d"], lane["kind"])
        _, is_nb = lookup(np.unique(lk[nb]), key)
    else:
        is_nb = np.zeros(len(key), bool)
    c = ~is_nb
    ci, cj, ct = bi[c], bj[c], bt[c]
    if not len(ci):
        return {}
    m = len(ci)
    rr, rv = range_rate(S, ci, cj), range_rate_var(S, ci, cj)
    nan = np.full(2 * m, np.nan)

    def both(v: np.ndarray) -> np.ndarray:
        return np.r_[v[c], v[c]]

    return {
        "i": np.r_[ci, cj], "j": np.r_[cj, ci],
        "rel": np.full(2 * m, REL["conflicting"]),
        "gap": nan, "gap_var": nan, "closing": np.r_[rr, rr], "closing_var": np.r_[rv, rv],
        "ttc": np.r_[ct, ct],
        "ttc_std": both(sd["ttc"]), "thw": nan, "dhw": nan,
        "ttc_ca": np.full(2 * m, np.inf), "ttc_ca_std": nan,
        "drac": both(val["drac"]), "drac_std": both(sd["drac"]),
        "mdrac": both(val["mdrac"]), "mdrac_std": both(sd["mdrac"]),
        "psd": np.r_[val["psd_i"][c], val["psd_j"][c]],
        "psd_std": np.r_[sd["psd_i"][c], sd["psd_j"][c]],
        "kind": np.full(2 * m, KIND["box_2d"]),
    }
