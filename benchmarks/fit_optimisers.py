"""Optimisers compared on the same budget of simulations (docs/fitting.md, "Choosing the optimiser").

    python benchmarks/fit_optimisers.py [OUT.json] [--budget 120] [--workers 2] [--plan M:S:K,...]

One recording of the paper's experiment (seed 7: the paper's road and demand, 15 min, instantaneous
lane changes, random desired speeds at the paper's estimates, subsampled to 178 cars and 33 trucks)
is fitted by single searches of at most ``--budget`` simulations each (fit seed 1007):

- Nelder-Mead (the paper's) from uniform starting points and from the data start,
- CMA-ES from uniform starting points and from the data start,
- Bayesian optimisation (scikit-optimize's ``gp_minimize``) from the data start, with half the
  budget: its own cost per step (fitting the Gaussian process, optimising the acquisition) is
  measured and reported.

The reference is the response surface (``aveas_format.fit.uncertainty``) around the lowest end
point: its minimum and standard errors. Each search reports its end point's distance from the
reference in standard errors (the largest over the 4 parameters), -ln L at its end, whether it
converged and why it stopped, and its seconds (of which simulation). Searches run as tasks through
``run_tasks`` (``--workers``); ``--plan`` runs a subset (method:start:seed, comma-separated).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np


def _recording():
    from aveas_format.fit.study import paper_scenario
    from aveas_format.sim import simulate

    ms = simulate(paper_scenario().model_copy(update={"seed": 7}), fcd=False).mean_speeds()
    rng = np.random.default_rng([7, 17])
    return {"car": np.sort(rng.choice(ms["car"], 178, replace=False)),
            "truck": np.sort(rng.choice(ms["truck"], 33, replace=False))}


def _config(method: str, budget: int, seed: int):
    from aveas_format.fit import FitConfig
    from aveas_format.fit.study import paper_scenario

    return FitConfig(scenario=paper_scenario().model_copy(update={"seed": 1007}), method=method,
                     maxfev=budget, restarts=1, seed=seed, refine=False)


def search(task: dict) -> dict:
    """One search (a module-level function for run_tasks)."""
    from aveas_format.fit.optimize import evaluate
    from aveas_format.fit.search import Objective, minimise
    from aveas_format.sim import prepare_network

    cfg = _config(task["method"], task["budget"], task["seed"])
    rec = {c: np.asarray(v) for c, v in task["recorded"].items()}
    net = prepare_network(cfg.scenario.network)
    b = cfg.bounds_array()
    if task["start"] == "data":
        x0 = cfg.data_start(rec)
    else:
        x0 = b[:, 0] + np.random.default_rng(task["seed"]).random(len(b)) * (b[:, 1] - b[:, 0])
    sim_s = [0.0]

    def fn(x):
        t = time.perf_counter()
        v = evaluate(x, cfg, rec, net)[0]
        sim_s[0] += time.perf_counter() - t
        return v

    f = Objective(fn, b)
    t0 = time.perf_counter()
    r = minimise(cfg.method, f, x0, maxfev=cfg.maxfev, xatol=cfg.xatol, fatol=cfg.fatol,
                 step=cfg.simplex_fraction, seed=task["seed"])
    return {**{k: task[k] for k in ("method", "start", "seed", "budget")}, "x0": x0.tolist(),
            "x": r.x.tolist(), "fun": r.fun, "nfev": r.nfev, "converged": r.converged, "stop": r.stop,
            "seconds": time.perf_counter() - t0, "simulation_s": sim_s[0],
            "best_evaluated": float(min(r.trace))}


def main(argv: list[str]) -> dict:
    from aveas_format.fit.optimize import evaluate
    from aveas_format.fit.uncertainty import response_surface
    from aveas_format.parallel import run_tasks
    from aveas_format.sim import prepare_network

    out_path = Path(argv[0]) if argv and not argv[0].startswith("--") else None
    budget = int(argv[argv.index("--budget") + 1]) if "--budget" in argv else 120
    workers = int(argv[argv.index("--workers") + 1]) if "--workers" in argv else 2
    rec = _recording()
    rl = {c: v.tolist() for c, v in rec.items()}
    plan = [("nelder-mead", "uniform", 1), ("nelder-mead", "uniform", 2), ("nelder-mead", "data", 1),
            ("cma", "uniform", 1), ("cma", "uniform", 2), ("cma", "data", 1),
            ("bayes", "data", 1)]
    if "--plan" in argv:  # a subset, e.g. --plan cma:data:1,bayes:data:1
        plan = [(m, s, int(k)) for m, s, k in (p.split(":") for p in
                                               argv[argv.index("--plan") + 1].split(","))]
    tasks = [{"method": m, "start": s, "seed": k, "recorded": rl,
              "budget": budget // 2 if m == "bayes" else budget} for m, s, k in plan]
    rows = []
    for r in run_tasks(search, tasks, workers=workers, description="searches"):
        if r.ok:
            rows.append(r.value)
            print(json.dumps({k: v for k, v in r.value.items() if k != "x0"}), flush=True)
        else:
            print(f"failed: {r.item['method']} {r.item['start']}: {r.error}", file=sys.stderr)
    cfg = _config("cma", budget, 0)
    net = prepare_network(cfg.scenario.network)
    best = min(rows, key=lambda r: r["fun"])
    b = cfg.bounds_array()

    def evaluate_all(points, seed):  # the fit's seed only (refine_seeds = 1)
        return [evaluate(p, cfg, rec, net)[0] for p in points]

    ref = response_surface(np.array(best["x"]), (b[:, 1] - b[:, 0]) * 0.03, evaluate_all, b)
    for r in rows:
        r["distance_se"] = float(np.max(np.abs(np.array(r["x"]) - ref["x"]) / ref["se"]))
    result = {"reference": {"x": ref["x"].tolist(), "se": ref["se"].tolist(), "fun": ref["fun"],
                            "converged": ref["converged"]}, "budget": budget, "searches": rows}
    if out_path:
        out_path.write_text(json.dumps(result, indent=1))
    print(f"{'method':<12} {'start':<8} {'nfev':>5} {'conv':>5} {'-lnL':>9} {'dist/SE':>8} "
          f"{'s':>7} {'sim s':>7}  stop")
    for r in rows:
        print(f"{r['method']:<12} {r['start']:<8} {r['nfev']:>5} {str(r['converged']):>5} "
              f"{r['fun']:>9.2f} {r['distance_se']:>8.2f} {r['seconds']:>7.1f} {r['simulation_s']:>7.1f}"
              f"  {r['stop'][:60]}")
    print("reference", np.round(ref["x"], 2), "se", np.round(ref["se"], 2))
    return result


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
