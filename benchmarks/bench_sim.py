"""SUMO runner and fitter timings: where one objective evaluation of the paper's experiment spends
its time, next to SUMO's own run time.

The paper's setup: its autobahn (1.5 km inflow + 4 km), 1,680 cars/h + 320 trucks/h, 15 min of
demand per evaluation (the run drains until every vehicle has left). For lane changes that take
3 s (the runner's default) and instantaneous ones (``lane_change_duration = 0``):

- ``SUMO alone``: the ``sumo`` process with the evaluation's network and routes, writing nothing
  (the baseline: what the simulation itself costs);
- ``evaluation``: what one evaluation costs now (routes, SUMO writing the section crossings,
  reading them, per-vehicle mean speeds, KDE -ln L), and its ratio to SUMO alone (goal <= 1.3x);
- ``evaluation, FCD path``: the previous way (SUMO writing FCD of every vehicle and step, read back
  from Parquet, mean speeds from the FCD), for comparison;
- per stage (``python benchmarks/bench_sim.py --profile`` prints the breakdown): netconvert (once
  per fit), writing the routes, SUMO, reading its output, the per-vehicle metric, the KDE.

Each number is the median of ``REPEATS`` runs in this process. Skipped (no rows) when SUMO is not
installed.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPEATS = 5


def _median(fn, n: int = REPEATS) -> tuple[float, object]:
    times, out = [], None
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def profile(lane_change_duration: float, repeats: int = REPEATS) -> dict[str, float]:
    """Seconds per stage of one evaluation (medians), SUMO alone, and the FCD path's total."""
    from aveas_format.fit import FitConfig, recorded_mean_speeds  # noqa: F401 — import cost outside
    from aveas_format.fit.objective import neg_log_likelihood
    from aveas_format.fit.study import paper_scenario
    from aveas_format.sim import find_sumo, prepare_network, simulate
    from aveas_format.sim.runner import _NET_CACHE, _sumo_env


    base = paper_scenario(900.0, lane_change_duration).model_copy(update={"seed": 1})
    rec = simulate(base.model_copy(update={"seed": 7}), fcd=False).mean_speeds()
    rng = np.random.default_rng(0)
    recorded = {"car": rng.choice(rec["car"], 178, replace=False),
                "truck": rng.choice(rec["truck"], 33, replace=False)}
    cfg = FitConfig(scenario=base)
    sc = cfg.scenario_at(np.array([130.0, 16.0, 89.0, 6.0]))
    _NET_CACHE.clear()
    t_net, net = _median(lambda: (_NET_CACHE.clear(), prepare_network(sc.network))[1], 1)
    out: dict[str, float] = {"netconvert (once per fit)": t_net}
    stages: dict[str, list[float]] = {}
    totals, fcd_totals, alone = [], [], []
    sumo = find_sumo("sumo")
    with tempfile.TemporaryDirectory() as d:  # SUMO alone: the same network and routes, no output
        wd = Path(d)
        net.write(wd)
        (wd / "routes.rou.xml").write_text(sc.routes_xml(net.from_edge, net.to_edge))
        cmd = [str(sumo), "-n", "net.net.xml", "-r", "routes.rou.xml", "--step-length", "0.5",
               "--seed", "1", "--no-step-log", "true"]
        if lane_change_duration > 0:
            cmd += ["--lanechange.duration", f"{lane_change_duration:g}"]
        for _ in range(repeats):  # interleaved, so that all three see the same load
            t0 = time.perf_counter()
            subprocess.run(cmd, cwd=wd, capture_output=True, check=True, env=_sumo_env(sumo))
            alone.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            res = simulate(sc, fcd=False, network=net)
            t1 = time.perf_counter()
            ms = res.mean_speeds()
            t2 = time.perf_counter()
            neg_log_likelihood(recorded, ms, variance_correction=True)
            t3 = time.perf_counter()
            totals.append(t3 - t0)
            for k, v in res.timings.items():
                stages.setdefault(k, []).append(v)
            stages.setdefault("metric", []).append(t2 - t1)
            stages.setdefault("kde", []).append(t3 - t2)
            stages.setdefault("other (temp dir, log)", []).append((t1 - t0) - sum(res.timings.values()))
            t0 = time.perf_counter()
            full = simulate(sc, fcd=True, network=net)
            neg_log_likelihood(recorded, full.mean_speeds(), variance_correction=True)
            fcd_totals.append(time.perf_counter() - t0)
            stages.setdefault("fcd: sumo", []).append(full.timings["sumo"])
            stages.setdefault("fcd: read", []).append(full.timings["read"])
    for k, v in stages.items():
        out[k] = statistics.median(v)
    out["evaluation"] = statistics.median(totals)
    out["evaluation, FCD path"] = statistics.median(fcd_totals)
    out["SUMO alone"] = statistics.median(alone)
    out["evaluation / SUMO alone (median of ratios)"] = statistics.median(
        t / a for t, a in zip(totals, alone, strict=True))
    out["vehicles"] = float(sum(len(v) for v in ms.values()))
    return out


def main() -> list[dict]:
    from aveas_format.sim import SumoNotFoundError, find_sumo

    try:
        find_sumo()
    except SumoNotFoundError as e:
        print(f"bench_sim skipped: {e}", file=sys.stderr)
        return []
    rows = []
    for lcd in (3.0, 0.0):
        p = profile(lcd)
        tag = f"lc {lcd:g} s"
        note = f"paper's road, 15 min of demand, {p['vehicles']:.0f} vehicles"
        rows.append({"benchmark": f"SUMO alone ({tag})", "seconds": round(p["SUMO alone"], 3),
                     "note": note + ", no output"})
        rows.append({"benchmark": f"fit evaluation ({tag})", "seconds": round(p["evaluation"], 3),
                     "baseline_s": round(p["SUMO alone"], 3),
                     "speedup_vs_baseline": round(p["SUMO alone"] / p["evaluation"], 2),
                     "note": f"= {p['evaluation / SUMO alone (median of ratios)']:.2f}x SUMO alone "
                             "(median of interleaved pairs; goal <= 1.3x)"})
        rows.append({"benchmark": f"fit evaluation, FCD ({tag})",
                      "seconds": round(p["evaluation, FCD path"], 3),
                      "baseline_s": round(p["SUMO alone"], 3),
                      "speedup_vs_baseline": round(p["SUMO alone"] / p["evaluation, FCD path"], 2),
                      "note": "the previous path: FCD of every vehicle and step"})
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    if "--profile" in sys.argv:
        for lcd in (3.0, 0.0):
            print(f"# one evaluation, lane changes {lcd:g} s (medians of {REPEATS}, seconds)")
            p = profile(lcd)
            for k, v in p.items():
                print(f"{k:<30} {v:8.4f}")
    else:
        for r in main():
            print(r)
