"""SUMO runner and fitter timings: one simulation (the paper's autobahn, 1 h of demand), one objective
evaluation, one Nelder-Mead restart, and restarts on 1 vs 2 local worker processes.

The restart benchmarks use a shorter scenario (1.3 km road, 10 min of demand, 30 evaluations per
restart) so that ``make bench`` stays short; docs/fitting.md scales them to the paper's setup.
Skipped (no rows) when SUMO is not installed.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np


def _small(duration: float, seed: int):
    from aveas_format.sim import Network, Scenario, VehicleClass

    return Scenario(network=Network(length=1000, inflow=300), duration=duration, seed=seed, classes=[
        VehicleClass(name="car", flow=1680, speed_mean_kmh=131.05, speed_std_kmh=17.48),
        VehicleClass(name="truck", vclass="truck", flow=320, speed_mean_kmh=89.22, speed_std_kmh=6.2)])


def main() -> list[dict]:
    from aveas_format.sim import Scenario, SumoNotFoundError, find_sumo, simulate

    try:
        find_sumo()
    except SumoNotFoundError as e:
        print(f"bench_sim skipped: {e}", file=sys.stderr)
        return []
    from aveas_format.fit import FitConfig, evaluate, fit_desired_speed

    rows = []
    paper = Scenario(seed=1)
    simulate(paper)  # warm-up (netconvert cache, page cache)
    t0 = time.perf_counter()
    res = simulate(paper)
    t_sim = time.perf_counter() - t0
    n_veh = sum(len(v) for v in res.mean_speeds().values())
    rows.append({"benchmark": "sim paper autobahn 1 h", "seconds": round(t_sim, 3),
                 "rows_per_s": f"{res.fcd.num_rows / t_sim:,.0f}",
                 "note": f"{n_veh} vehicles, {res.fcd.num_rows:,} FCD rows, step 0.5 s"})
    t0 = time.perf_counter()
    res = simulate(paper, recording=True)
    t_rec = time.perf_counter() - t0
    rows.append({"benchmark": "sim 1 h -> recording", "seconds": round(t_rec, 3),
                 "rows_per_s": f"{res.recording.states.num_rows / t_rec:,.0f}",
                 "note": "incl. converter (map matching)"})
    ms = res.mean_speeds()
    rng = np.random.default_rng(0)
    recorded = {"car": rng.choice(ms["car"], 178, replace=False),
                "truck": rng.choice(ms["truck"], 33, replace=False)}
    for lcd in (3.0, 0.0):
        cfg = FitConfig(scenario=paper.model_copy(update={"lane_change_duration": lcd}))
        t0 = time.perf_counter()
        evaluate(np.array([130.0, 15.0, 88.0, 5.0]), cfg, recorded)
        rows.append({"benchmark": f"fit: one evaluation (1 h, lc {lcd:g} s)",
                     "seconds": round(time.perf_counter() - t0, 3),
                     "note": "simulate + KDE -ln L; lane changes taking 3 s vs instantaneous"})

    small_rec = simulate(_small(900, 7)).mean_speeds()
    small_rec = {"car": small_rec["car"][:178], "truck": small_rec["truck"][:33]}
    base = FitConfig(scenario=_small(600, 1).model_copy(update={"lane_change_duration": 0.0}),
                     maxfev=30, seed=0)
    t0 = time.perf_counter()
    fit_desired_speed(small_rec, base.model_copy(update={"restarts": 1}), figures=False)
    t_one = time.perf_counter() - t0
    rows.append({"benchmark": "fit: one restart (30 evals)", "seconds": round(t_one, 3),
                 "note": "1.3 km road, 10 min demand"})
    times = {}
    for w in (1, 2):
        t0 = time.perf_counter()
        fit_desired_speed(small_rec, base.model_copy(update={"restarts": 4}), workers=w, figures=False)
        times[w] = time.perf_counter() - t0
        rows.append({"benchmark": f"fit: 4 restarts, workers={w}", "seconds": round(times[w], 3),
                     **({"baseline_s": round(times[1], 3),
                         "speedup_vs_baseline": round(times[1] / times[w], 2)} if w > 1 else {})})
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    for r in main():
        print(r)
