"""Piecewise cubics of s as OpenDRIVE records (``<width>``, ``<laneOffset>``, ``<border>``): fitted
to samples within a stated tolerance, and kept free of redundant records.

:func:`interpolating_cubics` cuts a sampled function ``v(s)`` into as few cubic pieces as the
tolerance allows (greedy, longest piece first): every piece passes exactly through the samples at
its two ends, so the pieces join continuously (C0) and the function is exact wherever a piece
starts or ends (the ends of a lane section above all, where linked lanes must meet); in between
every sample is within ``tol``. :func:`merge_continuations` drops records that continue the
previous cubic, which ASAM qc-opendrive reports as redundant (``performance.avoid_redundant_info``).
Rows are ``(s, a, b, c, d)`` with ``s`` where the record starts (the caller makes it absolute or
relative to its section) and the cubic in ``ds = s - start``.
"""

from __future__ import annotations

import numpy as np


def shift_cubic(coef: np.ndarray, delta: float) -> np.ndarray:
    """Coefficients of ``p(ds + delta)`` for the cubic ``p`` with coefficients ``(a, b, c, d)``."""
    a, b, c, d = (float(v) for v in coef)
    return np.array([a + delta * (b + delta * (c + delta * d)), b + delta * (2 * c + 3 * delta * d),
                     c + 3 * delta * d, d])


def evaluate_records(rows: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The piecewise cubic of ``rows`` (absolute starts, sorted) at ``s`` (the last record starting
    at or before each s applies; before the first, the first)."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, 5)
    s = np.asarray(s, dtype=np.float64)
    i = np.clip(np.searchsorted(rows[:, 0], s, side="right") - 1, 0, len(rows) - 1)
    u = s - rows[i, 0]
    return rows[i, 1] + u * (rows[i, 2] + u * (rows[i, 3] + u * rows[i, 4]))


def _fit_piece(u: np.ndarray, v: np.ndarray, va: float, vb: float, length: float) -> np.ndarray:
    """Cubic on [0, length] through (0, va) and (length, vb), least squares on the samples between:
    ``(a, b, c, d)``. With p(u) = va + (vb - va) u / L + q(u), q = alpha u (u - L) + beta u^2 (u - L)."""
    lin = va + (vb - va) * u / length
    if len(u) >= 2:
        basis = np.stack([u * (u - length), u * u * (u - length)], 1)
        alpha, beta = np.linalg.lstsq(basis, v - lin, rcond=None)[0]
    elif len(u) == 1:
        alpha = float((v[0] - lin[0]) / (u[0] * (u[0] - length))) if 0 < u[0] < length else 0.0
        beta = 0.0
    else:
        alpha = beta = 0.0
    # va + (vb-va)/L u + alpha (u^2 - L u) + beta (u^3 - L u^2)
    return np.array([va, (vb - va) / length - alpha * length, alpha - beta * length, beta])


def interpolating_cubics(s: np.ndarray, v: np.ndarray, tol: float, *, max_length: float | None = None,
                         lower: float | None = None) -> np.ndarray:
    """Rows ``(s_start, a, b, c, d)`` (absolute starts) of a continuous piecewise cubic through
    ``(s[0], v[0])`` and ``(s[-1], v[-1])`` that stays within ``tol`` of every sample, with as few
    pieces as a greedy search finds (each piece as long as possible; ``max_length`` caps it).
    ``lower``: a bound the cubic must not go below (at the samples and half-way between them),
    as a lane width must not go below 0 (the samples must respect it).

    ``s`` must be increasing. Piece ends lie on samples, where the function is exact.
    """
    s = np.asarray(s, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if len(s) != len(v) or len(s) == 0:
        raise ValueError("s and v must be non-empty and of equal length")
    if len(s) == 1 or s[-1] - s[0] <= 0:
        return np.array([[float(s[0]), float(v[0]), 0.0, 0.0, 0.0]])
    if np.any(np.diff(s) <= 0):
        raise ValueError("s must be strictly increasing")
    n = len(s)
    rows = []
    i = 0
    while i < n - 1:
        def ok(j: int) -> np.ndarray | None:
            L = s[j] - s[i]
            if max_length is not None and L > max_length and j > i + 1:
                return None
            u = s[i + 1:j] - s[i]
            coef = _fit_piece(u, v[i + 1:j], v[i], v[j], L)
            if len(u):
                err = coef[0] + u * (coef[1] + u * (coef[2] + u * coef[3])) - v[i + 1:j]
                if np.max(np.abs(err)) > tol:
                    return None
            if lower is not None:
                uu = np.r_[u, 0.5 * (np.r_[0.0, u] + np.r_[u, L])]
                val = coef[0] + uu * (coef[1] + uu * (coef[2] + uu * coef[3]))
                if np.min(val) < lower - 1e-9 and j > i + 1:
                    return None
            return coef

        # grow the piece by doubling, then bisect to the longest piece that fits
        best_j, best = i + 1, ok(i + 1)
        step = 1
        hi = None
        while True:
            j = min(i + 2 * step, n - 1)
            c = ok(j)
            if c is None:
                hi = j
                break
            best_j, best = j, c
            if j == n - 1:
                break
            step *= 2
        if hi is not None:
            lo = best_j
            while hi - lo > 1:
                mid = (lo + hi) // 2
                c = ok(mid)
                if c is None:
                    hi = mid
                else:
                    lo, best_j, best = mid, mid, c
        rows.append([float(s[i]), *(float(x) for x in best)])
        i = best_j
    return merge_continuations(np.array(rows), float(s[-1]), tol=min(tol, 1e-6))


def merge_continuations(rows: np.ndarray, end: float, tol: float = 1e-6) -> np.ndarray:
    """``rows`` without the records whose cubic continues the previous one (within ``tol`` m over
    the record's interval; ``end``: where the last record ends). Coefficients that move the cubic by
    less than 1e-12 m over their interval are set to 0."""
    rows = np.asarray(rows, dtype=np.float64).reshape(-1, 5).copy()
    if len(rows) == 0:
        return rows
    ends = np.r_[rows[1:, 0], end]
    span = np.maximum(ends - rows[:, 0], 1e-12)
    for p in (1, 2, 3):
        rows[np.abs(rows[:, 1 + p]) * span ** p < 1e-12, 1 + p] = 0.0
    out = [rows[0]]
    for j in range(1, len(rows)):
        prev = out[-1]
        cont = shift_cubic(prev[1:], rows[j, 0] - prev[0])
        u = np.linspace(0.0, span[j], 7)
        if np.max(np.abs(np.polyval(cont[::-1], u) - np.polyval(rows[j, 1:][::-1], u))) <= tol:
            continue
        out.append(rows[j])
    return np.array(out)


def difference(upper: np.ndarray, lower: np.ndarray, start: float, end: float) -> np.ndarray:
    """Rows of ``upper(s) - lower(s)`` on [start, end] (both piecewise cubics with absolute starts):
    one record per interval of the union of their breakpoints, continuations merged."""
    cuts = np.unique(np.r_[start, upper[:, 0], lower[:, 0]])
    cuts = cuts[(cuts >= start) & (cuts < end)]
    out = []
    for c in cuts:
        iu = max(0, int(np.searchsorted(upper[:, 0], c, side="right")) - 1)
        il = max(0, int(np.searchsorted(lower[:, 0], c, side="right")) - 1)
        cu = shift_cubic(upper[iu, 1:], c - upper[iu, 0])
        cl = shift_cubic(lower[il, 1:], c - lower[il, 0])
        out.append([c, *(cu - cl)])
    return merge_continuations(np.array(out), end)


def affine(rows: np.ndarray, scale: float = 1.0, shift: float = 0.0) -> np.ndarray:
    """Rows of ``scale * f(s) + shift``."""
    out = np.asarray(rows, dtype=np.float64).reshape(-1, 5).copy()
    out[:, 1:] *= scale
    out[:, 1] += shift
    return out


def relative(rows: np.ndarray, origin: float) -> np.ndarray:
    """Rows with their starts relative to ``origin`` (a lane section's s), as ``<width>`` wants."""
    out = np.asarray(rows, dtype=np.float64).reshape(-1, 5).copy()
    out[:, 0] -= origin
    out[np.abs(out[:, 0]) < 1e-12, 0] = 0.0
    return out


__all__ = ["affine", "difference", "evaluate_records", "interpolating_cubics", "merge_continuations",
           "relative", "shift_cubic"]
