"""The constant-acceleration Kalman filter and Rauch-Tung-Striebel smoother, in closed form.

State ``(p, v, a)`` per axis with a continuous white jerk of spectral density ``q``::

    Q(dt) = q [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]]

:func:`ca_decoupled` runs the filter and smoother on a ``(steps, axes, rows)`` grid with closed-form
3x3 arithmetic (x and y independent); :func:`ca_coupled` is the batched 6x6 variant for correlated
position noise (``xy_corr`` != 0). Both return the smoothed states, covariances and the lag-one
covariance the jerk's std comes from. A cell flagged ``first`` starts a new segment (state from
the measurement, prior covariance).
"""

from __future__ import annotations

import numpy as np


def predict_cov(P, d, q):
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


def ca_decoupled(z, r, dt, first, q, prior_v, prior_a):
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
        Pp = predict_cov(P, d, q[k] if np.ndim(q) else q)
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
        p00, p01, p02, p11, p12, p22 = predict_cov(Pk, d, q[k + 1] if np.ndim(q) else q)
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


def ca_coupled(z, R, dt, first, q, prior_v, prior_a):
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
