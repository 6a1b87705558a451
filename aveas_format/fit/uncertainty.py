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

**The simulation's seed.** Another simulation seed (other arrivals, other vehicles held up
behind slower ones) moves the minimum too. With ``seeds = S > 1`` a last round evaluates the design
around the estimate under ``S - 1`` further seeds, and the surface is fitted to every point with
one intercept and one gradient per seed and a common Hessian: each seed's minimum is
``x_r = centre - H^-1 g_r``, the estimate is their mean (the seed's noise divided by ``S``), and
the seed's part of the covariance is ``cov_r(x_r) / S`` (from ``S - 1`` degrees of freedom).

**The sampling part: a parametric bootstrap.** ``H^-1`` is the sampling covariance only if the
recorded values were independent draws of the simulated distribution; vehicles held up by the same
slow vehicle are not, and the curvature then understates the error (most for sigma_car). With
``resample`` the fitter simulates B recordings at the estimate (random desired speeds, the
recorded number of vehicles), computes each one's -ln L at every design point from the simulated
values already there, and minimises it on the same surface (``centre - H^-1 g_b``): the covariance
of these minima is the sampling part, their mean minus the estimate the estimator's bias, which
``bias_correction`` subtracts (an option: in the recovery study it removed sigma_car's +0.5 km/h
at the paper's sample size and made no difference with every vehicle of 15 min).
``cov = cov_bootstrap + cov_seed / S``. The recovery study (:mod:`aveas_format.fit.study`)
measures the coverage.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from itertools import combinations

import numpy as np


#: bootstrap replicates below which the estimate is not bias-corrected (the bias's own noise,
#: sd / sqrt(B), would then be a sizeable part of the standard error)
MIN_BIAS_REPLICATES = 20


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
    c, g, h = fit_quadratic_blocks(u, y, np.zeros(len(np.atleast_2d(u)), np.int64))
    return float(c[0]), g[0], h


def fit_quadratic_blocks(u: np.ndarray, y: np.ndarray, block: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ``y ~ c_b + g_b.u + u' H u / 2`` with an intercept and a gradient per block
    ``b = 0 .. B-1`` (one per simulation seed) and a common Hessian; returns (c[B], g[B, n], H).
    With ``y`` of shape (points, m) every column is fitted alike: (c[B, m], g[B, n, m], H[n, n, m])."""
    u = np.atleast_2d(u)
    n = u.shape[1]
    block = np.asarray(block, np.int64)
    nb = int(block.max()) + 1 if len(block) else 1
    cols = []
    for b in range(nb):
        ind = (block == b).astype(np.float64)
        cols += [ind] + [ind * u[:, i] for i in range(n)]
    pairs = [(i, j) for i in range(n) for j in range(i, n)]
    cols += [u[:, i] * u[:, j] * (0.5 if i == j else 1.0) for i, j in pairs]
    coef, *_ = np.linalg.lstsq(np.column_stack(cols), y, rcond=None)
    per = coef[:nb * (n + 1)].reshape(nb, n + 1, *coef.shape[1:])
    h = np.zeros((n, n, *coef.shape[1:]))
    for k, (i, j) in enumerate(pairs):
        h[i, j] = h[j, i] = coef[nb * (n + 1) + k]
    return per[:, 0], per[:, 1:], h


def response_surface(x0: np.ndarray, step: np.ndarray,
                     evaluate: Callable[[Sequence[np.ndarray], int], list[float]], bounds: np.ndarray,
                     *, rounds: int = 3, seeds: int = 1,
                     resample: Callable[[np.ndarray], np.ndarray] | None = None,
                     min_se: np.ndarray | None = None, bias_correction: bool = False) -> dict:
    """Estimate the minimum of a rough objective and its curvature around ``x0``.

    ``evaluate(points, r)`` maps a list of points to their -ln L (in parallel; NaN for a failed one)
    under simulation seed number ``r`` (0: the fit's own; ``1 .. seeds - 1``: the further seeds of
    the last round, see the module docstring); ``step``: the first design's half-width per
    parameter. ``resample(x)``: the parametric bootstrap — -ln L of B recordings simulated at the
    estimate ``x``, at every point evaluated so far (in the order evaluated; shape (points, B));
    each bootstrap recording's minimum on the same surface gives the sampling covariance.
    ``min_se``: a lower bound of the sampling part's standard errors (NaN: none), applied to the
    result (the designs' steps follow the surface's own). ``bias_correction``: the estimate is the
    minimum minus the bootstrap's bias (with at least :data:`MIN_BIAS_REPLICATES` replicates).

    Returns ``x`` (the estimate), ``minimum`` (the surface's minimum: ``x`` unless bias-corrected),
    ``bias_corrected``, ``fun`` (the surface's value at its minimum), ``se``, ``cov``,
    ``se_sampling`` (the recorded sample's part: the bootstrap's, else ``sqrt(diag(H^-1))``),
    ``se_information`` (``sqrt(diag(H^-1))``), ``se_seed`` (the simulation seed's part; NaN with
    one seed), ``seed_minima`` (one minimum per seed; none when the surface is not positive
    definite), ``bootstrap`` (replicates, their mean minus the estimate: the estimator's bias),
    ``converged``, ``stop``, ``step`` (of the last design), ``seeds``, ``rounds`` and
    ``evaluations``."""
    x0 = np.asarray(x0, np.float64)
    n = len(x0)
    lo, hi = bounds[:, 0], bounds[:, 1]
    step = np.asarray(step, np.float64)
    design = np.vstack([np.zeros(n), box_behnken(n)])
    pts_all: list[np.ndarray] = []
    f_all: list[float] = []
    blk_all: list[int] = []
    centre = x0.copy()
    out: dict = {}
    total = rounds + (1 if seeds > 1 else 0)
    for k in range(total):
        pts = np.clip(centre + design * step, lo, hi)
        # the rounds under the fit's seed, then one round under each further seed
        for r in (range(1, seeds) if k >= rounds else (0,)):
            f_all.extend(evaluate(list(pts), r))
            pts_all.extend(pts)
            blk_all.extend([r] * len(pts))
        p, f, blk = np.asarray(pts_all), np.asarray(f_all, np.float64), np.asarray(blk_all)
        ok = np.isfinite(f)
        scale = step  # the fit in units of the current step, centred here: well conditioned
        u = (p[ok] - centre) / scale
        present = np.unique(blk[ok])
        remap = np.searchsorted(present, blk[ok])
        c, g, h_u = fit_quadratic_blocks(u, f[ok], remap)
        h = h_u / np.outer(scale, scale)
        grads = g / scale  # one gradient per seed
        pd = bool(np.all(np.linalg.eigvalsh(h) > 0)) if np.all(np.isfinite(h)) else False
        cov_seed = cov_information = np.full((n, n), np.nan)
        boot: dict = {}
        if pd:
            cov_information = np.linalg.inv(h)
            minima = centre - grads @ cov_information  # x_r = centre - H^-1 g_r (H symmetric)
            xm = minima.mean(axis=0)
            cov_sampling = cov_information
            if resample is not None and k + 1 == total:
                boot = _bootstrap(resample, xm, u, ok, remap, scale, centre, cov_information)
                if boot:
                    cov_sampling = boot.pop("cov")
            cov = cov_sampling.copy()
            if len(minima) > 1:
                cov_seed = np.atleast_2d(np.cov(minima.T, ddof=1)) / len(minima)
                cov = cov + cov_seed
            se = np.sqrt(np.diag(cov))
        else:
            cov = cov_sampling = np.full((n, n), np.nan)
            xm = p[ok][np.argmin(f[ok])]
            minima = np.empty((0, n))  # no minimum per seed without a positive-definite surface
            se = np.full(n, np.nan)
        inside = bool(np.all(np.abs(xm - centre) <= step * (1 + 1e-9)))
        xm_c = np.clip(xm, np.maximum(centre - 2 * step, lo), np.minimum(centre + 2 * step, hi))
        d = xm_c - centre
        fm = float(np.mean(c) + (grads.mean(axis=0) @ d) + 0.5 * d @ h @ d)
        if pd and inside:
            stop = "the response surface is positive definite and its minimum inside the design"
        elif pd:
            stop = "the response surface's minimum lies outside the design (moved to its edge)"
        else:
            stop = "the response surface is not positive definite (no minimum resolved at this scale)"
        if pd and min_se is not None:  # the sampling part not below its bound
            d_se = np.sqrt(np.diag(cov_sampling))
            f_up = np.where(np.isfinite(min_se) & (d_se < min_se), min_se / d_se, 1.0)
            cov_sampling = cov_sampling * np.outer(f_up, f_up)
            cov = cov_sampling + np.where(np.isfinite(cov_seed), cov_seed, 0.0)
            se_out = np.sqrt(np.diag(cov))
        else:
            se_out = se
        x_est, corrected = xm_c, False
        if bias_correction and boot and boot["replicates"] >= MIN_BIAS_REPLICATES:
            x_est, corrected = np.clip(xm_c - boot["bias"], lo, hi), True
        out = {"x": x_est, "minimum": xm_c, "bias_corrected": corrected, "fun": fm, "se": se_out, "cov": cov,
               "se_sampling": np.sqrt(np.diag(cov_sampling)), "se_seed": np.sqrt(np.diag(cov_seed)),
               "se_information": np.sqrt(np.diag(cov_information)), "bootstrap": boot,
               "seed_minima": minima, "seeds": int(len(present)), "converged": pd and inside,
               "stop": stop, "step": step.copy(), "evaluations": int(len(f_all)), "rounds": k + 1}
        if k + 1 < total:
            centre = np.clip(xm_c, lo, hi)
            # next steps: two standard errors; where the curvature is not resolved (not positive
            # definite: from the diagonal alone, else twice the step) wider
            diag = np.diag(h)
            guide = se if pd else np.where(diag > 0, 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), np.nan)
            new = np.where(np.isfinite(guide), 2.0 * guide, step * 2.0)
            step = np.clip(new, step / 3.0, np.minimum(step * 3.0, (hi - lo) / 4))
    return out


def _bootstrap(resample, x: np.ndarray, u: np.ndarray, ok: np.ndarray, remap: np.ndarray,
               scale: np.ndarray, centre: np.ndarray, h_inv: np.ndarray) -> dict:
    """The parametric bootstrap on the fitted surface: -ln L of each recording simulated at ``x``
    over the same design points, its gradient per seed (the surface's Hessian kept), its minimum
    ``centre - H^-1 g_b``; the covariance of those minima, their number and mean - ``x``."""
    y = np.asarray(resample(x), np.float64)
    if y.ndim != 2 or y.shape[1] < 3:
        return {}
    y = y[ok]
    good = np.all(np.isfinite(y), axis=0)
    if good.sum() < 3:
        return {}
    _, g, _ = fit_quadratic_blocks(u, y[:, good], remap)  # g: (seeds, n, B)
    minima = centre - (h_inv @ (g.mean(axis=0) / scale[:, None])).T
    return {"cov": np.atleast_2d(np.cov(minima.T, ddof=1)), "replicates": int(good.sum()),
            "bias": minima.mean(axis=0) - x}
