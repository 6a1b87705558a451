"""The ``savitzky_golay`` estimator: a Savitzky-Golay filter of ``savgol_window_s`` per track
segment (resampled to a uniform grid where the sampling is irregular); its standard deviations
propagate the position noise through the filter's linear weights (no model-error term)."""

from __future__ import annotations

import numpy as np


def savgol(t, x, y, sx, sy, start, length, p):
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
    # no smoothed positions: the positions stay the measured ones (NaN here)
    return vx, vy, ax, ay, cov, jx, jy, jcov, np.full(n, np.nan), np.full(n, np.nan)
