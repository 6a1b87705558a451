"""Scaling of the fitter on a Dask cluster started from the command line (docs/performance.md).

    python benchmarks/fit_dask_scaling.py [--repeats 2] [--restarts 4] [--maxfev 24]

Starts ``dask scheduler`` on loopback and then 1 or 2 ``dask worker`` processes (``--nworkers 1
--nthreads 1`` each, so one worker process = one core), exactly as a user would from a shell, and
times the same fit on each cluster size: ``--restarts`` CMA-ES restarts of ``--maxfev``
evaluations each (the paper's demand and desired speeds on a 1.3 km road, 10 min of demand, no
response surface), scheduled through ``aveas_format.parallel.run_tasks`` (``--scheduler``). The
workers are warmed up first (they import the package and build the network), and the sizes are
interleaved (1, 2, 1, 2, ...) so that both see the same background load; the load average is
printed with every run. Efficiency = T(1) / (2 x T(2)); the goal is >= 0.8.
"""

from __future__ import annotations

import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DASK = str(Path(sys.executable).with_name("dask"))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """``dask scheduler`` + N ``dask worker`` processes on loopback (terminated on exit)."""

    def __init__(self, n_workers: int) -> None:
        self.n = n_workers
        self.port = _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []

    def __enter__(self) -> Cluster:
        from distributed import Client

        log = open(os.devnull, "wb")  # noqa: SIM115 — closed with the processes
        self.procs.append(subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port",
                                            str(self.port), "--no-dashboard"], stdout=log, stderr=log))
        for _ in range(self.n):
            self.procs.append(subprocess.Popen([DASK, "worker", self.address, "--nworkers", "1",
                                                "--nthreads", "1", "--no-dashboard",
                                                "--host", "127.0.0.1"], stdout=log, stderr=log))
        deadline = time.time() + 120
        while True:
            try:
                with Client(self.address, timeout=5) as c:
                    if len(c.scheduler_info()["workers"]) == self.n:
                        break
            except OSError:
                pass
            if time.time() > deadline:
                raise RuntimeError("the Dask cluster did not come up")
            time.sleep(0.5)
        return self

    def __exit__(self, *exc) -> None:
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def _workload(restarts: int, maxfev: int):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from helpers_sim import NARROW, small_scenario

    from aveas_format.fit import FitConfig
    from aveas_format.sim import simulate

    ms = simulate(small_scenario(duration=900, seed=7, lane_change_duration=0), fcd=False).mean_speeds()
    rng = np.random.default_rng(7)
    rec = {"car": rng.choice(ms["car"], 178, replace=False), "truck": rng.choice(ms["truck"], 33,
                                                                                   replace=False)}
    cfg = FitConfig(scenario=small_scenario(duration=600, lane_change_duration=0), bounds=NARROW,
                    restarts=restarts, maxfev=maxfev, refine=False, starts="uniform", seed=5)
    return rec, cfg


def main(argv: list[str]) -> list[dict]:
    from aveas_format.fit import fit_parameters

    def opt(name: str, default: int) -> int:
        return int(argv[argv.index(name) + 1]) if name in argv else default

    repeats, restarts, maxfev = opt("--repeats", 2), opt("--restarts", 4), opt("--maxfev", 24)
    rec, cfg = _workload(restarts, maxfev)
    times: dict[int, list[float]] = {1: [], 2: []}
    for rep in range(repeats):
        for n in (1, 2):
            with Cluster(n) as cl:
                fit_parameters(rec, cfg.model_copy(update={"restarts": n}), scheduler=cl.address,
                               figures=False)  # warm-up: imports, network
                load0 = os.getloadavg()[0]
                t0 = time.perf_counter()
                res = fit_parameters(rec, cfg, scheduler=cl.address, figures=False)
                t = time.perf_counter() - t0
                assert len(res.runs) == restarts and not res.failed, res.failed
            times[n].append(t)
            print(f"repeat {rep}: {n} worker(s): {t:.1f} s  ({sum(r['nfev'] for r in res.runs)} "
                  f"evaluations; load average {load0:.2f} -> {os.getloadavg()[0]:.2f})", flush=True)
    t1, t2 = statistics.median(times[1]), statistics.median(times[2])
    eff = t1 / (2 * t2)
    pairs = [a / (2 * b) for a, b in zip(times[1], times[2], strict=True)]
    print(f"median: 1 worker {t1:.1f} s, 2 workers {t2:.1f} s: speed-up {t1 / t2:.2f}x, "
          f"efficiency {eff:.2f} (per repeat: {', '.join(f'{p:.2f}' for p in pairs)}); goal >= 0.8")
    return [{"benchmark": "fit on dask: 2 vs 1 worker", "seconds": round(t2, 2), "baseline_s": round(t1, 2),
             "speedup_vs_baseline": round(t1 / t2, 2), "note": f"efficiency {eff:.2f}"}]


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
