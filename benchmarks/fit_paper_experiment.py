"""The paper's experiment with the default fitter, timed (docs/fitting.md, "The paper's experiment").

    python benchmarks/fit_paper_experiment.py OUTDIR [--workers 2] [--seed 7]

The "recording": the paper's road (1.5 km inflow + 4 km) and demand (1,680 cars/h, 320 trucks/h),
15 min, instantaneous lane changes, random desired speeds at the paper's estimates (mu_car 131.05,
sigma_car 17.48, mu_truck 89.22, sigma_truck 6.20 km/h), seed ``--seed``; the vehicles' mean speeds
on the measurement section, subsampled to the paper's 178 cars and 33 trucks. The fit: the default
``FitConfig`` (4 CMA-ES restarts of <= 200 evaluations, the first from the data, then the response
surface) with the same scenario and another seed, on ``--workers`` processes. Writes OUTDIR (the
fit's runs.parquet, best.json, figures) and prints the wall time, the CPU seconds (this process,
its workers and their SUMO runs), the load, the estimate, its standard errors, convergence and how
the restarts agreed. The figures in docs/figures/fit_*.png come from this run.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np


def _cpu_seconds() -> float:
    """User + system CPU seconds of this process and its finished children (the worker processes
    and their SUMO runs, counted once the pool has ended)."""
    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def main(argv: list[str]) -> dict:
    from aveas_format.fit import FitConfig, fit_parameters
    from aveas_format.fit.study import PAPER_SAMPLE, PAPER_TRUTH, paper_scenario
    from aveas_format.sim import simulate

    out = Path(argv[0])
    workers = int(argv[argv.index("--workers") + 1]) if "--workers" in argv else 2
    seed = int(argv[argv.index("--seed") + 1]) if "--seed" in argv else 7
    ms = simulate(paper_scenario().model_copy(update={"seed": seed}), fcd=False).mean_speeds()
    rng = np.random.default_rng(seed)
    rec = {c: rng.choice(ms[c], PAPER_SAMPLE[c], replace=False) for c in ("car", "truck")}
    cfg = FitConfig(scenario=paper_scenario().model_copy(update={"seed": 1000 + seed}))
    load0 = os.getloadavg()
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    res = fit_parameters(rec, cfg, workers=workers, outdir=out)
    wall = time.perf_counter() - t0
    cpu = _cpu_seconds() - cpu0
    s = res.summary()
    report = {"wall_s": round(wall, 1), "workers": workers, "load_before": load0,
              "load_after": os.getloadavg(), "cpu_s": round(cpu, 1),
              # what 2 idle cores would need at this CPU time if the work split evenly
              "cpu_s_per_worker": round(cpu / workers, 1), "truth": PAPER_TRUTH,
              "estimate": {n: round(s[n], 2) for n in cfg.names}, "se": s["se"],
              "converged": s["converged"], "stop": s["stop"], "evaluations": s["evaluations"],
              "restarts": [{n: round(r[n], 2) for n in cfg.names} | {
                  "fun": round(r["fun"], 2), "nfev": r["nfev"], "converged": r["converged"],
                  "stop": r["stop"]} for r in res.runs],
              "restarts_agreeing": s["restarts_agreeing"]}
    print(json.dumps(report, indent=1))
    (out / "experiment.json").write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
