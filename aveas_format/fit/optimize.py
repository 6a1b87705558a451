"""Fit simulation parameters to recorded per-vehicle metrics: the paper's desired-speed
distributions N(mu, sigma) per class against mean speeds (the default), or W99 car-following
parameters against time headways, minimum TTCs or acceleration spreads (``FitConfig.metric`` and
``FitConfig.parameters``).

>>> from aveas_format.fit import FitConfig, fit_parameters
>>> result = fit_parameters({"car": v_car, "truck": v_truck}, FitConfig(restarts=100),
...                         workers=8, outdir="fit-out")                         # doctest: +SKIP
>>> result.best                                                                  # doctest: +SKIP
>>> fit_parameters(headways, FitConfig(metric="time_headway", parameters=["cc1_car"]),
...                outdir="fit-cc1")                                             # doctest: +SKIP

Nelder-Mead (SciPy) minimises -ln L (:mod:`.objective`) from ``restarts`` starting points drawn
uniformly from the bounds; the initial simplex has edges of ``simplex_fraction`` x the bound widths
(pointing inwards), the bounds are enforced by SciPy's bounded Nelder-Mead (points are clipped).
Each evaluation runs SUMO with the same seed (common random numbers: same arrivals and same
standard-normal draw per vehicle), so the objective is a smooth-ish deterministic function.

Restarts are independent tasks run through :func:`aveas_format.parallel.run_tasks` (in-process,
local processes or a Dask cluster). Each finished restart is appended to ``OUTDIR/runs.jsonl`` at
once, so an interrupted fit resumes where it stopped (restarts already stored are skipped);
``runs.parquet``, ``best.json`` and the figures are written at the end.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from aveas_format.fit.objective import neg_log_likelihood
from aveas_format.safeio import write_parquet_atomic, write_text_atomic
from aveas_format.sim.scenario import W99_DEFAULTS, W99_RANGES, Scenario


class FitConfig(BaseModel):
    """What to fit and how."""

    model_config = ConfigDict(extra="forbid")

    scenario: Scenario = Field(default_factory=Scenario, description="the simulation; its classes' "
                               "mu/sigma are replaced by the parameters")
    classes: list[str] = Field(default_factory=lambda: ["car", "truck"])
    bounds: dict[str, tuple[float, float]] = Field(default_factory=lambda: {
        "mu_car": (100.0, 160.0), "sigma_car": (2.0, 30.0),
        "mu_truck": (70.0, 110.0), "sigma_truck": (1.0, 15.0)},
        description="per parameter mu_<class>/sigma_<class>, km/h")
    metric: str = Field("mean_speed", description="the per-vehicle metric compared (fit.METRICS)")
    parameters: list[str] | None = Field(None, description="what is fitted: mu_<class>, "
                                         "sigma_<class> (km/h) or a W99 parameter cc0..cc9 as "
                                         "<cc>_<class>; default mu and sigma of every class")
    metric_options: dict[str, float] = Field(default_factory=dict, description="options of the "
                                             "metric (e.g. max_thw, min_following)")
    restarts: int = Field(100, ge=1)
    seed: int = Field(0, description="seed of the starting points")
    maxfev: int = Field(120, ge=5, description="evaluations per restart at most")
    xatol: float = Field(0.1, gt=0, description="km/h")
    fatol: float = Field(0.05, gt=0)
    simplex_fraction: float = Field(0.2, gt=0, le=1)
    bandwidth: str | float = "silverman"
    kde_backend: str = "numpy"

    @model_validator(mode="after")
    def _check(self) -> FitConfig:
        from aveas_format.fit.objective import METRICS

        if self.metric not in METRICS:
            raise ValueError(f"metric {self.metric!r}: expected one of {', '.join(METRICS)}")
        for n in self.names:
            kind, _, c = n.partition("_")
            if kind not in ("mu", "sigma", *W99_DEFAULTS) or c not in self.classes:
                raise ValueError(f"parameter {n!r}: expected mu_<class>, sigma_<class> or "
                                 f"cc0_<class> ... cc9_<class> with a class of {self.classes}")
        return self

    @property
    def names(self) -> list[str]:
        if self.parameters:
            return list(self.parameters)
        return [f"{p}_{c}" for c in self.classes for p in ("mu", "sigma")]

    def bounds_array(self) -> np.ndarray:
        """(lower, upper) per parameter: ``bounds``, else the paper's W99 range for cc0..cc9."""
        out = []
        for n in self.names:
            kind = n.partition("_")[0]
            if n in self.bounds:
                out.append(sorted(self.bounds[n]))
            elif kind in W99_RANGES:
                out.append(sorted(W99_RANGES[kind]))
            else:
                raise ValueError(f"bounds lack {n!r} (need {self.names})")
        return np.array(out, np.float64)

    def scenario_at(self, theta: np.ndarray) -> Scenario:
        """The scenario with the parameters set to ``theta`` (the others as in ``scenario``)."""
        speeds = {c.name: [c.speed_mean_kmh, c.speed_std_kmh] for c in self.scenario.classes}
        cf: dict[str, dict[str, float]] = {}
        for n, v in zip(self.names, np.asarray(theta, np.float64), strict=True):
            kind, _, c = n.partition("_")
            if kind in ("mu", "sigma"):
                speeds[c][kind == "sigma"] = float(v)
            else:
                cf.setdefault(c, {})[kind] = float(v)
        sc = self.scenario.with_desired_speeds({c: (mu, sd) for c, (mu, sd) in speeds.items()})
        for c, params in cf.items():
            sc = sc.with_cf_params(c, **params)
        return sc

    def starts(self) -> np.ndarray:
        b = self.bounds_array()
        rng = np.random.default_rng(self.seed)
        return b[:, 0] + rng.random((self.restarts, len(b))) * (b[:, 1] - b[:, 0])


def metric_at(theta: np.ndarray, config: FitConfig) -> dict[str, np.ndarray]:
    """The simulated per-vehicle metric at ``theta``."""
    from aveas_format.fit.objective import METRICS
    from aveas_format.sim.runner import simulate

    m = METRICS[config.metric]
    res = simulate(config.scenario_at(theta), recording=m.needs_recording)
    return m.simulated(res, **config.metric_options)


def evaluate(theta: np.ndarray, config: FitConfig, recorded: dict[str, np.ndarray]
             ) -> tuple[float, dict[str, np.ndarray]]:
    """-ln L at ``theta`` (the parameters of ``config.names``) and the simulated metric."""
    sim = metric_at(theta, config)
    return neg_log_likelihood(recorded, sim, config.bandwidth, config.kde_backend), sim


def initial_simplex(x0: np.ndarray, bounds: np.ndarray, fraction: float) -> np.ndarray:
    """x0 plus one vertex per parameter, moved by ``fraction`` of the bound width, inwards."""
    w = (bounds[:, 1] - bounds[:, 0]) * fraction
    sim = [x0]
    for i in range(len(x0)):
        v = x0.copy()
        v[i] = x0[i] + w[i] if x0[i] + w[i] <= bounds[i, 1] else x0[i] - w[i]
        sim.append(v)
    return np.array(sim)


def run_restart(task: dict) -> dict:
    """One Nelder-Mead run (a module-level function: runs in worker processes and on Dask)."""
    from scipy.optimize import minimize

    config = FitConfig.model_validate(task["config"])
    recorded = {c: np.asarray(v, np.float64) for c, v in task["recorded"].items()}
    x0 = np.asarray(task["x0"], np.float64)
    b = config.bounds_array()
    t0 = time.perf_counter()
    cache: dict[tuple, float] = {}

    def f(x: np.ndarray) -> float:
        key = tuple(np.round(x, 6))
        if key not in cache:
            cache[key] = evaluate(np.clip(x, b[:, 0], b[:, 1]), config, recorded)[0]
        return cache[key]

    r = minimize(f, x0, method="Nelder-Mead", bounds=[tuple(v) for v in b],
                 options={"initial_simplex": initial_simplex(x0, b, config.simplex_fraction),
                          "maxfev": config.maxfev, "xatol": config.xatol, "fatol": config.fatol})
    out = {"restart": int(task["restart"]), "fun": float(r.fun), "nfev": int(r.nfev), "nit": int(r.nit),
           "success": bool(r.success), "message": str(r.message),
           "seconds": round(time.perf_counter() - t0, 3)}
    for i, n in enumerate(config.names):
        out[f"start_{n}"] = float(x0[i])
        out[n] = float(np.clip(r.x[i], b[i, 0], b[i, 1]))
    return out


@dataclass
class FitResult:
    config: FitConfig
    runs: list[dict]
    recorded: dict[str, np.ndarray]
    outdir: Path | None = None
    failed: list[str] = field(default_factory=list)

    @property
    def best(self) -> dict:
        return min(self.runs, key=lambda r: r["fun"])

    def best_params(self) -> dict[str, float]:
        return {n: self.best[n] for n in self.config.names}


def load_runs(outdir: Path) -> list[dict]:
    p = Path(outdir) / "runs.jsonl"
    if not p.exists():
        return []
    runs = []
    for line in p.read_text().splitlines():
        if line.strip():
            try:
                runs.append(json.loads(line))
            except json.JSONDecodeError:  # a line cut by an interruption
                continue
    return runs


def fit_parameters(recorded: dict[str, np.ndarray], config: FitConfig | None = None, *,
                   workers: int | None = 1, scheduler: str | None = None,
                   outdir: str | Path | None = None, progress: bool = False,
                   figures: bool = True) -> FitResult:
    """Run (or resume) the restarts; see the module docstring. ``recorded``: per class, the
    recorded values of ``config.metric``."""
    from aveas_format.parallel import run_tasks

    config = config or FitConfig()
    recorded = {c: np.asarray(recorded.get(c, []), np.float64) for c in config.classes}
    od = Path(outdir) if outdir is not None else None
    done: list[dict] = []
    if od is not None:
        od.mkdir(parents=True, exist_ok=True)
        cfg_path = od / "config.json"
        cfg_json = config.model_dump(mode="json")
        if cfg_path.exists():
            old = json.loads(cfg_path.read_text())
            try:  # fills fields added since the fit was stored with their defaults
                old = FitConfig.model_validate(old).model_dump(mode="json")
            except ValueError:
                pass
            if {k: v for k, v in old.items() if k != "restarts"} != \
                    {k: v for k, v in cfg_json.items() if k != "restarts"}:
                from aveas_format.errors import AveasError

                raise AveasError("holds a fit with a different configuration; use another "
                                 "output directory", path=od)
        write_text_atomic(cfg_path, json.dumps(cfg_json, indent=2))
        write_text_atomic(od / "recorded.json", json.dumps({c: v.tolist() for c, v in recorded.items()}))
        done = [r for r in load_runs(od) if r["restart"] < config.restarts]
    have = {r["restart"] for r in done}
    starts = config.starts()
    cfg = config.model_dump(mode="json")
    rec_l = {c: v.tolist() for c, v in recorded.items()}
    tasks = [{"config": cfg, "recorded": rec_l, "restart": i, "x0": starts[i].tolist()}
             for i in range(config.restarts) if i not in have]
    runs = list(done)
    failed = []
    for r in run_tasks(run_restart, tasks, workers=workers, scheduler=scheduler, progress=progress,
                       description="restarts"):
        if not r.ok:
            failed.append(f"restart {r.item['restart']}: {r.error}")
            continue
        runs.append(r.value)
        if od is not None:
            with open(od / "runs.jsonl", "a") as f:
                f.write(json.dumps(r.value) + "\n")
    runs.sort(key=lambda r: r["restart"])
    res = FitResult(config, runs, recorded, od, failed)
    if od is not None and runs:
        import pyarrow as pa

        write_parquet_atomic(pa.Table.from_pylist(runs), od / "runs.parquet")
        write_text_atomic(od / "best.json", json.dumps(res.best, indent=2))
        if figures:
            from aveas_format.fit.objective import METRICS, kde_logpdf
            from aveas_format.plot.fit import plot_histogram, plot_parameters

            m = METRICS[config.metric]
            sim = metric_at(np.array([res.best[n] for n in config.names]), config)
            plot_histogram(recorded, sim, od / "fit_histogram.png",
                           density=lambda s, grid: np.exp(kde_logpdf(s, grid, config.bandwidth)),
                           unit=m.unit, label=m.label or m.name)
            plot_parameters(runs, config.names, od / "fit_parameters.png")
    return res


#: the paper's experiment (the default configuration fits the desired speeds)
fit_desired_speed = fit_parameters
