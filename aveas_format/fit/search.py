"""The optimisers of the fitter, behind one interface: minimise a deterministic but rough objective
(common random numbers make -ln L a function of the parameters alone; lane changes and other
discrete decisions make it jump by small amounts) inside box bounds, within a budget of evaluations,
and say whether the search converged and why it stopped.

- ``cma`` (default): CMA-ES from the ``cma`` package (Hansen), in coordinates scaled to the unit box,
  the bounds handled by its boundary transformation. A population of candidate points per
  generation smooths over small jumps of the objective; converged when the search distribution has
  shrunk below ``xatol`` in every parameter or the population's values stay within ``fatol``;
  otherwise it stops at ``maxfev``. It ends at the distribution's mean (evaluated once more),
  which estimates the minimum of a rough objective better than the luckiest evaluated point.
- ``nelder-mead``: the paper's method (SciPy, bounded), with the initial simplex of
  :func:`initial_simplex`; converged when SciPy reports success (its ``xatol`` and ``fatol``).
- ``bayes``: Gaussian-process Bayesian optimisation (``scikit-optimize``'s ``gp_minimize``,
  expected improvement); converged when the last proposals stay within ``xatol`` of the best
  point, else stopped at ``maxfev``.

docs/fitting.md compares them on the same budget of simulations; the default follows the numbers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: the optimisers by name
METHODS = ("cma", "nelder-mead", "bayes")


@dataclass
class SearchResult:
    """The end of one search: its end point and value (the best evaluated point; CMA-ES: the
    distribution's mean), evaluations, convergence and the reason it stopped."""

    x: np.ndarray
    fun: float
    nfev: int
    converged: bool
    stop: str
    nit: int = 0
    trace: list[float] = field(default_factory=list)


class Objective:
    """``f(theta)`` with clipping to the bounds, a cache of evaluated points and a trace of values."""

    def __init__(self, fn: Callable[[np.ndarray], float], bounds: np.ndarray) -> None:
        self.fn = fn
        self.bounds = bounds
        self.cache: dict[tuple, float] = {}
        self.trace: list[float] = []
        self.best_x: np.ndarray | None = None
        self.best_f = np.inf

    def __call__(self, x: np.ndarray) -> float:
        x = np.clip(np.asarray(x, np.float64), self.bounds[:, 0], self.bounds[:, 1])
        key = tuple(np.round(x, 6))
        if key not in self.cache:
            f = float(self.fn(x))
            self.cache[key] = f
            self.trace.append(round(f, 4))
            if f < self.best_f:
                self.best_f, self.best_x = f, x.copy()
        return self.cache[key]

    @property
    def nfev(self) -> int:
        return len(self.trace)


def initial_simplex(x0: np.ndarray, bounds: np.ndarray, fraction: float) -> np.ndarray:
    """x0 plus one vertex per parameter, moved by ``fraction`` of the bound width, inwards."""
    w = (bounds[:, 1] - bounds[:, 0]) * fraction
    sim = [x0]
    for i in range(len(x0)):
        v = x0.copy()
        v[i] = x0[i] + w[i] if x0[i] + w[i] <= bounds[i, 1] else x0[i] - w[i]
        sim.append(v)
    return np.array(sim)


def minimise(method: str, f: Objective, x0: np.ndarray, *, maxfev: int, xatol, fatol: float,
             step: float, seed: int, popsize: int | None = None) -> SearchResult:
    """Run ``method`` on ``f`` from ``x0``; ``step``: the initial step as a fraction of the bound
    widths (Nelder-Mead's simplex edges, CMA-ES's sigma0, the spread of the first Bayesian points);
    ``xatol``: one tolerance or one per parameter (Nelder-Mead, whose SciPy criterion takes one,
    uses the smallest)."""
    xatol = np.broadcast_to(np.asarray(xatol, np.float64), np.shape(x0))
    if method == "nelder-mead":
        return _nelder_mead(f, x0, maxfev=maxfev, xatol=float(xatol.min()), fatol=fatol, step=step)
    if method == "cma":
        return _cma(f, x0, maxfev=maxfev, xatol=xatol, fatol=fatol, step=step, seed=seed,
                    popsize=popsize)
    if method == "bayes":
        return _bayes(f, x0, maxfev=maxfev, xatol=xatol, step=step, seed=seed)
    raise ValueError(f"method {method!r}: expected one of {', '.join(METHODS)}")


def _result(f: Objective, converged: bool, stop: str, nit: int) -> SearchResult:
    return SearchResult(np.asarray(f.best_x), float(f.best_f), f.nfev, converged, stop, nit, list(f.trace))


def _nelder_mead(f: Objective, x0: np.ndarray, *, maxfev: int, xatol: float, fatol: float,
                 step: float) -> SearchResult:
    from scipy.optimize import minimize

    b = f.bounds
    r = minimize(f, x0, method="Nelder-Mead", bounds=[tuple(v) for v in b],
                 options={"initial_simplex": initial_simplex(x0, b, step), "maxfev": maxfev,
                          "xatol": xatol, "fatol": fatol})
    stop = "xatol and fatol reached" if r.success else f"evaluation cap ({maxfev}): {r.message}"
    return _result(f, bool(r.success), stop, int(r.nit))


#: CMA-ES terminations that mean the search settled (the others: it diverged or hit a limit)
_CMA_SETTLED = ("tolx", "tolfun", "tolfunhist", "tolflatfitness", "tolstagnation")


def _tol_text(xatol: np.ndarray) -> str:
    """``0.5`` where every parameter has the same tolerance, else ``0.5, 0.5, 0.015``."""
    return f"{xatol[0]:g}" if np.all(xatol == xatol[0]) else ", ".join(f"{v:.3g}" for v in xatol)


def _cma(f: Objective, x0: np.ndarray, *, maxfev: int, xatol: np.ndarray, fatol: float, step: float,
         seed: int, popsize: int | None) -> SearchResult:
    import cma

    b = f.bounds
    lo, width = b[:, 0], b[:, 1] - b[:, 0]
    tol = xatol / width  # per parameter, in unit-box coordinates
    opts = {"bounds": [0.0, 1.0], "tolx": float(tol.min()), "tolfun": fatol, "tolfunhist": 0.0,
            "seed": int(seed) + 1, "verbose": -9, "maxfevals": np.inf}
    if popsize:
        opts["popsize"] = int(popsize)
    if len(x0) == 1:  # pycma 4.x cannot rescale a one-dimensional search to its std limits
        opts["maxstd"], opts["minstd"] = np.inf, 0.0  # ("not yet initialized"): none here
    es = cma.CMAEvolutionStrategy(np.clip((x0 - lo) / width, 1e-3, 1 - 1e-3), step, opts)
    while True:
        if np.all(es.sigma * np.sqrt(np.diag(es.C)) < tol):
            converged, stop = True, f"xatol reached (spread < {_tol_text(xatol)} in every parameter)"
            break
        stops = es.stop()
        if stops:
            converged = any(k in stops for k in _CMA_SETTLED)
            stop = ", ".join(f"{k}={v:g}" if isinstance(v, (int, float)) else k for k, v in stops.items())
            break
        if f.nfev + es.popsize > maxfev:  # the next generation would not fit in the budget
            converged, stop = False, f"evaluation cap ({maxfev})"
            break
        xs = es.ask()
        es.tell(xs, [f(lo + np.asarray(u) * width) for u in xs])
    # on a rough objective the distribution's mean estimates the minimum better than the luckiest
    # evaluated point: the restart ends there (one more evaluation). The mean in the bounds is
    # ``xfavorite`` (the boundary transformation of the internal mean, which may lie outside:
    # clipping it would put the end on a bound the search never evaluated)
    mean = lo + np.clip(np.asarray(es.result.xfavorite), 0.0, 1.0) * width
    fm = f(mean)
    return SearchResult(mean, fm, f.nfev, converged, stop, int(es.countiter), list(f.trace))


def _bayes(f: Objective, x0: np.ndarray, *, maxfev: int, xatol: np.ndarray, step: float, seed: int
           ) -> SearchResult:
    from skopt import gp_minimize

    b = f.bounds
    state = {"converged": False}

    def stopper(res) -> bool:  # the last 4 proposals all within xatol of the best point
        xs = np.asarray(res.x_iters[-4:])
        if len(res.x_iters) < 12:
            return False
        done = bool(np.all(np.abs(xs - np.asarray(res.x)) <= xatol))
        state["converged"] = done
        return done

    rng = np.random.default_rng(seed)
    width = b[:, 1] - b[:, 0]
    n_init = max(2 * len(x0) + 1, 8)
    init = [x0] + [np.clip(x0 + rng.normal(0, step, len(x0)) * width, b[:, 0], b[:, 1])
                   for _ in range(n_init - 1)]
    # the Gaussian process's matrices are tiny: threaded BLAS only oversubscribes the cores (6x
    # slower on 2 shared cores), so one thread (threadpoolctl comes with scikit-learn)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        res = gp_minimize(lambda x: f(np.asarray(x)), [tuple(v) for v in b],
                          n_calls=max(maxfev, len(init) + 1),
                          x0=[list(map(float, x)) for x in init], n_initial_points=0, acq_func="EI",
                          noise=1e-6, random_state=int(seed), callback=[stopper])
    stop = "xatol reached (the last proposals stay at the best point)" if state["converged"] \
        else f"evaluation cap ({maxfev})"
    return _result(f, state["converged"], stop, len(res.x_iters))
