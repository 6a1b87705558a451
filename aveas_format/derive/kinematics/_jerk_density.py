"""``jerk_density="auto"``: the process-noise density chosen per track window and axis by maximum
likelihood.

The innovations' log-likelihood is evaluated on ``jerk_density_grid`` (decades) in one batched
forward pass (:func:`_ca_window_loglik`, no smoother), then ``jerk_density_refine`` bisections in
``log q`` around each window's best value, then the vertex of a parabola
(:func:`ml_jerk_density`). Rows with one sampling step and one noise variance run that pass with
tabulated gains (:func:`_gain_table`, :func:`_ca_window_loglik_regular`: only the state
recursion per step); :class:`_WindowLikelihood` sends each row to the right pass.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from aveas_format.derive.kinematics._filters import predict_cov

if TYPE_CHECKING:
    from aveas_format.derive.kinematics import KinematicsParams


def ml_jerk_density(z: np.ndarray, r: np.ndarray, dt: np.ndarray, first: np.ndarray,
                     valid: np.ndarray, cells: tuple[np.ndarray, np.ndarray],
                     windows: tuple[np.ndarray, np.ndarray, np.ndarray],
                     p: KinematicsParams) -> np.ndarray:
    """Maximum-likelihood jerk density per window and axis, ``(windows, 2)``.

    The innovations' log-likelihood is evaluated on ``jerk_density_grid`` in one batched forward
    pass; ``jerk_density_refine`` bisections (in ``log q``) around each window's best value follow,
    two candidates per pass; the vertex of the parabola through the best value and its two
    neighbours gives the result. ``cells`` is ``(step, row)`` of every sample, ``windows`` is
    ``(offset, row, length)`` of every window of the ``(steps, rows)`` grid."""
    lik = _WindowLikelihood(z, r, dt, first, valid, cells, windows, p)
    fine, step = lik.fine, 1 << p.jerk_density_refine
    coarse = np.arange(0, len(fine), step)
    ll = lik(coarse)  # (windows, nq, 2)
    # ties (within 1e-6: a flat likelihood towards q = 0) go to the smallest candidate, so the
    # choice on the plateau does not depend on rounding
    best = np.argmax(ll >= ll.max(axis=1, keepdims=True) - 1e-6, axis=1)
    c = coarse[best]
    pad = np.full((ll.shape[0], 1, 2), -np.inf)
    llp = np.concatenate([pad, ll, pad], axis=1)
    yl, yc, yr = (_pick(llp, best + o) for o in (0, 1, 2))
    for level in range(1, p.jerk_density_refine + 1):
        h = step >> level
        cand = np.stack([c - h, c + h], axis=1)  # (windows, 2, axes)
        inside = (cand >= 0) & (cand < len(fine))
        ll = np.where(inside, lik(np.clip(cand, 0, len(fine) - 1)), -np.inf)
        b = np.argmax(np.stack([ll[:, 0], yc, ll[:, 1]], axis=1), axis=1)
        yl, yc, yr = (np.choose(b, opts) for opts in ((yl, ll[:, 0], yc), (ll[:, 0], yc, ll[:, 1]),
                                                      (yc, ll[:, 1], yr)))
        c = c + (b - 1) * h
    lg = np.log(fine)  # the final neighbours are adjacent on the refined grid
    return np.exp(_parabola_vertex(lg[np.clip(c - 1, 0, None)], lg[c],
                                   lg[np.clip(c + 1, None, len(fine) - 1)], yl, yc, yr))


def _pick(a: np.ndarray, i: np.ndarray) -> np.ndarray:
    """``a[w, i[w, j], j]`` for ``a`` of shape ``(windows, n, axes)``."""
    return np.take_along_axis(a, i[:, None, :], axis=1)[:, 0, :]


def _parabola_vertex(x0: np.ndarray, x1: np.ndarray, x2: np.ndarray, y0: np.ndarray,
                     y1: np.ndarray, y2: np.ndarray) -> np.ndarray:
    """Abscissa of the maximum of the parabola through three points with ``y1`` the largest,
    clipped to ``[x0, x2]``; ``x1`` where a neighbour is missing (``-inf``) or the three points
    are not strictly concave."""
    with np.errstate(invalid="ignore", divide="ignore"):
        u, w = (x1 - x0) * (y1 - y2), (x1 - x2) * (y1 - y0)
        xv = x1 - 0.5 * ((x1 - x0) * u - (x1 - x2) * w) / (u - w)
        curv = (y2 - y1) / (x2 - x1) - (y1 - y0) / (x1 - x0)
        ok = np.isfinite(y0) & np.isfinite(y2) & (curv < 0) & np.isfinite(xv)
    return np.where(ok, np.clip(np.where(ok, xv, x1), x0, x2), x1)


def _refined_grid(grid: np.ndarray, levels: int) -> np.ndarray:
    """``grid`` (sorted) with ``levels`` geometric bisections between neighbouring values."""
    if len(grid) < 2 or not levels:
        return grid
    lg = np.log(grid)
    frac = np.arange(1 << levels) / (1 << levels)
    inner = lg[:-1, None] + (lg[1:] - lg[:-1])[:, None] * frac[None, :]
    return np.exp(np.r_[inner.ravel(), lg[-1]])


class _WindowLikelihood:
    """The windows' log-likelihood for candidate densities given as indices into ``fine`` (the
    refined grid).

    Rows whose windows all share one sampling step and one noise variance on both axes (the usual
    case: a fixed frame rate and constant position std) take a fast pass whose gains depend only
    on the number of steps since the window start and are tabulated once; the other rows run the
    full recursion."""

    def __init__(self, z: np.ndarray, r: np.ndarray, dt: np.ndarray, first: np.ndarray,
                 valid: np.ndarray, cells: tuple[np.ndarray, np.ndarray],
                 windows: tuple[np.ndarray, np.ndarray, np.ndarray], p: KinematicsParams) -> None:
        self.fine = _refined_grid(np.unique(np.asarray(p.jerk_density_grid, float)),
                                  p.jerk_density_refine)
        self.z, self.r, self.dt, self.first, self.p = z, r, dt, first, p
        self.sstep, self.srow = cells
        off, row, self.ln = windows
        fast, self.d0, r0 = _regular_rows(dt, r, first, valid)
        end_step = off + self.ln - 1
        self.groups = []
        for sel in (fast, ~fast):
            if not sel.any():
                continue
            wins = np.flatnonzero(sel[row])
            order = wins[np.argsort(end_step[wins], kind="stable")]
            ends = (end_step[order], (np.cumsum(sel) - 1)[row[order]], np.arange(len(order)))
            cols = None if sel.all() else np.flatnonzero(sel)
            self.groups.append((sel is fast, cols, order, ends))
        self.table = _gain_table(int(self.ln.max()), self.d0, r0, tuple(self.fine.tolist()),
                                 p.prior_speed_std, p.prior_accel_std) if fast.any() else None

    def __call__(self, qi: np.ndarray) -> np.ndarray:
        """Log-likelihood ``(windows, nq, 2)`` for the grid indices ``qi``: ``(nq,)`` for every
        window or ``(windows, nq, 2)`` per window and axis."""
        L, _, W = self.z.shape
        per_win = qi.ndim == 3
        nq = qi.shape[1] if per_win else len(qi)
        out = np.empty((len(self.ln), nq, 2))
        qcell = qi
        if per_win:
            qcell = np.zeros((L, nq, 2, W), np.int32)
            qcell[self.sstep, :, :, self.srow] = np.repeat(qi.astype(np.int32), self.ln, axis=0)
        p = self.p
        for is_fast, cols, order, ends in self.groups:
            def sub(a: np.ndarray) -> np.ndarray:
                return a if cols is None else a[..., cols]
            qsub = sub(qcell) if per_win else qi
            if is_fast:
                out[order] = _ca_window_loglik_regular(
                    sub(self.z), sub(self.first), self.ln[order] - 1, ends, self.table, self.d0,
                    qsub, qi[order] if per_win else qi)
            else:
                rs = sub(self.r)
                shared = not per_win and np.array_equal(rs[:, 0], rs[:, 1])
                out[order] = _ca_window_loglik(
                    sub(self.z), rs[:, :1] if shared else rs, sub(self.dt)[:, None, :],
                    sub(self.first), ends, len(order), self.fine[qsub], p.prior_speed_std,
                    p.prior_accel_std)
        return out


def _regular_rows(dt: np.ndarray, r: np.ndarray, first: np.ndarray, valid: np.ndarray
                  ) -> tuple[np.ndarray, float, float]:
    """Rows of the ``(steps, rows)`` grid whose every sample (``valid`` cell) has the same noise
    variance ``r0`` on both axes and, outside segment starts, the same step ``d0``:
    ``(mask, d0, r0)``."""
    cont = ~first
    if not cont.any():
        return np.zeros(first.shape[1], bool), 0.0, 0.0
    k, w = np.unravel_index(np.argmax(cont), cont.shape)  # the first continuing sample
    d0, r0 = float(dt[k, w]), float(r[k, 0, w])
    odd = cont & (np.abs(dt - d0) > 1e-9 * d0)
    odd |= valid & ((r[:, 0] != r0) | (r[:, 1] != r0))
    return ~odd.any(axis=0), d0, r0


def _ca_window_loglik(z: np.ndarray, r: np.ndarray, dt: np.ndarray, first: np.ndarray,
                      ends: tuple[np.ndarray, np.ndarray, np.ndarray], n_win: int,
                      q: np.ndarray, prior_v: float, prior_a: float) -> np.ndarray:
    """Forward pass only, for several process-noise densities at once: the innovations'
    log-likelihood of every window, shape ``(n_win, nq, axes)``.

    ``z`` is ``(steps, axes, rows)``; ``r`` is ``(steps, axes, rows)`` or ``(steps, 1, rows)``
    when both axes share their noise (the covariance recursion, which does not depend on the
    data, then runs once for both axes); ``dt`` is ``(steps, 1, rows)``, ``first`` ``(steps,
    rows)``; ``q`` is ``(nq,)`` (the same values everywhere) or ``(steps, nq, axes, rows)`` (per
    cell). ``ends`` gives ``(step, row, window)`` of every window's last cell, sorted by step: the
    running sum of the log-likelihood (reset at every segment start, whose own term is 0) is read
    there, so no per-cell array is kept. Arrays are updated in place (no temporaries of the
    state's size beyond a few buffers)."""
    L = z.shape[0]
    per_cell = q.ndim == 4
    qv = q if per_cell else q[:, None, None]
    nq = q.shape[1] if per_cell else len(q)
    xshape = (nq,) + z.shape[1:]
    pshape = xshape if per_cell else (nq,) + r.shape[1:]
    x0, x1, x2, acc, e, tx = (np.zeros(xshape) for _ in range(6))
    p00, p01, p02, p11, p12, p22, tp, iS = (np.ones(pshape) for _ in range(8))
    prior = ((p00, 1e6), (p01, 0.0), (p02, 0.0), (p11, prior_v ** 2), (p12, 0.0),
             (p22, prior_a ** 2))
    tot = np.zeros((n_win, nq, z.shape[1]))
    end_step, end_row, end_win = ends
    cut = np.searchsorted(end_step, np.arange(L + 1))
    for k in range(L):
        d = dt[k]
        h, d3 = 0.5 * d * d, d * d * d
        qk = qv[k] if per_cell else qv
        # predict the state and the covariance F P Fᵀ + Q (in place, old values read first)
        x0 += np.multiply(x1, d, out=tx)
        x0 += np.multiply(x2, h, out=tx)
        x1 += np.multiply(x2, d, out=tx)
        for a, b, c in ((p00, p01, p02), (p01, p11, p12), (p02, p12, p22)):
            a += np.multiply(b, d, out=tp)
            a += np.multiply(c, h, out=tp)
        p11 += np.multiply(p12, d, out=tp)
        p12 += np.multiply(p22, d, out=tp)
        p00 += np.multiply(p01, d, out=tp)
        p00 += np.multiply(p02, h, out=tp)
        p00 += np.multiply(qk, d3 * d * d / 20.0, out=tp)
        p01 += np.multiply(p02, d, out=tp)
        p01 += np.multiply(qk, d3 * d / 8.0, out=tp)
        p02 += np.multiply(qk, d3 / 6.0, out=tp)
        p11 += np.multiply(p12, d, out=tp)
        p11 += np.multiply(qk, d3 / 3.0, out=tp)
        p12 += np.multiply(qk, h, out=tp)
        p22 += np.multiply(qk, d, out=tp)
        f = first[k]
        any_f = f.any()
        if any_f:
            x0[:, :, f] = z[k][:, f]
            x1[:, :, f] = x2[:, :, f] = 0.0
            for arr, v in prior:
                arr[:, :, f] = v
        np.add(p00, r[k], out=iS)
        np.divide(1.0, iS, out=iS)
        np.subtract(z[k], x0, out=e)
        np.multiply(e, e, out=tx)
        acc -= np.multiply(tx, iS, out=tx)
        acc += np.log(iS, out=tp)  # twice the log-likelihood term, up to a constant
        if any_f:
            acc[:, :, f] = 0.0
        # update: x += K e and P -= K P[0, :] with K = P[:, 0] / S (in place; P[0, :] read last)
        k1, k2 = p01 * iS, p02 * iS
        x1 += np.multiply(k1, e, out=tx)
        x2 += np.multiply(k2, e, out=tx)
        p11 -= np.multiply(k1, p01, out=tp)
        p12 -= np.multiply(k1, p02, out=tp)
        p22 -= np.multiply(k2, p02, out=tp)
        np.multiply(p00, iS, out=iS)  # k0
        x0 += np.multiply(iS, e, out=tx)
        p02 -= np.multiply(iS, p02, out=tp)
        p01 -= np.multiply(iS, p01, out=tp)
        p00 -= np.multiply(iS, p00, out=tp)
        lo, hi = cut[k], cut[k + 1]
        if hi > lo:
            tot[end_win[lo:hi]] = np.moveaxis(acc[:, :, end_row[lo:hi]], 2, 0)
    return 0.5 * tot


@functools.lru_cache(maxsize=4)
def _gain_table(n: int, d: float, r: float, grid: tuple[float, ...], prior_v: float,
                prior_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Kalman gains ``k0, k1, k2`` and ``1/S`` of the CA filter with a fixed step ``d`` and noise
    variance ``r`` after ``i = 0 .. n-1`` steps from a segment start for every ``q`` of ``grid``,
    stacked ``(4, len(grid) * n)`` (column ``j * n + i``), and the sum of ``log(1/S)`` over steps
    ``1 .. i`` (the start's own term is 0), ``(n, len(grid))``. Cached (the chunks of a run
    share it), so both arrays are read-only."""
    qs = np.asarray(grid)
    n = max(n, 1)
    out = np.empty((4, n, len(qs)))
    P = (np.full(len(qs), 1e6), 0.0 * qs, 0.0 * qs, np.full(len(qs), prior_v ** 2), 0.0 * qs,
         np.full(len(qs), prior_a ** 2))
    for i in range(n):
        if i:
            P = predict_cov(P, d, qs)
        p00, p01, p02, p11, p12, p22 = P
        iS = 1.0 / (p00 + r)
        k0, k1, k2 = p00 * iS, p01 * iS, p02 * iS
        out[:, i] = k0, k1, k2, iS
        P = (p00 - k0 * p00, p01 - k0 * p01, p02 - k0 * p02,
             p11 - k1 * p01, p12 - k1 * p02, p22 - k2 * p02)
    logs = np.log(out[3])
    logs[0] = 0.0
    gains = np.ascontiguousarray(out.transpose(0, 2, 1)).reshape(4, -1)
    logsum = np.cumsum(logs, axis=0)
    gains.flags.writeable = logsum.flags.writeable = False
    return gains, logsum


def _ca_window_loglik_regular(z: np.ndarray, first: np.ndarray, last: np.ndarray,
                              ends: tuple[np.ndarray, np.ndarray, np.ndarray],
                              table: tuple[np.ndarray, ...], d: float, qi: np.ndarray,
                              qi_win: np.ndarray) -> np.ndarray:
    """:func:`_ca_window_loglik` for rows with one step and one noise variance: the gains come
    from ``table`` (:func:`_gain_table` over a grid of q) by the number of steps since the window
    start, so only the state recursion runs per step (``d``: the step). ``qi`` indexes the
    table's grid, ``(nq,)`` or per cell ``(steps, nq, axes, rows)``; ``qi_win`` is the same per
    window, ``(nq,)`` or ``(windows, nq, axes)``; ``last`` is each window's last offset (its
    length − 1); windows are in the order of ``ends``."""
    L, A, W = z.shape
    gains, logsum = table
    n_tab = gains.shape[1] // logsum.shape[1]
    h = 0.5 * d * d
    per_cell = qi.ndim == 4
    nq = qi.shape[1] if per_cell else len(qi)
    shape = (nq, A, W)
    x0, x1, x2, acc, e, tmp = (np.zeros(shape) for _ in range(6))
    tot = np.zeros((len(last), nq, A))
    end_step, end_row, end_win = ends
    cut = np.searchsorted(end_step, np.arange(L + 1))
    n = np.zeros(W, np.int64)  # steps since the window start
    qoff = qi[:, None, None] * n_tab
    if per_cell:
        qi = qi * n_tab
    for k in range(L):
        f = first[k]
        n = np.where(f, 0, n + 1)
        # predict (in place: no temporaries of the (nq, axes, rows) state)
        x0 += np.multiply(x1, d, out=tmp)
        x0 += np.multiply(x2, h, out=tmp)
        x1 += np.multiply(x2, d, out=tmp)
        if f.any():
            x0[:, :, f] = z[k][:, f]
            x1[:, :, f] = x2[:, :, f] = acc[:, :, f] = 0.0
        # one gather of the four gains: row q * n_tab + steps since the start of the flat table
        k0, k1, k2, iS = np.take(gains, (qi[k] if per_cell else qoff) + n, axis=1)
        np.subtract(z[k], x0, out=e)
        np.multiply(e, e, out=tmp)
        acc -= np.multiply(tmp, iS, out=tmp)
        x0 += np.multiply(k0, e, out=tmp)
        x1 += np.multiply(k1, e, out=tmp)
        x2 += np.multiply(k2, e, out=tmp)
        lo, hi = cut[k], cut[k + 1]
        if hi > lo:
            tot[end_win[lo:hi]] = np.moveaxis(acc[:, :, end_row[lo:hi]], 2, 0)
    logs = logsum[last[:, None, None], qi_win] if qi_win.ndim == 3 else \
        logsum[last][:, qi_win][:, :, None]
    return 0.5 * (tot + logs)
