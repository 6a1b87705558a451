"""``derived/kinematics``: speed, accelerations and jerk with standard deviations from positions.

Default method ``ca_kalman_rts``: a constant-acceleration (white-jerk) Kalman filter with a
Rauch-Tung-Striebel smoother per track, state ``(p, v, a)`` per axis. Every sample's measurement
noise is its position covariance ``[[x_std², ρ x_std y_std], [ρ x_std y_std, y_std²]]``
(``ρ = xy_corr``); the process noise is a continuous white jerk of spectral density ``q``
(``jerk_density``, m²/s⁵ per axis)::

    Q(dt) = q [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]]

so irregular sampling and short gaps are handled exactly (gaps longer than ``max_gap_s`` start a
new track segment). All tracks run in lockstep: segments are packed into the rows of a
``(steps, rows)`` grid and each time step updates every row at once with closed-form 3x3
arithmetic (x and y are independent when ``xy_corr`` is 0; otherwise a batched 6x6 filter over the
rows with correlated noise). Standard deviations come from the smoothed covariance: speed,
``a_lon`` and ``a_lat`` by the delta method, jerk from the smoother's lag-one covariance.

``jerk_density="auto"`` (default) chooses ``q`` per track window and axis by maximum likelihood:
the innovations' log-likelihood over ``jerk_density_grid`` (decades) in one batched forward pass,
``jerk_density_refine`` bisections in ``log q`` around each window's best value, then the vertex of
a parabola. Rows with one sampling step and one noise variance run that pass with tabulated gains
(only the state recursion per step).

Option ``savitzky_golay``: a cubic Savitzky-Golay filter of ``savgol_window_s`` per track segment
(resampled to a uniform grid where the sampling is irregular); its standard deviations propagate
the position noise through the filter's linear weights (no model-error term).

Conventions: ``a_lon = (v·a)/|v|``, ``a_lat = (v×a)/|v| = (vx ay - vy ax)/|v|`` (ISO 8855, positive
to the left); below ``min_speed`` the direction of the ``heading`` column replaces ``v/|v|``.
``jerk_lon = d a_lon/dt = j·u + a_lat²/|v|``.
"""

from __future__ import annotations

import functools
from typing import Literal

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.errors import FormatError
from aveas_format.schema.columns import MUST, gaussian, pid_col, time_col
from aveas_format.schema.tables import derived_table


class KinematicsParams(Params):
    """Parameters of ``kinematics``."""

    method: Literal["ca_kalman_rts", "savitzky_golay"] = Field(
        "ca_kalman_rts", description="estimator: constant-acceleration Kalman + RTS smoother, or "
        "Savitzky-Golay")
    jerk_density: float | Literal["auto"] = Field(
        "auto", description="process noise: spectral density q of the white jerk per axis "
        "(m²/s⁵), or 'auto': chosen per track window and axis by maximum likelihood over "
        "`jerk_density_grid`")
    jerk_density_grid: tuple[float, ...] = Field(
        (1e-15, 1e-12, 1e-9, 1e-6, 1e-5, 1e-4, 1e-3, 0.01, 0.1, 1.0, 10.0, 100.0), min_length=1,
        description="candidate values of q for 'auto' (m²/s⁵), evaluated in one batched pass; "
        "the smallest stands for 'no jerk' (the likelihood is flat towards 0)")
    jerk_density_refine: int = Field(
        1, ge=0, le=4, description="'auto': bisections in log q around each window's best "
        "candidate (two more candidates per bisection) before the parabolic refinement")
    default_position_std: float = Field(0.1, gt=0, description="position std (m) where x_std/"
                                        "y_std are null or absent")
    min_position_std: float = Field(0.001, gt=0, description="lower bound of the position std (m)")
    max_gap_s: float = Field(1.0, gt=0, description="a longer gap between samples starts a new "
                             "track segment")
    prior_speed_std: float = Field(50.0, gt=0, description="prior std of each velocity component "
                                   "at a segment start (m/s)")
    prior_accel_std: float = Field(10.0, gt=0, description="prior std of each acceleration "
                                   "component at a segment start (m/s²)")
    min_speed: float = Field(0.5, ge=0, description="below this speed (m/s) the heading column "
                             "gives the longitudinal direction")
    savgol_window_s: float = Field(1.6, gt=0, description="Savitzky-Golay window length (s)")
    savgol_polyorder: int = Field(3, ge=2, le=5, description="Savitzky-Golay polynomial order")
    batch_rows: int = Field(8192, ge=1, description="tracks run in lockstep (rows of the grid)")
    window_steps: int = Field(1024, ge=16, description="long segments are smoothed in windows of "
                              "this many samples (plus the overlap on each side)")
    overlap_steps: int = Field(128, ge=8, description="samples of overlap on each side of a window "
                               "(discarded; the smoother's memory is far shorter)")


# --- segments and packing ------------------------------------------------------------------------

def segments(pid: np.ndarray, t: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """``(start, length)`` of the track segments of rows sorted by (participant, time): a new
    segment starts at a new participant or after a gap longer than ``max_gap``."""
    n = len(t)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    brk = np.ones(n, bool)
    brk[1:] = (pid[1:] != pid[:-1]) | (np.diff(t) > max_gap)
    start = np.flatnonzero(brk)
    length = np.diff(np.r_[start, n])
    return start, length


def windows(start: np.ndarray, length: np.ndarray, core: int, overlap: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split segments longer than ``core + 2 overlap`` into overlapping windows.

    Returns ``(start, length, keep_lo, keep_hi)`` per window: the window covers samples
    ``start .. start + length`` and its results are kept for offsets ``keep_lo .. keep_hi``. Each
    kept sample has ``overlap`` samples of context on both sides (or the segment's end), so the
    windowed smoother matches the full one to within the decay of the smoother's gain over
    ``overlap`` steps (far below the estimates' standard deviations; see the tests)."""
    n_win = np.where(length > core + 2 * overlap, -(-length // core), 1)
    seg = np.repeat(np.arange(len(length)), n_win)
    j = np.arange(len(seg)) - np.repeat(np.cumsum(n_win) - n_win, n_win)
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


# --- closed-form 3x3 CA filter over (axes, rows) -------------------------------------------------

def _predict_cov(P, d, q):
    """F P Fᵀ + Q for the CA model; P = (p00, p01, p02, p11, p12, p22)."""
    p00, p01, p02, p11, p12, p22 = P
    h = 0.5 * d * d
    a00 = p00 + d * p01 + h * p02
    a01 = p01 + d * p11 + h * p12
    a02 = p02 + d * p12 + h * p22
    a11 = p11 + d * p12
    a12 = p12 + d * p22
    d2 = d * d
    d3 = d2 * d
    return (a00 + d * a01 + h * a02 + q * (d3 * d2 / 20.0),
            a01 + d * a02 + q * (d2 * d2 / 8.0),
            a02 + q * (d3 / 6.0),
            a11 + d * a12 + q * (d3 / 3.0),
            a12 + q * (d2 / 2.0),
            p22 + q * d)


def _predict_state(X, d):
    x0, x1, x2 = X
    return x0 + d * x1 + 0.5 * d * d * x2, x1 + d * x2, x2


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
            P = _predict_cov(P, d, qs)
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


def _ca_decoupled(z, r, dt, first, q, prior_v, prior_a):
    """Filter + RTS smoother on a (steps, 2, rows) grid with independent axes.

    Returns smoothed states (3, steps, 2, rows), covariances (6, ...) and the lag-one
    covariance ``Cov(a[k+1], a[k])`` (steps, 2, rows; NaN where k+1 starts a new segment).
    """
    L = z.shape[0]
    Xf = np.empty((3,) + z.shape)
    Pf = np.empty((6,) + z.shape)
    big = 1e6
    X = (np.zeros(z.shape[1:]),) * 3
    P = (np.ones(z.shape[1:]),) * 6
    for k in range(L):
        d = dt[k]
        Xp = _predict_state(X, d)
        Pp = _predict_cov(P, d, q[k] if np.ndim(q) else q)
        f = first[k]
        if f.any():
            Xp = tuple(np.where(f, v, a) for v, a in zip((z[k], 0.0, 0.0), Xp))
            Pp = tuple(np.where(f, v, a) for v, a in
                       zip((big, 0.0, 0.0, prior_v ** 2, 0.0, prior_a ** 2), Pp))
        p00, p01, p02, p11, p12, p22 = Pp
        S = p00 + r[k]
        k0, k1, k2 = p00 / S, p01 / S, p02 / S
        e = z[k] - Xp[0]
        X = (Xp[0] + k0 * e, Xp[1] + k1 * e, Xp[2] + k2 * e)
        P = (p00 - k0 * p00, p01 - k0 * p01, p02 - k0 * p02,
             p11 - k1 * p01, p12 - k1 * p02, p22 - k2 * p02)
        for i in range(3):
            Xf[i, k] = X[i]
        for i in range(6):
            Pf[i, k] = P[i]
    # the smoother overwrites the filtered estimates in place: step k reads filtered[k] and
    # smoothed[k + 1] only
    Xs, Ps = Xf, Pf
    lag = np.full(z.shape, np.nan)
    for k in range(L - 2, -1, -1):
        cont = ~first[k + 1]
        if not cont.any():
            continue
        every = bool(cont.all())
        d = dt[k + 1]
        Pk = tuple(Pf[i, k].copy() for i in range(6))
        Xk = tuple(Xf[i, k].copy() for i in range(3))
        p00, p01, p02, p11, p12, p22 = _predict_cov(Pk, d, q[k + 1] if np.ndim(q) else q)
        c00 = p11 * p22 - p12 * p12
        c01 = p02 * p12 - p01 * p22
        c02 = p01 * p12 - p11 * p02
        c11 = p00 * p22 - p02 * p02
        c12 = p01 * p02 - p00 * p12
        c22 = p00 * p11 - p01 * p01
        det = p00 * c00 + p01 * c01 + p02 * c02
        i00, i01, i02, i11, i12, i22 = (c / det for c in (c00, c01, c02, c11, c12, c22))
        # B = P_f Fᵀ
        f00, f01, f02, f11, f12, f22 = Pk
        h = 0.5 * d * d
        B = ((f00 + d * f01 + h * f02, f01 + d * f02, f02),
             (f01 + d * f11 + h * f12, f11 + d * f12, f12),
             (f02 + d * f12 + h * f22, f12 + d * f22, f22))
        inv = ((i00, i01, i02), (i01, i11, i12), (i02, i12, i22))
        C = tuple(tuple(B[i][0] * inv[0][j] + B[i][1] * inv[1][j] + B[i][2] * inv[2][j]
                        for j in range(3)) for i in range(3))
        xp = _predict_state(Xk, d)
        dx = tuple(Xs[i, k + 1] - xp[i] for i in range(3))
        D = tuple(Ps[i, k + 1] for i in range(6))
        Dm = ((D[0] - p00, D[1] - p01, D[2] - p02),
              (D[1] - p01, D[3] - p11, D[4] - p12),
              (D[2] - p02, D[4] - p12, D[5] - p22))
        E = tuple(tuple(C[i][0] * Dm[0][j] + C[i][1] * Dm[1][j] + C[i][2] * Dm[2][j]
                        for j in range(3)) for i in range(3))
        G = {(i, j): E[i][0] * C[j][0] + E[i][1] * C[j][1] + E[i][2] * C[j][2]
             for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))}
        new_x = [Xk[i] + C[i][0] * dx[0] + C[i][1] * dx[1] + C[i][2] * dx[2] for i in range(3)]
        new_p = [Pk[m] + G[ij] for m, ij in
                 enumerate(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))]
        # Cov(x[k+1], x[k] | all) = P_s[k+1] Cᵀ; its (a, a) element
        new_lag = D[2] * C[2][0] + D[4] * C[2][1] + D[5] * C[2][2]
        if not every:
            new_x = [np.where(cont, v, o) for v, o in zip(new_x, Xk)]
            new_p = [np.where(cont, v, o) for v, o in zip(new_p, Pk)]
            new_lag = np.where(cont, new_lag, np.nan)
        for i in range(3):
            Xs[i, k] = new_x[i]
        for m in range(6):
            Ps[m, k] = new_p[m]
        lag[k] = new_lag
    return Xs, Ps, lag


# --- batched 6x6 filter for correlated measurement noise -------------------------------------------

def _F6(d):
    n = d.shape[0]
    F = np.zeros((n, 6, 6))
    for a in (0, 3):
        F[:, a, a] = F[:, a + 1, a + 1] = F[:, a + 2, a + 2] = 1.0
        F[:, a, a + 1] = F[:, a + 1, a + 2] = d
        F[:, a, a + 2] = 0.5 * d * d
    return F


def _Q6(d, q):
    n = d.shape[0]
    Q = np.zeros((n, 6, 6))
    d2, d3 = d * d, d * d * d
    blk = np.stack([np.stack([d3 * d2 / 20, d2 * d2 / 8, d3 / 6], -1),
                    np.stack([d2 * d2 / 8, d3 / 3, d2 / 2], -1),
                    np.stack([d3 / 6, d2 / 2, d], -1)], -2)
    blk = blk * (np.reshape(q, (-1, 1, 1)) if np.ndim(q) else q)
    Q[:, 0:3, 0:3] = blk
    Q[:, 3:6, 3:6] = blk
    return Q


def _ca_coupled(z, R, dt, first, q, prior_v, prior_a):
    """6-state filter + RTS smoother; z (steps, rows, 2), R (steps, rows, 2, 2).

    Returns Xs (steps, rows, 6), Ps (steps, rows, 6, 6) and lag-one covariances
    ``Cov(x[k+1], x[k])`` (steps, rows, 6, 6; NaN where k+1 starts a new segment)."""
    L, W = z.shape[:2]
    H = np.zeros((2, 6))
    H[0, 0] = H[1, 3] = 1.0
    P0 = np.diag([1e6, prior_v ** 2, prior_a ** 2, 1e6, prior_v ** 2, prior_a ** 2])
    Xf = np.empty((L, W, 6))
    Pf = np.empty((L, W, 6, 6))
    X = np.zeros((W, 6))
    P = np.broadcast_to(np.eye(6), (W, 6, 6)).copy()
    for k in range(L):
        F = _F6(dt[k])
        Xp = np.einsum("wij,wj->wi", F, X)
        Pp = F @ P @ F.transpose(0, 2, 1) + _Q6(dt[k], q[k] if np.ndim(q) else q)
        f = first[k]
        if f.any():
            Xp[f] = 0.0
            Xp[f, 0], Xp[f, 3] = z[k, f, 0], z[k, f, 1]
            Pp[f] = P0
        S = Pp[:, [0, 3]][:, :, [0, 3]] + R[k]
        PHt = Pp[:, :, [0, 3]]
        K = np.linalg.solve(S, PHt.transpose(0, 2, 1)).transpose(0, 2, 1)
        e = z[k] - Xp[:, [0, 3]]
        X = Xp + np.einsum("wij,wj->wi", K, e)
        P = Pp - K @ PHt.transpose(0, 2, 1)
        P = 0.5 * (P + P.transpose(0, 2, 1))
        Xf[k], Pf[k] = X, P
    Xs, Ps = Xf.copy(), Pf.copy()
    lag = np.full((L, W, 6, 6), np.nan)
    for k in range(L - 2, -1, -1):
        cont = ~first[k + 1]
        if not cont.any():
            continue
        F = _F6(dt[k + 1])
        Pp = F @ Pf[k] @ F.transpose(0, 2, 1) + _Q6(dt[k + 1], q[k + 1] if np.ndim(q) else q)
        C = np.linalg.solve(Pp, (Pf[k] @ F.transpose(0, 2, 1)).transpose(0, 2, 1)).transpose(0, 2, 1)
        xs = Xf[k] + np.einsum("wij,wj->wi", C, Xs[k + 1] - np.einsum("wij,wj->wi", F, Xf[k]))
        ps = Pf[k] + C @ (Ps[k + 1] - Pp) @ C.transpose(0, 2, 1)
        Xs[k] = np.where(cont[:, None], xs, Xf[k])
        Ps[k] = np.where(cont[:, None, None], 0.5 * (ps + ps.transpose(0, 2, 1)), Pf[k])
        lag[k] = np.where(cont[:, None, None], Ps[k + 1] @ C.transpose(0, 2, 1), np.nan)
    return Xs, Ps, lag


# --- driver -----------------------------------------------------------------------------------------

def _column(table: pa.Table, name: str, default: float) -> np.ndarray:
    if name not in table.column_names:
        return np.full(table.num_rows, default)
    from aveas_format.io.arrow import column_numpy

    v = column_numpy(table, name)
    return np.where(np.isfinite(v), v, default)


def estimate(pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, x_std: np.ndarray,
             y_std: np.ndarray, xy_corr: np.ndarray, heading: np.ndarray | None,
             p: KinematicsParams) -> dict[str, np.ndarray]:
    """Kinematics of rows sorted by (participant, time): a dict of output columns (NaN where a
    segment is too short: fewer than 3 samples)."""
    n = len(t)
    out = {k: np.full(n, np.nan) for k in
           ("speed", "ax", "ay", "a_lon", "a_lat", "jerk_lon", "speed_std", "ax_std", "ay_std",
            "a_lon_std", "a_lat_std", "jerk_lon_std")}
    if n == 0:
        return out
    if n > 1:
        same = pid[1:] == pid[:-1]
        bad = same & ~(np.diff(t) > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise FormatError(f"derivation kinematics: table states: participant {int(pid[i])} has "
                              f"non-increasing time at {t[i + 1]!r} (rows must be sorted by "
                              "participant_id, time, unique)")
    bad = ~(np.isfinite(x) & np.isfinite(y) & np.isfinite(t))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FormatError(f"derivation kinematics: table states: participant {int(pid[i])} has a "
                          f"non-finite position or time at row {i}")
    sx = np.maximum(x_std, p.min_position_std)
    sy = np.maximum(y_std, p.min_position_std)
    rho = np.clip(np.nan_to_num(xy_corr), -0.999, 0.999)
    start, length = segments(pid, t, p.max_gap_s)
    if p.method == "savitzky_golay":
        res = _savgol(t, x, y, sx, sy, start, length, p)
    else:
        res = _kalman(t, x, y, sx, sy, rho, start, length, p)
    vx, vy, ax, ay, cov, jx, jy, jcov = res
    ok = np.repeat(length >= 3, length)
    _combine(out, vx, vy, ax, ay, cov, jx, jy, jcov, heading, p.min_speed)
    for k in out:
        out[k][~ok] = np.nan
    return out


def _kalman(t, x, y, sx, sy, rho, start, length, p):
    n = len(t)
    vx, vy, ax, ay = (np.empty(n) for _ in range(4))
    cov = {k: np.zeros(n) for k in ("vxvx", "vyvy", "vxvy", "axax", "ayay", "axay",
                                     "vxax", "vyay", "vxay", "vyax")}
    lagx, lagy, lagxy, lagyx = (np.full(n, np.nan) for _ in range(4))
    # long segments are cut into overlapping windows; windows are processed in chunks so the
    # grid stays bounded (~2M samples per chunk); windows with correlated x/y noise go through the
    # 6-state filter, the others through two 3-state filters
    wst, wln, klo, khi = windows(start, length, p.window_steps, p.overlap_steps)
    order = np.argsort(-wln, kind="stable")
    chunk_id = (np.cumsum(wln[order]) - 1) // 2_000_000
    for c in np.unique(chunk_id):
        segs = order[chunk_id == c]
        seg_rows = np.repeat(np.arange(len(segs)), wln[segs])
        corr = np.zeros(len(segs), bool)
        np.logical_or.at(corr, seg_rows, rho[_ranges(wst[segs], wln[segs])] != 0)
        for coupled in (False, True):
            sel = segs[corr == coupled]
            if len(sel):
                _run_grid(sel, wst, wln, klo, khi, t, x, y, sx, sy, rho, p, coupled, vx, vy, ax,
                          ay, cov, (lagx, lagy, lagxy, lagyx))
    # jerk per axis: forward differences of the smoothed acceleration (backward at segment ends)
    jx, jy, jcov = _jerk(t, ax, ay, cov, lagx, lagy, lagxy, lagyx, start, length)
    return vx, vy, ax, ay, cov, jx, jy, jcov


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Concatenated ``arange(s, s + l)`` for every (s, l), vectorised."""
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    seg_off = np.repeat(np.cumsum(lengths) - lengths, lengths)
    return np.repeat(starts, lengths) + (np.arange(total) - seg_off)


def _ml_jerk_density(z: np.ndarray, r: np.ndarray, dt: np.ndarray, first: np.ndarray,
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


def _run_grid(segs, start, length, keep_lo, keep_hi, t, x, y, sx, sy, rho, p, coupled, vx, vy,
              ax, ay, cov, lags):
    lagx, lagy, lagxy, lagyx = lags
    ln = length[segs]
    row, off, W, L = pack(ln, p.batch_rows)
    idx = _ranges(start[segs], ln)  # sample index in the input
    srow = np.repeat(row, ln)
    pos = np.arange(len(idx)) - np.repeat(np.cumsum(ln) - ln, ln)  # offset within the window
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
        qwin = _ml_jerk_density(z, r, dt, first, valid, (sstep, srow), (off, row, ln), p)
        q = np.full((L, 2, W), float(qwin.min()))
        q[sstep, :, srow] = np.repeat(qwin, ln, axis=0)
        if coupled:
            q = q.max(axis=1)
    if not coupled:
        Xs, Ps, lag = _ca_decoupled(z, r, dt[:, None, :], first[:, None, :], q,
                                    p.prior_speed_std, p.prior_accel_std)
        idx, sstep, srow = idx[keep], sstep[keep], srow[keep]
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
        Xs, Ps, lag = _ca_coupled(z.transpose(0, 2, 1), R, dt, first, q, p.prior_speed_std,
                                  p.prior_accel_std)
        idx, sstep, srow = idx[keep], sstep[keep], srow[keep]
        X = Xs[sstep, srow]
        P = Ps[sstep, srow]
        vx[idx], ax[idx], vy[idx], ay[idx] = X[:, 1], X[:, 2], X[:, 4], X[:, 5]
        for k, (i, j) in {"vxvx": (1, 1), "vyvy": (4, 4), "vxvy": (1, 4), "axax": (2, 2),
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


def _combine(out, vx, vy, ax, ay, cov, jx, jy, jcov, heading, min_speed):
    """speed, a_lon, a_lat, jerk_lon and their std (delta method) into ``out``."""
    s = np.hypot(vx, vy)
    moving = s >= max(min_speed, 1e-9)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(moving, vx / s, np.cos(heading) if heading is not None else 1.0)
        uy = np.where(moving, vy / s, np.sin(heading) if heading is not None else 0.0)
        a_lon = ax * ux + ay * uy
        a_lat = ay * ux - ax * uy
        inv_s = np.where(moving, 1.0 / s, 0.0)
    # Jacobians w.r.t. (vx, vy, ax, ay); the velocity terms vanish when the heading gives u
    J_lon = ((ax - a_lon * ux) * inv_s, (ay - a_lon * uy) * inv_s, ux, uy)
    J_lat = ((ay - a_lat * ux) * inv_s, (-ax - a_lat * uy) * inv_s, -uy, ux)
    C = {("vx", "vx"): cov["vxvx"], ("vy", "vy"): cov["vyvy"], ("vx", "vy"): cov["vxvy"],
         ("ax", "ax"): cov["axax"], ("ay", "ay"): cov["ayay"], ("ax", "ay"): cov["axay"],
         ("vx", "ax"): cov["vxax"], ("vy", "ay"): cov["vyay"], ("vx", "ay"): cov["vxay"],
         ("vy", "ax"): cov["vyax"]}
    names = ("vx", "vy", "ax", "ay")

    def quad(J):
        v = np.zeros_like(s)
        for i, a in enumerate(names):
            for j, b in enumerate(names):
                c = C.get((a, b), C.get((b, a)))
                v = v + J[i] * J[j] * c
        return np.sqrt(np.maximum(v, 0.0))

    out["speed"] = s
    out["speed_std"] = np.sqrt(np.maximum(ux * ux * cov["vxvx"] + uy * uy * cov["vyvy"]
                                          + 2 * ux * uy * cov["vxvy"], 0.0))
    out["ax"], out["ay"] = ax, ay
    out["ax_std"] = np.sqrt(np.maximum(cov["axax"], 0.0))
    out["ay_std"] = np.sqrt(np.maximum(cov["ayay"], 0.0))
    out["a_lon"], out["a_lat"] = a_lon, a_lat
    out["a_lon_std"], out["a_lat_std"] = quad(J_lon), quad(J_lat)
    out["jerk_lon"] = jx * ux + jy * uy + a_lat * a_lat * inv_s
    out["jerk_lon_std"] = np.sqrt(np.maximum(ux * ux * jcov["xx"] + uy * uy * jcov["yy"]
                                             + 2 * ux * uy * jcov["xy"], 0.0))


# --- Savitzky-Golay ---------------------------------------------------------------------------------

def _savgol(t, x, y, sx, sy, start, length, p):
    """Cubic Savitzky-Golay derivatives per segment (uniform grid; irregular sampling is linearly
    resampled to the segment's median step and back). One loop iteration per segment."""
    from scipy.signal import savgol_coeffs, savgol_filter

    n = len(t)
    vx, vy, ax, ay, jx, jy = (np.full(n, np.nan) for _ in range(6))
    cov = {k: np.zeros(n) for k in ("vxvx", "vyvy", "vxvy", "axax", "ayay", "axay",
                                     "vxax", "vyay", "vxay", "vyax")}
    jcov = {k: np.zeros(n) for k in ("xx", "yy", "xy")}
    po = p.savgol_polyorder
    coeff_cache: dict[tuple[int, float, int], tuple[float, float, float, float]] = {}
    for s0, ln in zip(start.tolist(), length.tolist()):
        if ln < 3:
            continue
        sl = slice(s0, s0 + ln)
        ts = t[sl]
        h = float(np.median(np.diff(ts)))
        w = int(round(p.savgol_window_s / h)) | 1
        w = max(min(w, ln if ln % 2 else ln - 1), 3)
        order = min(po, w - 1)
        uniform = np.allclose(np.diff(ts), h, rtol=1e-3, atol=1e-9)
        grid = ts if uniform else np.arange(ts[0], ts[-1] + 0.5 * h, h)
        res = {}
        for name, arr in (("x", x[sl]), ("y", y[sl])):
            g = arr if uniform else np.interp(grid, ts, arr)
            for d in (1, 2, 3):
                v = savgol_filter(g, w, order, deriv=d, delta=h, mode="interp") if d <= order \
                    else np.zeros_like(g)
                res[name, d] = v if uniform else np.interp(ts, grid, v)
        vx[sl], ax[sl], jx[sl] = res["x", 1], res["x", 2], res["x", 3]
        vy[sl], ay[sl], jy[sl] = res["y", 1], res["y", 2], res["y", 3]
        key = (w, round(h, 9), order)
        if key not in coeff_cache:
            c = [savgol_coeffs(w, order, deriv=d, delta=h, use="dot") if d <= order
                 else np.zeros(w) for d in (1, 2, 3)]
            coeff_cache[key] = (float(c[0] @ c[0]), float(c[1] @ c[1]), float(c[2] @ c[2]),
                                float(c[0] @ c[1]))
        c11, c22, c33, c12 = coeff_cache[key]
        vx2, vy2 = sx[sl] ** 2, sy[sl] ** 2
        cov["vxvx"][sl], cov["vyvy"][sl] = c11 * vx2, c11 * vy2
        cov["axax"][sl], cov["ayay"][sl] = c22 * vx2, c22 * vy2
        cov["vxax"][sl], cov["vyay"][sl] = c12 * vx2, c12 * vy2
        jcov["xx"][sl], jcov["yy"][sl] = c33 * vx2, c33 * vy2
    return vx, vy, ax, ay, cov, jx, jy, jcov


# --- the derivation ---------------------------------------------------------------------------------

def compute(rec, p: KinematicsParams) -> pa.Table:
    """The ``derived/kinematics`` table of ``rec``."""
    from aveas_format.io.arrow import column_numpy

    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = column_numpy(s, "time")
    x = column_numpy(s, "x")
    y = column_numpy(s, "y")
    sx = _column(s, "x_std", p.default_position_std)
    sy = _column(s, "y_std", p.default_position_std)
    rho = _column(s, "xy_corr", 0.0)
    heading = column_numpy(s, "heading") if "heading" in s.column_names else None
    order = None
    if len(t) > 1 and (np.any(np.diff(pid) < 0) or np.any((np.diff(pid) == 0) & (np.diff(t) < 0))):
        order = np.lexsort((t, pid))
        pid, t, x, y, sx, sy, rho = (a[order] for a in (pid, t, x, y, sx, sy, rho))
        heading = heading[order] if heading is not None else None
    res = estimate(pid, t, x, y, sx, sy, rho, heading, p)
    cols = {"participant_id": pa.array(pid, pa.int64()), "time": pa.array(t, pa.float64())}
    for name in ("speed", "ax", "ay", "a_lon", "a_lat", "jerk_lon"):
        for c in (name, f"{name}_std"):
            v = res[c]
            cols[c] = pa.array(v, pa.float64(), mask=~np.isfinite(v))
    return pa.table(cols)


TABLE = derived_table(
    "kinematics",
    doc="Speed, accelerations and jerk per participant and time, estimated from the positions with "
    "their uncertainty.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(
        pid_col(),
        time_col(),
        *gaussian("speed", "m/s", MUST, "speed over ground", minimum=0.0, std_req=MUST),
        *gaussian("ax", "m/s²", MUST, "acceleration x, local frame", std_req=MUST),
        *gaussian("ay", "m/s²", MUST, "acceleration y, local frame", std_req=MUST),
        *gaussian("a_lon", "m/s²", MUST, "longitudinal acceleration (along the heading)",
                  std_req=MUST),
        *gaussian("a_lat", "m/s²", MUST, "lateral acceleration (to the left of the heading)",
                  std_req=MUST),
        *gaussian("jerk_lon", "m/s³", MUST, "longitudinal jerk", std_req=MUST),
    ),
)

KINEMATICS = register(Derivation(
    name="kinematics",
    spec=TABLE,
    version="1.1.0",
    params=KinematicsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y")},
    doc="speed, ax/ay, a_lon/a_lat and jerk_lon with standard deviations from the positions "
        "(constant-acceleration Kalman + RTS smoother, or Savitzky-Golay)",
    method=lambda p: p.method,
))
