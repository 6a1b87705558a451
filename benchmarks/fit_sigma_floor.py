"""Where sigma_car's error comes from (docs/fitting.md, "Why sigma_car stays above the other
parameters' ratios").

    python benchmarks/fit_sigma_floor.py [OUT.json] [--seeds 30] [--fit-seeds 4] [--workers 2]

Recordings: the paper's road and demand, 15 min, random desired speeds at the paper's estimates,
seeds 1..``--seeds``, each also at sigma_car +-2 km/h with the same arrivals and standard-normal
draws (common random numbers), every car's desired speed d and mean speed v on the section.
Fit-side simulations: stratified desired speeds (as the fitter's), mu at the truth, sigma_car
13..22 km/h in steps of 1, seeds 1001..1000 + ``--fit-seeds``.

Reported, for all cars of 15 min and for the paper's 178 (4 random subsamples per recording):

- ``v = a + b d + e``: how much of a car's desired speed its mean speed keeps (b) and the spread of
  what the traffic adds (e: being held up), and how that spread varies between recordings;
- the sampling floor: the recorded cars' own desired-speed standard deviation minus the truth;
- ``d sd(v) / d sigma``: how much the mean speeds' spread moves with sigma_car (same recording);
- three estimators of sigma_car from the recorded mean speeds with mu_car at the truth (a 1-D
  profile, so only sigma_car's own difficulty counts), each against every fit seed: the paper's
  KDE likelihood with the fitter's variance correction and without (the minimum of a cubic through
  -ln L on the grid), and moment matching (the sigma at which the simulated mean speeds' standard
  deviation equals the recorded one; linear in sigma on the grid) — bias, RMSE, RMSE / floor, and
  the slope and residual of their error regressed on the floor's (the desired-speed sample's own
  error: slope 1 = the estimator follows the sample, the residual is what the mean speeds add).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

TRUTH_SIGMA = 17.48
GRID = [float(g) for g in np.arange(13.0, 22.01, 1.0)]


def simulate_cars(task: dict) -> dict:
    """One simulation (a module-level function for run_tasks): the cars' desired and mean speeds."""
    from aveas_format.fit.study import paper_scenario
    from aveas_format.sim import simulate

    base = paper_scenario().model_copy(update={"speed_sampling": task["sampling"]})
    car = base.classes[0].model_copy(update={"speed_std_kmh": task["sigma"]})
    sc = base.model_copy(update={"seed": task["seed"], "classes": [car, base.classes[1]]})
    r = simulate(sc, fcd=False, speed_factors=task["sampling"] == "random")
    out = dict(task, v=r.mean_speeds()["car"].tolist())
    if task["sampling"] == "random":  # desired speeds in the order of the mean speeds
        cross = r.section
        ids, types = cross["id"].to_pylist(), np.asarray(cross["type"].to_pylist(), dtype=object)
        dt = cross["t_out"].to_numpy(zero_copy_only=False) - cross["t_in"].to_numpy(zero_copy_only=False)
        sel = np.flatnonzero(np.isfinite(dt) & (dt > 0) & (types == "car"))
        out["d"] = [r.speed_factors[ids[i]] * car.speed_mean_kmh for i in sel]
    return out


def _estimates(vr: np.ndarray, fit: dict[float, np.ndarray]) -> dict[str, float]:
    from aveas_format.fit.objective import kde_logpdf

    grid = np.array(sorted(fit))
    fine = np.linspace(grid[0], grid[-1], 901)
    out = {}
    for key, vc in (("kde", True), ("kde_plain", False)):
        nll = [-float(kde_logpdf(fit[g], vr, "silverman", variance_correction=vc).sum()) for g in grid]
        out[key] = float(fine[np.argmin(np.polyval(np.polyfit(grid, nll, 3), fine))])
    sd = np.array([fit[g].std(ddof=1) for g in grid])
    q = np.polyfit(grid, sd, 1)
    out["moments"] = float((vr.std(ddof=1) - q[1]) / q[0])
    return out


def analyse(sims: list[dict], subsamples: int = 4, n_paper: int = 178) -> dict:
    rec = {}
    fits: dict[int, dict[float, np.ndarray]] = {}
    for s in sims:
        if s["sampling"] == "random":
            rec.setdefault(s["seed"], {})[s["sigma"]] = s
        else:
            fits.setdefault(s["seed"], {})[s["sigma"]] = np.asarray(s["v"])
    rng = np.random.default_rng(0)
    report: dict = {"recordings": len(rec), "fit_seeds": len(fits)}
    for size in ("all", "paper"):
        est: dict[str, list[float]] = {"kde": [], "kde_plain": [], "moments": []}
        floor, per_seed_sd, slope_b, resid_e, dsd = [], [], [], [], []
        for seed in sorted(rec):
            r = rec[seed]
            d, v = np.asarray(r[TRUTH_SIGMA]["d"]), np.asarray(r[TRUTH_SIGMA]["v"])
            for _ in range(subsamples if size == "paper" else 1):
                pick = rng.choice(len(v), n_paper, replace=False) if size == "paper" else np.arange(len(v))
                p = np.polyfit(d[pick], v[pick], 1)
                slope_b.append(p[0])
                resid_e.append(float(np.std(v[pick] - np.polyval(p, d[pick]), ddof=2)))
                lo, hi = r.get(TRUTH_SIGMA - 2), r.get(TRUTH_SIGMA + 2)
                if lo and hi and len(lo["v"]) == len(v) == len(hi["v"]):
                    dsd.append((np.asarray(hi["v"])[pick].std(ddof=1) - np.asarray(lo["v"])[pick].std(ddof=1)) / 4)
                one = []
                for f in sorted(fits):
                    e = _estimates(v[pick], fits[f])
                    for k in est:
                        est[k].append(e[k] - TRUTH_SIGMA)
                    floor.append(float(d[pick].std(ddof=1)) - TRUTH_SIGMA)
                    one.append(e["kde"])
                per_seed_sd.append(float(np.std(one, ddof=1)) if len(one) > 1 else np.nan)
        fl = np.asarray(floor)
        floor_rmse = float(np.sqrt(np.mean(fl ** 2)))
        row: dict = {"floor_rmse": floor_rmse, "b": float(np.mean(slope_b)),
                     "sd_e": float(np.mean(resid_e)), "sd_e_between_recordings": float(np.std(resid_e, ddof=1)),
                     "dsd_v_dsigma": float(np.mean(dsd)) if dsd else None,
                     "kde_sd_between_fit_seeds": float(np.nanmean(per_seed_sd)) if len(fits) > 1 else None,
                     "estimators": {}}
        for k, e in est.items():
            e = np.asarray(e)
            p = np.polyfit(fl, e, 1)
            rmse = float(np.sqrt(np.mean(e ** 2)))
            row["estimators"][k] = {"bias": float(e.mean()), "rmse": rmse, "rmse_ratio": rmse / floor_rmse,
                                    "slope_on_floor": float(p[0]),
                                    "residual_sd": float(np.std(e - np.polyval(p, fl), ddof=2))}
        report[size] = row
    return report


def main(argv: list[str]) -> dict:
    from aveas_format.parallel import run_tasks

    def opt(name: str, default: int) -> int:
        return int(argv[argv.index(name) + 1]) if name in argv else default

    seeds, fit_seeds, workers = opt("--seeds", 30), opt("--fit-seeds", 4), opt("--workers", 2)
    tasks = [{"sampling": "random", "seed": k, "sigma": TRUTH_SIGMA + ds} for k in range(1, seeds + 1)
             for ds in (-2.0, 0.0, 2.0)]
    tasks += [{"sampling": "stratified", "seed": 1000 + k, "sigma": g} for k in range(1, fit_seeds + 1)
              for g in GRID]
    sims = []
    for r in run_tasks(simulate_cars, tasks, workers=workers):
        if r.error:
            raise SystemExit(f"simulation failed: {r.error}")
        sims.append(r.value)
    report = analyse(sims)
    print(json.dumps(report, indent=1))
    if argv and not argv[0].startswith("--"):
        Path(argv[0]).write_text(json.dumps(report, indent=1))
    return report


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main(sys.argv[1:])
