"""The ``ca_kalman_rts`` estimator: every track smoothed in lockstep on a ``(steps, rows)`` grid.

Long segments are cut into overlapping windows (:func:`windows`), windows are packed into the rows
of the grid (:func:`pack`) in chunks of ~2M samples, and each chunk runs the filter and smoother of
:mod:`._filters` (two 3-state filters per row, or the 6-state one where the position noise is
correlated) with ``q`` fixed or chosen by :func:`~._jerk_density.ml_jerk_density`. The jerk comes
from forward differences of the smoothed acceleration, its std from the lag-one covariance.
"""

from __future__ import annotations

import numpy as np

from aveas_format.derive._samples import ragged
from aveas_format.derive.kinematics._filters import ca_coupled, ca_decoupled
from aveas_format.derive.kinematics._jerk_density import ml_jerk_density


def windows(start: np.ndarray, length: np.ndarray, core: int, overlap: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split segments longer than ``core + 2 overlap`` into overlapping windows.

    Returns ``(start, length, keep_lo, keep_hi)`` per window: the window covers samples
    ``start .. start + length`` and its results are kept for offsets ``keep_lo .. keep_hi``. Each
    kept sample has ``overlap`` samples of context on both sides (or the segment's end), so the
    windowed smoother matches the full one to within the decay of the smoother's gain over
    ``overlap`` steps (far below the estimates' standard deviations; see the tests)."""
    n_win = np.where(length > core + 2 * overlap, -(-length // core), 1)
    seg, j = ragged(n_win)
    single = n_win[seg] == 1
    lo_core = np.where(single, 0, j * core)
    hi_core = np.where(single, length[seg], np.minimum((j + 1) * core, length[seg]))
    w_lo = np.maximum(lo_core - overlap, 0)
    w_hi = np.minimum(hi_core + overlap, length[seg])
    return start[seg] + w_lo, w_hi - w_lo, lo_core - w_lo, hi_core - w_lo


def pack(length: np.ndarray, rows: int) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Pack segments into the rows of a lockstep grid: ``(row, offset, n_rows, n_steps)`` per
    segment. Longest first, next-fit into rows of ``max(longest, ceil(total/rows))`` steps."""
    if len(length) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), 0, 0
    steps = int(max(length.max(), -(-int(length.sum()) // rows)))
    order = np.argsort(-length, kind="stable")
    row = np.empty(len(length), np.int64)
    off = np.empty(len(length), np.int64)
    r, fill = 0, 0
    for i in order:  # one iteration per segment (not per sample)
        n = int(length[i])
        if fill + n > steps:
            r, fill = r + 1, 0
        row[i], off[i] = r, fill
        fill += n
    return row, off, r + 1, steps


def kalman(t, x, y, sx, sy, rho, start, length, p):
    n = len(t)
    vx, vy, ax, ay = (np.empty(n) for _ in range(4))
    px, py = np.empty(n), np.empty(n)
    cov = {k: np.zeros(n) for k in ("vxvx", "vyvy", "vxvy", "axax", "ayay", "axay",
                                     "vxax", "vyay", "vxay", "vyax", "xx", "yy", "xy")}
    lagx, lagy, lagxy, lagyx = (np.full(n, np.nan) for _ in range(4))
    # long segments are cut into overlapping windows; windows are processed in chunks so the
    # grid stays bounded (~2M samples per chunk); windows with correlated x/y noise go through the
    # 6-state filter, the others through two 3-state filters
    wst, wln, klo, khi = windows(start, length, p.window_steps, p.overlap_steps)
    order = np.argsort(-wln, kind="stable")
    chunk_id = (np.cumsum(wln[order]) - 1) // 2_000_000
    for c in np.unique(chunk_id):
        segs = order[chunk_id == c]
        seg_rows, pos = ragged(wln[segs])
        corr = np.zeros(len(segs), bool)
        np.logical_or.at(corr, seg_rows, rho[wst[segs][seg_rows] + pos] != 0)
        for coupled in (False, True):
            sel = segs[corr == coupled]
            if len(sel):
                _run_grid(sel, wst, wln, klo, khi, t, x, y, sx, sy, rho, p, coupled,
                          (px, py, vx, vy, ax, ay), cov, (lagx, lagy, lagxy, lagyx))
    # jerk per axis: forward differences of the smoothed acceleration (backward at segment ends)
    jx, jy, jcov = _jerk(t, ax, ay, cov, lagx, lagy, lagxy, lagyx, start, length)
    return vx, vy, ax, ay, cov, jx, jy, jcov, px, py


def _run_grid(segs, start, length, keep_lo, keep_hi, t, x, y, sx, sy, rho, p, coupled, states,
              cov, lags):
    """Filter and smooth the windows ``segs`` on one lockstep grid; write the kept samples'
    smoothed ``states`` (positions, velocities, accelerations), covariances and lag-one
    covariances."""
    px, py, vx, vy, ax, ay = states
    lagx, lagy, lagxy, lagyx = lags
    ln = length[segs]
    row, off, W, L = pack(ln, p.batch_rows)
    seg, pos = ragged(ln)  # window and offset within the window of every sample
    idx = start[segs][seg] + pos  # sample index in the input
    srow = row[seg]
    sstep = np.repeat(off, ln) + pos
    keep = (pos >= np.repeat(keep_lo[segs], ln)) & (pos < np.repeat(keep_hi[segs], ln))
    first = np.zeros((L, W), bool)
    first[off, row] = True
    # padding cells act as segment starts so nothing propagates through them
    valid = np.zeros((L, W), bool)
    valid[sstep, srow] = True
    first |= ~valid
    dt = np.zeros((L, W))
    tt = np.zeros((L, W))
    tt[sstep, srow] = t[idx]
    dt[1:] = np.where(first[1:], 0.0, tt[1:] - tt[:-1])
    # positions centred on each window's first sample (numerical conditioning) and their noise
    z = np.zeros((L, 2, W))
    r = np.ones((L, 2, W))
    z[sstep, 0, srow] = x[idx] - np.repeat(x[start[segs]], ln)
    z[sstep, 1, srow] = y[idx] - np.repeat(y[start[segs]], ln)
    r[sstep, 0, srow] = sx[idx] ** 2
    r[sstep, 1, srow] = sy[idx] ** 2
    q = p.jerk_density
    if q == "auto":
        # maximum likelihood per window and axis (forward passes only); the 6-state filter takes
        # the larger of the two axes' values
        qwin = ml_jerk_density(z, r, dt, first, valid, (sstep, srow), (off, row, ln), p)
        q = np.full((L, 2, W), float(qwin.min()))
        q[sstep, :, srow] = np.repeat(qwin, ln, axis=0)
        if coupled:
            q = q.max(axis=1)
    if not coupled:
        Xs, Ps, lag = ca_decoupled(z, r, dt[:, None, :], first[:, None, :], q,
                                    p.prior_speed_std, p.prior_accel_std)
        x0, y0 = np.repeat(x[start[segs]], ln)[keep], np.repeat(y[start[segs]], ln)[keep]
        idx, sstep, srow = idx[keep], sstep[keep], srow[keep]
        px[idx], py[idx] = Xs[0][sstep, 0, srow] + x0, Xs[0][sstep, 1, srow] + y0
        cov["xx"][idx], cov["yy"][idx] = Ps[0][sstep, 0, srow], Ps[0][sstep, 1, srow]
        cov["xy"][idx] = 0.0
        vx[idx], vy[idx] = Xs[1][sstep, 0, srow], Xs[1][sstep, 1, srow]
        ax[idx], ay[idx] = Xs[2][sstep, 0, srow], Xs[2][sstep, 1, srow]
        cov["vxvx"][idx] = Ps[3][sstep, 0, srow]
        cov["vyvy"][idx] = Ps[3][sstep, 1, srow]
        cov["axax"][idx] = Ps[5][sstep, 0, srow]
        cov["ayay"][idx] = Ps[5][sstep, 1, srow]
        cov["vxax"][idx] = Ps[4][sstep, 0, srow]
        cov["vyay"][idx] = Ps[4][sstep, 1, srow]
        for k in ("vxvy", "axay", "vxay", "vyax"):
            cov[k][idx] = 0.0
        lagx[idx] = lag[sstep, 0, srow]
        lagy[idx] = lag[sstep, 1, srow]
        lagxy[idx] = 0.0
        lagyx[idx] = 0.0
    else:
        R = np.broadcast_to(np.eye(2), (L, W, 2, 2)).copy()
        cxy = rho[idx] * sx[idx] * sy[idx]
        R[:, :, 0, 0], R[:, :, 1, 1] = r[:, 0], r[:, 1]
        R[sstep, srow, 0, 1] = R[sstep, srow, 1, 0] = cxy
        Xs, Ps, lag = ca_coupled(z.transpose(0, 2, 1), R, dt, first, q, p.prior_speed_std,
                                  p.prior_accel_std)
        x0, y0 = np.repeat(x[start[segs]], ln)[keep], np.repeat(y[start[segs]], ln)[keep]
        idx, sstep, srow = idx[keep], sstep[keep], srow[keep]
        X = Xs[sstep, srow]
        P = Ps[sstep, srow]
        px[idx], py[idx] = X[:, 0] + x0, X[:, 3] + y0
        vx[idx], ax[idx], vy[idx], ay[idx] = X[:, 1], X[:, 2], X[:, 4], X[:, 5]
        for k, (i, j) in {"xx": (0, 0), "yy": (3, 3), "xy": (0, 3), "vxvx": (1, 1),
                          "vyvy": (4, 4), "vxvy": (1, 4), "axax": (2, 2),
                          "ayay": (5, 5), "axay": (2, 5), "vxax": (1, 2), "vyay": (4, 5),
                          "vxay": (1, 5), "vyax": (4, 2)}.items():
            cov[k][idx] = P[:, i, j]
        lg = lag[sstep, srow]
        lagx[idx], lagy[idx] = lg[:, 2, 2], lg[:, 5, 5]
        lagxy[idx], lagyx[idx] = lg[:, 2, 5], lg[:, 5, 2]  # Cov(ax[k+1], ay[k]), Cov(ay[k+1], ax[k])


def _jerk(t, ax, ay, cov, lagx, lagy, lagxy, lagyx, start, length):
    """Jerk vector by forward differences of the smoothed acceleration with its covariance (from
    the lag-one covariance); the last sample of a segment takes the backward difference."""
    n = len(t)
    jx, jy = np.full(n, np.nan), np.full(n, np.nan)
    jcov = {k: np.full(n, np.nan) for k in ("xx", "yy", "xy")}
    if n < 2:
        return jx, jy, jcov
    last = np.zeros(n, bool)
    last[start + length - 1] = True
    i = np.arange(n)
    a = np.where(last, i - 1, i)  # difference between a and a + 1
    a = np.clip(a, 0, n - 2)
    b = a + 1
    with np.errstate(invalid="ignore", divide="ignore"):
        dt = t[b] - t[a]
        jx = (ax[b] - ax[a]) / dt
        jy = (ay[b] - ay[a]) / dt
        jcov["xx"] = (cov["axax"][b] + cov["axax"][a] - 2 * lagx[a]) / dt ** 2
        jcov["yy"] = (cov["ayay"][b] + cov["ayay"][a] - 2 * lagy[a]) / dt ** 2
        jcov["xy"] = (cov["axay"][b] + cov["axay"][a] - lagxy[a] - lagyx[a]) / dt ** 2
    single = length == 1
    if single.any():
        jx[start[single]] = np.nan
    return jx, jy, jcov
