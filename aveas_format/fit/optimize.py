"""Fit simulation parameters to recorded per-vehicle metrics: the paper's desired-speed
distributions N(mu, sigma) per class against mean speeds (the default), or W99 car-following
parameters against time headways, minimum TTCs or acceleration spreads (``FitConfig.metric`` and
``FitConfig.parameters``).

>>> from aveas_format.fit import FitConfig, fit_parameters
>>> result = fit_parameters({"car": v_car, "truck": v_truck}, FitConfig(restarts=4),
...                         workers=2, outdir="fit-out")                         # doctest: +SKIP
>>> result.best, result.summary()                                                # doctest: +SKIP
>>> fit_parameters(headways, FitConfig(metric="time_headway", parameters=["cc1_car"]),
...                outdir="fit-cc1")                                             # doctest: +SKIP

Each restart minimises -ln L (:mod:`.objective`) with one of the optimisers of :mod:`.search`
(CMA-ES by default; the paper's Nelder-Mead with ``method="nelder-mead"``) from its own starting
point: the first from the data (``starts="data"``: the recorded values' moments for mu/sigma under
the mean-speed metric, else the scenario's value; ``FitConfig.start`` overrides), the others drawn
uniformly from the bounds. Every evaluation runs SUMO with the same seed (common random numbers:
same arrivals and same standard-normal draw per vehicle, stratified by default), so the objective is
a deterministic, nearly smooth function; the network is built once per fit and shipped with the
tasks; with the mean-speed metric SUMO writes only the section crossings.

Restarts are independent tasks run through :func:`aveas_format.parallel.run_tasks` (in-process,
local processes or a Dask cluster). Each finished restart is appended to ``OUTDIR/runs.jsonl`` at
once, so an interrupted fit resumes where it stopped (restarts already stored are skipped). At the
end a quadratic response surface of -ln L around the best restart's end gives the estimate and a
standard error per parameter (the quadratic profile likelihood, :mod:`.uncertainty`), and
``runs.parquet``, ``best.json`` (the estimate, whether the fit converged and why it stopped, the
standard errors, every restart's convergence) and the figures are written.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from aveas_format.fit.objective import neg_log_likelihood
from aveas_format.fit.search import Objective, initial_simplex, minimise
from aveas_format.safeio import write_parquet_atomic, write_text_atomic
from aveas_format.sim.scenario import W99_DEFAULTS, W99_RANGES, Scenario

__all__ = ["FitConfig", "FitResult", "evaluate", "fit_desired_speed", "fit_parameters",
           "initial_simplex", "load_runs", "metric_at", "run_restart", "run_stored"]


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
    method: Literal["cma", "nelder-mead", "bayes"] = Field(
        "cma", description="optimiser (aveas_format.fit.search): CMA-ES, the paper's Nelder-Mead, "
        "or Gaussian-process Bayesian optimisation")
    restarts: int = Field(4, ge=1, description="independent searches (the paper: 100 Nelder-Mead runs)")
    starts: Literal["data", "uniform"] = Field("data", description="data: the first restart starts "
                                               "from the data (see start), the others uniformly in "
                                               "the bounds; uniform: all uniformly (the paper's)")
    start: dict[str, float] | None = Field(None, description="the first restart's starting point "
                                           "(default: the recorded values' mean and standard "
                                           "deviation for mu/sigma under the mean-speed metric, "
                                           "else the scenario's value)")
    seed: int = Field(0, description="seed of the starting points and of the optimiser")
    maxfev: int = Field(200, ge=5, description="evaluations per restart at most")
    xatol: float = Field(0.5, gt=0, description="a restart has converged when its search has "
                         "settled to within this in every desired-speed parameter (km/h; CMA-ES: "
                         "the spread of its distribution). Finer than about half a standard error "
                         "the objective's jumps decide, and the response surface takes over")
    xatol_fraction: float = Field(0.01, gt=0, le=0.5, description="the same for every other "
                                  "parameter (W99 cc0..cc9, in their own units): this fraction of "
                                  "its bound width (cc1 bounded to 0.3-1.8 s: 0.015 s)")
    fatol: float = Field(0.05, gt=0, description="convergence tolerance in -ln L")
    simplex_fraction: float = Field(0.2, gt=0, le=1, description="initial step as a fraction of "
                                    "the bound widths (Nelder-Mead's simplex, CMA-ES's sigma0)")
    popsize: int | None = Field(None, ge=2, description="CMA-ES population (default 4 + 3 ln n)")
    speed_sampling: Literal["random", "stratified", "scenario"] = Field(
        "stratified", description="the simulated desired speeds: stratified quantiles (no sampling "
        "error of the simulated mu and sigma), random draws, or as the scenario says")
    refine: bool = Field(True, description="estimate and standard errors from a quadratic "
                         "response surface of -ln L around the best restart's end (three rounds of "
                         "2 n (n - 1) + 1 simulations; aveas_format.fit.uncertainty)")
    refine_rounds: int = Field(3, ge=1, le=10, description="rounds of the response-surface design")
    refine_seeds: int = Field(4, ge=1, le=50, description="simulation seeds of the response "
                              "surface: after its rounds under the fit's seed, one more design "
                              "under each of refine_seeds - 1 further seeds; the estimate averages "
                              "the seeds' minima and the standard errors include the seed's noise "
                              "(aveas_format.fit.uncertainty); 1: the fit's seed only")
    refine_step: float = Field(0.03, gt=0, le=0.25, description="the first response-surface "
                               "design's half-width as a fraction of the bound widths (for mu/sigma "
                               "under the mean-speed metric: two standard errors of the recorded "
                               "values' mean and standard deviation instead)")
    bootstrap: int = Field(40, ge=0, le=1000, description="recordings of the parametric "
                           "bootstrap: simulated at the estimate with random desired speeds (as "
                           "many vehicles per class as recorded), each refitted on the response "
                           "surface; their spread is the standard error's sampling part (with "
                           "vehicles held up together, not independent). Fewer than 3: the "
                           "surface's curvature H^-1 instead")
    bias_correction: bool = Field(False, description="the estimate is the response surface's "
                                  "minimum minus the bootstrap's bias (mean of the bootstrap minima "
                                  "minus the minimum; with >= 20 bootstrap recordings); off by "
                                  "default: in the recovery study it helped sigma_car at the "
                                  "paper's sample size, not with every vehicle of 15 min")
    bandwidth: str | float = "silverman"
    kde_backend: str = "numpy"
    variance_correction: bool = Field(True, description="shrink the simulated values towards their "
                                      "mean before smoothing so that the KDE's variance is theirs "
                                      "(without it a fitted sigma is biased low by about h^2 / 2s)")

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
        unknown = set(self.start or {}) - set(self.names)
        if unknown:
            raise ValueError(f"start has parameters that are not fitted: {sorted(unknown)}")
        return self

    @property
    def names(self) -> list[str]:
        if self.parameters:
            return list(self.parameters)
        return [f"{p}_{c}" for c in self.classes for p in ("mu", "sigma")]

    def tolerances(self) -> np.ndarray:
        """Per parameter, how far a converged search may still move: ``xatol`` (km/h) for
        mu/sigma, ``xatol_fraction`` x the bound width for the others."""
        b = self.bounds_array()
        speed = np.array([n.partition("_")[0] in ("mu", "sigma") for n in self.names])
        return np.where(speed, self.xatol, self.xatol_fraction * (b[:, 1] - b[:, 0]))

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
        if self.speed_sampling != "scenario" and sc.random_numbers == "common":
            sc.speed_sampling = self.speed_sampling
        return sc

    def data_start(self, recorded: dict[str, np.ndarray]) -> np.ndarray:
        """The first restart's start: ``start``, else per parameter the recorded values' mean
        (mu_<class>) or standard deviation (sigma_<class>) under the mean-speed metric, else the
        scenario's value; clipped into the bounds."""
        b = self.bounds_array()
        x = []
        for n in self.names:
            kind, _, c = n.partition("_")
            v = np.asarray(recorded.get(c, []), np.float64)
            if self.start and n in self.start:
                x.append(self.start[n])
            elif self.metric == "mean_speed" and kind in ("mu", "sigma") and len(v) > 1:
                x.append(float(v.mean()) if kind == "mu" else float(v.std(ddof=1)))
            elif kind in ("mu", "sigma"):
                cls = self.scenario.cls(c)
                x.append(cls.speed_mean_kmh if kind == "mu" else cls.speed_std_kmh)
            else:
                x.append(self.scenario.cls(c).w99()[kind])
        return np.clip(np.array(x, np.float64), b[:, 0], b[:, 1])

    def moment_se(self, recorded: dict[str, np.ndarray]) -> np.ndarray:
        """Per parameter the standard error of the recorded values' own moment where the data tell
        it (mean-speed metric: mu ``s / sqrt(n)``, sigma ``s / sqrt(2 n)`` of the recorded mean
        speeds; more than 5 values), else NaN: no estimate from n vehicles is more precise than
        the moments of their own desired speeds, so this bounds the standard error from below."""
        out = np.full(len(self.names), np.nan)
        for i, n in enumerate(self.names):
            kind, _, c = n.partition("_")
            v = np.asarray(recorded.get(c, []), np.float64)
            if self.metric == "mean_speed" and kind in ("mu", "sigma") and len(v) > 5:
                out[i] = v.std(ddof=1) / np.sqrt(len(v) * (1 if kind == "mu" else 2))
        return out

    def surface_step(self, recorded: dict[str, np.ndarray]) -> np.ndarray:
        """The first response-surface design's half-width per parameter: two standard errors of
        the recorded moments where the data tell them (:meth:`moment_se`), else ``refine_step`` x
        the bound width."""
        b = self.bounds_array()
        se = self.moment_se(recorded)
        return np.where(np.isfinite(se), 2.0 * se, (b[:, 1] - b[:, 0]) * self.refine_step)

    def starts_array(self, recorded: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """One starting point per restart (see ``starts``)."""
        b = self.bounds_array()
        rng = np.random.default_rng(self.seed)
        pts = b[:, 0] + rng.random((self.restarts, len(b))) * (b[:, 1] - b[:, 0])
        if self.starts == "data":
            pts[0] = self.data_start(recorded or {})
        return pts


def metric_at(theta: np.ndarray, config: FitConfig, network=None) -> dict[str, np.ndarray]:
    """The simulated per-vehicle metric at ``theta`` (``network``: a prepared SUMO network)."""
    from aveas_format.fit.objective import METRICS
    from aveas_format.sim.runner import simulate

    m = METRICS[config.metric]
    res = simulate(config.scenario_at(theta), recording=m.needs_recording,
                   fcd=not m.section_only, network=network)
    return m.simulated(res, **config.metric_options)


def evaluate(theta: np.ndarray, config: FitConfig, recorded: dict[str, np.ndarray], network=None
             ) -> tuple[float, dict[str, np.ndarray]]:
    """-ln L at ``theta`` (the parameters of ``config.names``) and the simulated metric."""
    sim = metric_at(theta, config, network)
    return neg_log_likelihood(recorded, sim, config.bandwidth, config.kde_backend,
                              config.variance_correction), sim


def _task_inputs(task: dict) -> tuple[FitConfig, dict[str, np.ndarray]]:
    config = task["config"]
    config = config if isinstance(config, FitConfig) else FitConfig.model_validate(config)
    return config, {c: np.asarray(v, np.float64) for c, v in task["recorded"].items()}


def run_restart(task: dict) -> dict:
    """One search from ``task["x0"]`` (a module-level function: runs in worker processes and on
    Dask). Returns the start and end parameters, -ln L, evaluations, whether it converged and why
    it stopped, the seconds it took and the trace of -ln L per evaluation."""
    config, recorded = _task_inputs(task)
    x0 = np.asarray(task["x0"], np.float64)
    b = config.bounds_array()
    net = task.get("network")
    t0 = time.perf_counter()
    f = Objective(lambda x: evaluate(x, config, recorded, net)[0], b)
    r = minimise(config.method, f, x0, maxfev=config.maxfev, xatol=config.tolerances(), fatol=config.fatol,
                 step=config.simplex_fraction, seed=config.seed * 1000 + int(task["restart"]),
                 popsize=config.popsize)
    out = {"restart": int(task["restart"]), "method": config.method, "fun": r.fun, "nfev": r.nfev,
           "nit": r.nit, "converged": r.converged, "stop": r.stop,
           "seconds": round(time.perf_counter() - t0, 3)}
    for i, n in enumerate(config.names):
        out[f"start_{n}"] = float(x0[i])
        out[n] = float(np.clip(r.x[i], b[i, 0], b[i, 1]))
    out["trace"] = r.trace
    return out


def evaluate_point(task: dict) -> dict:
    """-ln L at ``task["theta"]`` and the simulated metric (a module-level function for the
    response surface's tasks; the bootstrap re-uses the simulated values)."""
    config, recorded = _task_inputs(task)
    f, sim = evaluate(np.asarray(task["theta"], np.float64), config, recorded, task.get("network"))
    return {"f": f, "sim": {c: np.asarray(v, np.float64).tolist() for c, v in sim.items()}}


def bootstrap_recording(task: dict) -> dict[str, list[float]]:
    """One recording of the parametric bootstrap (a module-level function for the tasks): the
    metric simulated at ``task["theta"]`` with random desired speeds and the task's seeds (further
    seeds until every class has as many values as recorded), subsampled to the recorded sizes."""
    config, recorded = _task_inputs(task)
    theta = np.asarray(task["theta"], np.float64)
    need = {c: len(v) for c, v in recorded.items() if len(v)}
    got: dict[str, list[np.ndarray]] = {c: [] for c in need}
    cfg = config.model_copy(update={"speed_sampling": "random"})
    for seed in task["seeds"]:
        sim = metric_at(theta, cfg.model_copy(update={"scenario": cfg.scenario.model_copy(
            update={"seed": int(seed)})}), task.get("network"))
        for c in need:
            got[c].append(np.asarray(sim.get(c, []), np.float64))
        if all(sum(map(len, got[c])) >= need[c] for c in need):
            break
    rng = np.random.default_rng(int(task["seeds"][0]))
    out = {}
    for c, n in need.items():
        v = np.concatenate(got[c]) if got[c] else np.empty(0)
        out[c] = (v[np.sort(rng.choice(len(v), n, replace=False))] if len(v) > n else v).tolist()
    return out


@dataclass
class FitResult:
    config: FitConfig
    runs: list[dict]
    recorded: dict[str, np.ndarray]
    outdir: Path | None = None
    failed: list[str] = field(default_factory=list)
    #: the response surface (:func:`aveas_format.fit.uncertainty.response_surface`; empty without)
    surface: dict = field(default_factory=dict)

    @property
    def best(self) -> dict:
        """The restart with the lowest -ln L at its end."""
        return min(self.runs, key=lambda r: r["fun"])

    def best_params(self) -> dict[str, float]:
        """The estimate: the response surface's minimum, else the best restart's end."""
        if self.surface:
            return {n: float(self.surface["x"][i]) for i, n in enumerate(self.config.names)}
        return {n: self.best[n] for n in self.config.names}

    @property
    def optimiser_converged(self) -> bool:
        """The best restart (the one the estimate starts from) converged by its optimiser's own
        criterion (CMA-ES: its spread below ``xatol`` or its values within ``fatol``; Nelder-Mead:
        SciPy's ``xatol`` and ``fatol``), not stopped at the evaluation cap."""
        return bool(self.best.get("converged", False))

    @property
    def surface_converged(self) -> bool | None:
        """The response surface is positive definite with its minimum inside its design (None
        without ``refine``)."""
        return bool(self.surface["converged"]) if self.surface else None

    @property
    def converged(self) -> bool:
        """The fit converged: the best restart converged by its optimiser's criterion and, when
        refined, the response surface resolved its minimum. A fit whose best restart stopped at the
        evaluation cap has not converged, whatever the surface says."""
        return self.optimiser_converged and self.surface_converged is not False

    @property
    def stop(self) -> str:
        """Why the fit stopped, in words that agree with :attr:`converged`."""
        b = self.best
        head = (f"the best restart ({b['restart']}) converged: {b.get('stop', '')}" if self.optimiser_converged
                else f"the best restart ({b['restart']}) did not converge: {b.get('stop', '')}")
        return f"{head}; {self.surface['stop']}" if self.surface else head

    def agreeing(self) -> int:
        """How many restarts ended within two standard errors of the estimate in every parameter
        (without standard errors: within twice :meth:`FitConfig.tolerances` of the best
        restart's end) — the paper's
        robustness check, the same minimum from different starts."""
        names = self.config.names
        est = self.best_params()
        se = self.surface.get("se") if self.surface else None
        if se is not None and np.all(np.isfinite(se)):
            tol = dict(zip(names, 2.0 * np.asarray(se), strict=True))
        else:
            est = {n: self.best[n] for n in names}
            tol = dict(zip(names, 2.0 * self.config.tolerances(), strict=True))
        return sum(all(abs(r[n] - est[n]) <= tol[n] for n in names) for r in self.runs)

    def summary(self) -> dict:
        """What ``best.json`` holds: the estimate, whether the fit converged and why it stopped,
        the standard errors and 95 % intervals, the best restart and how the restarts agreed."""
        names = self.config.names
        b = self.best
        est = self.best_params()
        out: dict = {**est, "fun": self.surface["fun"] if self.surface else b["fun"],
                     "converged": self.converged, "stop": self.stop,
                     "optimiser_converged": self.optimiser_converged,
                     "surface_converged": self.surface_converged,
                     "estimate": "response surface" if self.surface else "best restart",
                     "method": self.config.method, "restarts": len(self.runs),
                     "restarts_converged": sum(bool(r.get("converged")) for r in self.runs),
                     "restarts_at_cap": sum(not r.get("converged") for r in self.runs),
                     "restarts_agreeing": self.agreeing(),
                     "evaluations": sum(r["nfev"] for r in self.runs)
                     + self.surface.get("evaluations", 0),
                     "best_restart": {k: b[k] for k in ("restart", "fun", "nfev", "converged", "stop",
                                                        *names, *(f"start_{n}" for n in names))
                                      if k in b}}
        if self.surface:
            se = self.surface["se"]
            out["se"] = {n: _num(se[i]) for i, n in enumerate(names)}
            out["ci95"] = {n: [_num(est[n] - 1.96 * se[i]), _num(est[n] + 1.96 * se[i])]
                           for i, n in enumerate(names)}
            sf = self.surface
            out["se_sampling"] = {n: _num(sf["se_sampling"][i]) for i, n in enumerate(names)}
            out["se_seed"] = {n: _num(sf["se_seed"][i]) for i, n in enumerate(names)}
            out["se_information"] = {n: _num(v) for n, v in zip(
                names, sf.get("se_information", [np.nan] * len(names)), strict=True)}
            boot = sf.get("bootstrap") or {}
            out["response_surface"] = {
                "method": "quadratic fit of -ln L to Box-Behnken designs around the best restart, "
                          "the last design under further simulation seeds (one gradient per seed, "
                          "a common Hessian H); estimate = mean of the seeds' minima (minus the "
                          "bootstrap's bias when bias_corrected); cov = cov(bootstrap minima) "
                          "(else H^-1) + cov(seed minima) / seeds",
                "bootstrap": boot.get("replicates", 0),
                "bootstrap_bias": {n: _num(v) for n, v in zip(names, boot["bias"], strict=True)}
                if boot else None,
                "bias_corrected": bool(sf.get("bias_corrected", False)),
                "minimum": {n: _num(v) for n, v in zip(names, sf.get("minimum", sf["x"]), strict=True)},
                "seeds": sf.get("seeds", 1),
                "seed_minima": [{n: _num(v) for n, v in zip(names, row, strict=True)}
                                for row in np.asarray(sf.get("seed_minima", np.empty((0, len(names)))))],
                "rounds": self.surface["rounds"], "evaluations": self.surface["evaluations"],
                "step": {n: _num(self.surface["step"][i]) for i, n in enumerate(names)},
                "cov": [[_num(v) for v in row] for row in np.asarray(self.surface["cov"])]}
        return out


def _num(v: float) -> float | None:
    return None if not np.isfinite(v) else round(float(v), 6)


def load_runs(outdir: Path, name: str = "runs.jsonl") -> list[dict]:
    """The rows stored in ``outdir/name`` (JSON lines; a line cut by an interruption is skipped)."""
    p = Path(outdir) / name
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


def run_stored(fn, tasks: list[dict], label, *, workers: int | None, scheduler: str | None,
               progress: bool, description: str, store: Path | None) -> tuple[list, list[str]]:
    """Run ``fn`` over ``tasks`` through :func:`aveas_format.parallel.run_tasks`; every result is
    appended to the JSON-lines file ``store`` as soon as it arrives (so that an interrupted run
    resumes, :func:`load_runs`). Returns the results and one message per failed task
    (``label(task)``: what failed)."""
    from aveas_format.parallel import run_tasks

    values, failed = [], []
    for r in run_tasks(fn, tasks, workers=workers, scheduler=scheduler, progress=progress,
                       description=description):
        if not r.ok:
            failed.append(f"{label(r.item)}: {r.error}")
            continue
        values.append(r.value)
        if store is not None:
            with open(store, "a") as f:
                f.write(json.dumps(r.value) + "\n")
    return values, failed


def _check_stored_config(od: Path, config: FitConfig) -> None:
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


def fit_parameters(recorded: dict[str, np.ndarray], config: FitConfig | None = None, *,
                   workers: int | None = 1, scheduler: str | None = None,
                   outdir: str | Path | None = None, progress: bool = False,
                   figures: bool = True) -> FitResult:
    """Run (or resume) the restarts, then the response surface; see the module docstring.
    ``recorded``: per class, the recorded values of ``config.metric``."""
    from aveas_format.sim.runner import prepare_network

    config = config or FitConfig()
    recorded = {c: np.asarray(recorded.get(c, []), np.float64) for c in config.classes}
    od = Path(outdir) if outdir is not None else None
    done: list[dict] = []
    if od is not None:
        od.mkdir(parents=True, exist_ok=True)
        _check_stored_config(od, config)
        write_text_atomic(od / "recorded.json", json.dumps({c: v.tolist() for c, v in recorded.items()}))
        done = [r for r in load_runs(od) if r["restart"] < config.restarts]
    have = {r["restart"] for r in done}
    starts = config.starts_array(recorded)
    network = prepare_network(config.scenario.network)  # once per fit, shipped with the tasks
    base = {"config": config.model_dump(mode="json"), "network": network,
            "recorded": {c: v.tolist() for c, v in recorded.items()}}
    tasks = [{**base, "restart": i, "x0": starts[i].tolist()}
             for i in range(config.restarts) if i not in have]
    new, failed = run_stored(run_restart, tasks, lambda t: f"restart {t['restart']}", workers=workers,
                             scheduler=scheduler, progress=progress, description="restarts",
                             store=None if od is None else od / "runs.jsonl")
    runs = [*done, *new]
    runs.sort(key=lambda r: r["restart"])
    res = FitResult(config, runs, recorded, od, failed)
    if runs and config.refine:
        res.surface = _refine(res, base, workers, scheduler, progress)
    if od is not None and runs:
        import pyarrow as pa

        write_parquet_atomic(pa.Table.from_pylist(runs), od / "runs.parquet")
        write_text_atomic(od / "best.json", json.dumps(res.summary(), indent=2))
        if figures:
            _figures(res, network)
    return res


def _refine(res: FitResult, base: dict, workers: int | None, scheduler: str | None,
            progress: bool) -> dict:
    from aveas_format.fit.uncertainty import response_surface
    from aveas_format.parallel import run_tasks

    config = res.config
    b = config.bounds_array()

    sims: list[dict | None] = []  # the simulated metric per evaluated point, in order

    def evaluate_all(points: list[np.ndarray], seed: int = 0) -> list[float]:
        out, sim = [np.nan] * len(points), [None] * len(points)
        task_base = base if seed == 0 else {**base, "config": _with_seed(base["config"], seed)}
        tasks = [{**task_base, "theta": p.tolist()} for p in points]
        for r in run_tasks(evaluate_point, tasks, workers=workers, scheduler=scheduler,
                           progress=progress, description="response surface"):
            if r.ok:
                out[r.index], sim[r.index] = r.value["f"], r.value["sim"]
        sims.extend(sim)
        return out

    def resample(x: np.ndarray) -> np.ndarray:
        return _bootstrap_values(x, config, base, sims, workers, scheduler, progress)

    x = np.array([res.best[n] for n in config.names])
    return response_surface(x, config.surface_step(res.recorded), evaluate_all, b,
                            rounds=config.refine_rounds, seeds=config.refine_seeds,
                            resample=resample if config.bootstrap >= 3 else None,
                            min_se=config.moment_se(res.recorded),
                            bias_correction=config.bias_correction)


def _bootstrap_values(x: np.ndarray, config: FitConfig, base: dict, sims: list[dict | None],
                      workers: int | None, scheduler: str | None, progress: bool) -> np.ndarray:
    """-ln L of ``config.bootstrap`` recordings simulated at ``x`` (in parallel) under the simulated
    values of every evaluated point: shape (points, recordings); NaN where a point or a recording
    failed."""
    from aveas_format.fit.objective import kde_logpdf
    from aveas_format.parallel import run_tasks

    seed0 = int(config.scenario.seed)
    tasks = [{**base, "theta": x.tolist(),
              "seeds": [(seed0 + SEED_STRIDE * (BOOTSTRAP_SEEDS + 100 * b + j)) % 2**31 for j in range(20)]}
             for b in range(config.bootstrap)]
    recs: list[dict | None] = [None] * len(tasks)
    for r in run_tasks(bootstrap_recording, tasks, workers=workers, scheduler=scheduler,
                       progress=progress, description="bootstrap"):
        if r.ok:
            recs[r.index] = r.value
    y = np.full((len(sims), len(recs)), np.nan)
    good = [i for i, rec in enumerate(recs) if rec is not None]
    if not good:
        return y
    classes = [c for c in recs[good[0]] if recs[good[0]][c]]
    for j, sim in enumerate(sims):
        if sim is None:
            continue
        total = np.zeros(len(good))
        for c in classes:  # one KDE call per point and class for every recording at once
            vals = [np.asarray(recs[i][c], np.float64) for i in good]
            lp = kde_logpdf(np.asarray(sim.get(c, []), np.float64), np.concatenate(vals),
                            config.bandwidth, config.kde_backend, config.variance_correction)
            total -= np.add.reduceat(lp, np.cumsum([0, *map(len, vals[:-1])]))
        y[j, good] = total
    return y


#: further simulation seeds of the response surface: the fit's seed + r x this (r = 1, 2, ...)
SEED_STRIDE = 7919
#: the bootstrap's recordings use the fit's seed + SEED_STRIDE x (this + 100 b + j)
BOOTSTRAP_SEEDS = 10_000


def _with_seed(config: dict, r: int) -> dict:
    """The task configuration (JSON) with the scenario's r-th further seed."""
    sc = dict(config["scenario"])
    sc["seed"] = (int(sc["seed"]) + SEED_STRIDE * r) % 2**31
    return {**config, "scenario": sc}


def _figures(res: FitResult, network) -> None:
    from aveas_format.fit.objective import METRICS, kde_logpdf
    from aveas_format.plot.fit import plot_histogram, plot_parameters

    config, od = res.config, res.outdir
    m = METRICS[config.metric]
    sim = metric_at(np.array(list(res.best_params().values())), config, network)
    plot_histogram(res.recorded, sim, od / "fit_histogram.png",
                   density=lambda s, grid: np.exp(kde_logpdf(s, grid, config.bandwidth,
                                                             variance_correction=config.variance_correction)),
                   unit=m.unit, label=m.label or m.name)
    plot_parameters(res.runs, config.names, od / "fit_parameters.png",
                    estimate=res.best_params() if res.surface else None,
                    se=dict(zip(config.names, res.surface["se"], strict=True)) if res.surface else None)


#: the paper's experiment (the default configuration fits the desired speeds)
fit_desired_speed = fit_parameters
