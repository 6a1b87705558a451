"""Sensitivity of TTC to the Wiedemann 99 parameters (the paper's table "Variation of Wiedemann99
parameters" and figure "WiedemannPara").

Each parameter cc0..cc9 is varied alone over its range (:data:`~aveas_format.sim.scenario.W99_RANGES`)
while the others keep Vissim's defaults; the varied values apply to a subset of the cars (a class
``<car>_mod`` that takes ``fraction`` of the car flow). Each run goes through the converter into a
recording, ``derive(only=["kinematics", "interactions"])`` gives the TTC of every follower to its
lane leader, and per value the study reports

- ``min_mean_ttc``: the smallest per-vehicle mean TTC among the altered vehicles (those with at
  least ``min_ttc_samples`` TTC samples; default 1, every vehicle), and
- ``min_ttc``: the smallest TTC of an altered vehicle in any time step.

Runs are independent tasks through :func:`aveas_format.parallel.run_tasks`. The figure is drawn by
:func:`aveas_format.plot.sensitivity.plot_sensitivity` (``aveas-format sim sensitivity`` writes both).
"""

from __future__ import annotations

import numpy as np

from aveas_format.sim.scenario import W99_RANGES, Scenario


def modified_scenario(base: Scenario, param: str, value: float, *, car: str = "car",
                      fraction: float = 0.2) -> Scenario:
    s = base.model_copy(deep=True)
    c = s.cls(car)
    mod = c.model_copy(deep=True)
    mod.name = f"{car}_mod"
    mod.flow = c.flow * fraction
    mod.cf_params = {**mod.cf_params, param: float(value)}
    c.flow = c.flow * (1 - fraction)
    s.classes.append(mod)
    return s


def ttc_stats(task: dict) -> dict:
    """Run one variation and return its TTC statistics (module-level: runs in workers)."""
    import pyarrow.compute as pc

    from aveas_format.derive import derive
    from aveas_format.sim.runner import simulate

    sc = Scenario.model_validate(task["scenario"])
    mod_name = task["mod_class"]
    res = simulate(sc, recording=True)
    rec = res.recording
    derive(rec, only=["kinematics", "interactions"], interactions={"box_2d": False})
    it = rec.derived["interactions"]
    attrs = rec.participants["attributes"].to_pylist()
    import json

    mod_ids = {pid for pid, a in zip(rec.participants["participant_id"].to_pylist(), attrs, strict=True)
               if a and json.loads(a).get("sumo_type") == mod_name}
    t = it.filter(pc.equal(it["relation"], "leader"))
    pid = t["participant_id"].to_numpy()
    ttc = t["ttc"].to_numpy(zero_copy_only=False)
    ok = np.isfinite(ttc) & (ttc > 0) & np.isin(pid, list(mod_ids))
    return {"param": task["param"], "value": task["value"], "n_altered": len(mod_ids),
            **ttc_summary(pid[ok], ttc[ok], int(task.get("min_ttc_samples", 1)))}


def ttc_summary(pid: np.ndarray, ttc: np.ndarray, min_samples: int = 1) -> dict:
    """``min_ttc`` over all samples; ``min_mean_ttc`` over the per-vehicle mean TTCs of the
    vehicles with at least ``min_samples`` TTC samples (a vehicle with one short closing-in event
    otherwise decides the statistic alone); NaN where there are none."""
    out = {"n_ttc_samples": int(len(ttc)), "min_ttc": float(ttc.min()) if len(ttc) else float("nan"),
           "min_mean_ttc": float("nan"), "n_vehicles_mean": 0}
    if len(ttc):
        _, inv, counts = np.unique(pid, return_inverse=True, return_counts=True)
        means = np.bincount(inv, weights=ttc) / counts
        keep = counts >= min_samples
        out["n_vehicles_mean"] = int(keep.sum())
        if keep.any():
            out["min_mean_ttc"] = float(means[keep].min())
    return out


def sensitivity(base: Scenario | None = None, *, params: list[str] | None = None, n_values: int = 5,
                car: str = "car", fraction: float = 0.2, workers: int | None = 1,
                scheduler: str | None = None, progress: bool = False,
                min_ttc_samples: int = 1) -> list[dict]:
    """One row per (parameter, value): ``min_mean_ttc``, ``min_ttc`` (s); failed runs carry ``error``.
    ``min_ttc_samples``: TTC samples a vehicle needs for its mean to count (see :func:`ttc_summary`)."""
    from aveas_format.parallel import run_tasks

    base = base or Scenario()
    params = params or list(W99_RANGES)
    tasks = []
    for p in params:
        if p not in W99_RANGES:
            raise ValueError(f"unknown W99 parameter {p!r} (cc0..cc9)")
        lo, hi = W99_RANGES[p]
        for v in np.linspace(lo, hi, n_values):
            sc = modified_scenario(base, p, float(v), car=car, fraction=fraction)
            tasks.append({"scenario": sc.model_dump(mode="json"), "param": p, "value": float(v),
                          "mod_class": f"{car}_mod", "min_ttc_samples": int(min_ttc_samples)})
    rows = []
    for r in run_tasks(ttc_stats, tasks, workers=workers, scheduler=scheduler, progress=progress,
                       description="sensitivity"):
        rows.append(r.value if r.ok else {"param": r.item["param"], "value": r.item["value"],
                                          "error": r.error})
    rows.sort(key=lambda r: (r["param"], r["value"]))
    return rows
