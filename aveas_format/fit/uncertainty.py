"""The estimate and a standard error per fitted parameter: a quadratic response surface of -ln L
around the best restart's end (the quadratic profile likelihood).

Why a surface and not the best evaluated point: with common random numbers -ln L is a
deterministic function of the parameters, but not a smooth one. A change of 0.25 km/h in a desired
speed changes lane-change decisions, and -ln L jumps by about 0.5 (the paper's sample, 15 min of
simulated demand) while it rises by only 0.5 at one standard error from the minimum. The lowest of
many evaluations is then the luckiest jump, up to a standard error away from the minimum of the
underlying curve. A least-squares quadratic over designs spread over +-2 standard errors
averages the jumps out: its minimum is the estimate, and its curvature the observed information.

-ln L is a negative log-likelihood of the recorded values, so ``cov = H^-1`` with ``H`` the Hessian
of the fitted quadratic, and the profile likelihood of parameter ``i`` in this approximation is
``-ln L_min + (theta_i - theta_hat_i)^2 / (2 cov_ii)``: its 95 % interval is ``theta_hat_i +- 1.96
sqrt(cov_ii)``. The design is a Box-Behnken design (every pair of parameters at +-step, the others
at the centre: ``2 n (n - 1)`` simulations, 24 for the paper's 4 parameters) plus its centre, run in
parallel like the restarts; each further round (three in all) re-centres at the previous minimum
with steps of two standard errors, and the surface is fitted to the points of every round. It has
converged when the surface is positive definite and its minimum lies inside the last design.

What the interval covers: the sampling error of the recorded vehicles. The simulation's own error
(one seed) is not in it; the recovery study (:mod:`aveas_format.fit.study`) measures the coverage.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import combinations

import numpy as np


def box_behnken(n: int) -> np.ndarray:
    """Design points in [-1, 1]^n: for every pair of coordinates the four corners (+-1, +-1), the
    other coordinates 0 (``2 n (n - 1)`` points; for n = 1 the two points +-1)."""
    if n == 1:
        return np.array([[-1.0], [1.0]])
    pts = []
    for i, j in combinations(range(n), 2):
        for a in (-1.0, 1.0):
            for b in (-1.0, 1.0):
                p = np.zeros(n)
                p[i], p[j] = a, b
                pts.append(p)
    return np.array(pts)


def fit_quadratic(u: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares ``y ~ c + g.u + u' H u / 2``; returns (c, g, H)."""
    u = np.atleast_2d(u)
    n = u.shape[1]
    cols = [np.ones(len(u))] + [u[:, i] for i in range(n)]
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    cols += [u[:, i] * u[:, j] * (0.5 if i == j else 1.0) for i, j in pairs]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), y, rcond=None)
    h = np.zeros((n, n))
    for k, (i, j) in enumerate(pairs):
        h[i, j] = h[j, i] = coef[1 + n + k]
    return float(coef[0]), coef[1:1 + n], h


def response_surface(x0: np.ndarray, step: np.ndarray,
                     evaluate: Callable[[Sequence[np.ndarray]], list[float]], bounds: np.ndarray,
                     *, rounds: int = 3) -> dict:
    """Estimate the minimum of a rough objective and its curvature around ``x0``.

    ``evaluate`` maps a list of points to their -ln L (in parallel; NaN for a failed one);
    ``step``: the first design's half-width per parameter. Returns ``x`` (the estimate), ``fun``
    (the surface's value there), ``se``, ``cov``, ``converged``, ``stop``, ``step`` (of the last
    design) and ``evaluations``."""
    x0 = np.asarray(x0, np.float64)
    lo, hi = bounds[:, 0], bounds[:, 1]
    step = np.asarray(step, np.float64)
    design = np.vstack([np.zeros(len(x0)), box_behnken(len(x0))])
    pts_all: list[np.ndarray] = []
    f_all: list[float] = []
    centre = x0.copy()
    out: dict = {}
    for k in range(rounds):
        pts = np.clip(centre + design * step, lo, hi)
        f_all.extend(evaluate(list(pts)))
        pts_all.extend(pts)
        p, f = np.asarray(pts_all), np.asarray(f_all, np.float64)
        ok = np.isfinite(f)
        scale = step  # the fit in units of the current step, centred here: well conditioned
        c, g, h_u = fit_quadratic((p[ok] - centre) / scale, f[ok])
        h = h_u / np.outer(scale, scale)
        grad = g / scale
        pd = bool(np.all(np.linalg.eigvalsh(h) > 0)) if np.all(np.isfinite(h)) else False
        if pd:
            cov = np.linalg.inv(h)
            xm = centre - cov @ grad
            se = np.sqrt(np.diag(cov))
        else:
            cov = np.full_like(h, np.nan)
            xm = p[ok][np.argmin(f[ok])]
            se = np.full(len(x0), np.nan)
        inside = bool(np.all(np.abs(xm - centre) <= step * (1 + 1e-9)))
        xm_c = np.clip(xm, np.maximum(centre - 2 * step, lo), np.minimum(centre + 2 * step, hi))
        fm = float(c + (grad @ (xm_c - centre)) + 0.5 * (xm_c - centre) @ h @ (xm_c - centre))
        if pd and inside:
            stop = "the response surface is positive definite and its minimum inside the design"
        elif pd:
            stop = "the response surface's minimum lies outside the design (moved to its edge)"
        else:
            stop = "the response surface is not positive definite (no minimum resolved at this scale)"
        out = {"x": xm_c, "fun": fm, "se": se, "cov": cov, "converged": pd and inside, "stop": stop,
               "step": step.copy(), "evaluations": int(len(f_all)), "rounds": k + 1}
        if k + 1 < rounds:
            centre = np.clip(xm_c, lo, hi)
            # next steps: two standard errors; where the curvature is not resolved (not positive
            # definite: from the diagonal alone, else twice the step) wider
            diag = np.diag(h)
            guide = se if pd else np.where(diag > 0, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), np.nan)
            new = np.where(np.isfinite(guide), 2.0 * guide, step * 2.0)
            step = np.clip(new, step / 3.0, np.minimum(step * 3.0, (hi - lo) / 4))
    return out
