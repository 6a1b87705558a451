"""``aveas-format fit``: fit behaviour-model parameters to recordings with SUMO."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out
from aveas_format.cli.options import parse_option_pairs, scheduler_option, workers_option

fit_app = typer.Typer(help="Fit behaviour-model parameters to recordings (maximum likelihood "
                      "with SUMO; docs/fitting.md).", no_args_is_help=True)
app.add_typer(fit_app, name="fit")


def _range(text: str | None) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise fail(f"--s-range {text!r}: expected MIN,MAX", EXIT_USAGE) from None
    return a, b


def _recorded(recordings: list[Path], metric: str, road: str | None, s_range: str | None,
              options: dict[str, float], scenario: bool) -> tuple[dict[str, list[float]], object]:
    """The recorded values per class and (``scenario``) the simulation the recordings describe
    (:func:`aveas_format.fit.recorded.recorded_scenario`), else None."""
    import aveas_format
    from aveas_format.fit import METRICS

    classes = ("car", "truck")
    values: dict[str, list] = {c: [] for c in classes}
    recs = []
    for p in recordings:
        rec = aveas_format.open(p)
        v = METRICS[metric].recorded(rec, classes=classes, road_id=road, s_range=_range(s_range),
                                     **options)
        for c in classes:
            values[c].extend(v[c].tolist())
        if scenario:
            recs.append(rec)
    if not scenario:
        return values, None
    from aveas_format.fit.recorded import recorded_scenario

    used = tuple(c for c in classes if values[c])
    return values, recorded_scenario(recs, classes=used or classes, metric=metric, road_id=road,
                                     s_range=_range(s_range))


def _fit(recordings: list[Path], output: Path, config: Path | None, metric: str,
         parameters: list[str] | None, options: dict[str, float], restarts: int, workers: int,
         scheduler: str | None, maxfev: int, seed: int, bandwidth: str, bounds: str | None,
         road: str | None, s_range: str | None, search: dict) -> None:
    import numpy as np
    from pydantic import ValidationError

    from aveas_format.fit import METRICS, FitConfig, fit_parameters
    from aveas_format.io.reader import format_validation_error
    from aveas_format.sim.scenario import Scenario

    if metric not in METRICS:
        raise fail(f"--metric {metric!r}: expected one of {', '.join(METRICS)}", EXIT_USAGE)
    values, described = _recorded(recordings, metric, road, s_range, options, scenario=config is None)
    used = [c for c in values if values[c]]
    if not used:
        raise fail(f"the recordings hold no cars or trucks with a {metric} value", EXIT_USAGE)
    err.print(f"recorded {metric}: " + ", ".join(f"{len(values[c])} {c}s" for c in used))
    if parameters:
        parameters = [n for n in parameters if n.partition("_")[2] in used]
        if not parameters:
            raise fail("no parameter of a class with recorded values", EXIT_USAGE)
    if config:
        scenario = Scenario.from_toml(config)
    else:  # the simulation the recordings describe (their duration, demand, section, lanes)
        scenario = described.scenario
        for note in described.notes:
            err.print(f"note: {note}")
        err.print(described.describe() + (" (--duration overrides the duration)"
                                          if search.get("duration") is not None else ""))
    duration = search.pop("duration", None)
    if duration is not None:
        scenario = scenario.model_copy(update={"duration": duration})
    cfg: dict = {"scenario": scenario, "classes": used, "restarts": restarts, "maxfev": maxfev,
                 "seed": seed, "metric": metric, "parameters": parameters, "metric_options": options,
                 **search}
    try:
        cfg["bandwidth"] = float(bandwidth)
    except ValueError:
        cfg["bandwidth"] = bandwidth
    if bounds:
        try:
            cfg["bounds"] = {k: tuple(v) for k, v in json.loads(bounds).items()}
        except (json.JSONDecodeError, TypeError, AttributeError):
            raise fail(f"--bounds {bounds!r}: expected JSON like {{\"mu_car\": [100, 160]}}",
                       EXIT_USAGE) from None
    try:
        fc = FitConfig(**cfg)
    except ValidationError as e:
        raise fail(f"fit configuration: {format_validation_error(e)}", EXIT_USAGE) from None
    res = fit_parameters({c: np.asarray(values[c]) for c in used}, fc, workers=workers,
                         scheduler=scheduler, outdir=output, progress=True)
    for f in res.failed:
        err.print(f"failed: {f}")
    if not res.runs:
        raise fail("every restart failed")
    s = res.summary()
    out.print(json.dumps({"best": {n: round(s[n], 3) for n in fc.names},
                          "se": s.get("se"), "se_seed": s.get("se_seed"),
                          "neg_log_likelihood": round(s["fun"], 4),
                          "converged": s["converged"], "stop": s["stop"], "method": s["method"],
                          "restarts": s["restarts"], "restarts_converged": s["restarts_converged"],
                          "restarts_agreeing": s["restarts_agreeing"],
                          "evaluations": s["evaluations"]}, indent=2))
    # the verdict and the restarts' own words agree: the fit converged only where its best
    # restart converged by the optimiser's criterion (and the response surface resolved a minimum)
    err.print(f"the fit {'converged' if s['converged'] else 'did not converge'}: {s['stop']}")
    for r in res.runs:
        if not r.get("converged"):
            err.print(f"restart {r['restart']} did not converge: {r.get('stop', '')}")
    err.print(f"wrote {output}/runs.parquet, best.json, fit_histogram.png, fit_parameters.png")


_RECORDINGS = typer.Argument(..., help="Recordings with the observed vehicles.")
_OUTPUT = typer.Option(..., "--output", "-o", help="Output directory (runs.jsonl/.parquet, "
                       "best.json, figures); an existing one is resumed.")
_CONFIG = typer.Option(None, "--config", "-c", help="Scenario TOML of the simulation (default: "
                       "what the recordings show: their duration, demand and desired speeds per "
                       "class, section length and lanes on the paper's autobahn; docs/fitting.md).")
_SCHEDULER = scheduler_option(help="Dask scheduler address tcp://... (overrides --workers).")
_MAXFEV = typer.Option(200, "--maxfev", help="Evaluations (simulations) per restart at most; the "
                       "response surface and the bootstrap add theirs (--no-refine: none).")
_RESTARTS = typer.Option(4, "--restarts", "-r", min=1, help="Independent searches of --method "
                         "(CMA-ES by default; the paper: 100 Nelder-Mead runs).")
_SEED = typer.Option(0, "--seed", help="Seed of the starting points.")
_ROAD = typer.Option(None, "--road", help="Use only samples on this road id.")
_METHOD = typer.Option("cma", "--method", help="Optimiser: cma (CMA-ES, default), nelder-mead (the "
                       "paper's) or bayes (Gaussian-process Bayesian optimisation).")
_STARTS = typer.Option("data", "--starts", help="data: the first restart starts from the data, the "
                       "others uniformly in the bounds; uniform: all uniformly (the paper's).")
_REFINE = typer.Option(True, "--refine/--no-refine", help="Estimate and standard errors from a "
                       "quadratic response surface around the best restart (75 more simulations "
                       "for 4 parameters, and 25 per further --surface-seeds).")
_SURFACE_SEEDS = typer.Option(4, "--surface-seeds", min=1, help="Simulation seeds of the response "
                              "surface: its last design runs under this many - 1 further seeds, the "
                              "estimate averages them and the standard errors include the seed's "
                              "noise (25 simulations per further seed for 4 parameters).")
_BOOTSTRAP = typer.Option(40, "--bootstrap", min=0, help="Recordings of the parametric bootstrap "
                          "(simulated at the estimate, refitted on the response surface): the "
                          "standard errors' sampling part; below 3 the surface's curvature instead.")
_BIAS = typer.Option(False, "--bias-correction/--no-bias-correction", help="Subtract the "
                     "bootstrap's bias from the response surface's minimum (with >= 20 bootstrap "
                     "recordings; see docs/fitting.md, recovery study).")
_DURATION = typer.Option(None, "--duration", help="Override the simulated demand period (s) of "
                         "each evaluation (default: the recordings' duration, or the --config "
                         "scenario's).")
_S_RANGE = typer.Option(None, "--s-range", help="Use only samples with road_s in MIN,MAX.")


@fit_app.command("desired-speed")
@handle_errors
def desired_speed(
    recordings: list[Path] = _RECORDINGS,
    output: Path = _OUTPUT,
    config: Path = _CONFIG,
    restarts: int = _RESTARTS,
    workers: int = workers_option(),
    scheduler: str = _SCHEDULER,
    maxfev: int = _MAXFEV,
    seed: int = _SEED,
    method: str = _METHOD,
    starts: str = _STARTS,
    refine: bool = _REFINE,
    surface_seeds: int = _SURFACE_SEEDS,
    bootstrap: int = _BOOTSTRAP,
    bias_correction: bool = _BIAS,
    duration: float = _DURATION,
    bandwidth: str = typer.Option("silverman", "--bandwidth", help="KDE bandwidth: silverman, "
                                  "scott or a number (km/h)."),
    bounds: str = typer.Option(None, "--bounds", help="JSON {\"mu_car\": [lo, hi], ...} (km/h)."),
    road: str = _ROAD,
    s_range: str = _S_RANGE,
) -> None:
    """Fit the desired-speed distributions N(mu, sigma) of cars and trucks to the per-vehicle mean
    speeds of recordings (the paper's experiment)."""
    _fit(recordings, output, config, "mean_speed", None, {}, restarts, workers, scheduler, maxfev,
         seed, bandwidth, bounds, road, s_range,
         {"method": method, "starts": starts, "refine": refine, "refine_seeds": surface_seeds,
          "bootstrap": bootstrap, "bias_correction": bias_correction, "duration": duration})


@fit_app.command("car-following")
@handle_errors
def car_following(
    recordings: list[Path] = _RECORDINGS,
    output: Path = _OUTPUT,
    param: list[str] = typer.Option(None, "--param", "-p", help="Parameter to fit, NAME_CLASS: "
                                    "cc0_car ... cc9_truck, mu_car, sigma_car (repeatable; "
                                    "default cc1_car and cc1_truck)."),
    metric: str = typer.Option("time_headway", "--metric", "-m", help="Per-vehicle metric: "
                               "time_headway, min_ttc, a_lon_std or mean_speed."),
    config: Path = _CONFIG,
    restarts: int = _RESTARTS,
    workers: int = workers_option(),
    scheduler: str = _SCHEDULER,
    maxfev: int = _MAXFEV,
    seed: int = _SEED,
    method: str = _METHOD,
    starts: str = _STARTS,
    refine: bool = _REFINE,
    surface_seeds: int = _SURFACE_SEEDS,
    bootstrap: int = _BOOTSTRAP,
    bias_correction: bool = _BIAS,
    duration: float = _DURATION,
    bandwidth: str = typer.Option("silverman", "--bandwidth", help="KDE bandwidth: silverman, "
                                  "scott or a number (in the metric's unit)."),
    bounds: str = typer.Option(None, "--bounds", help="JSON {\"cc1_car\": [lo, hi], ...} "
                               "(default: the paper's W99 ranges)."),
    option: list[str] = typer.Option(None, "--option", help="Metric option NAME=VALUE (max_thw, "
                                     "min_speed, max_closing, max_ttc, min_following)."),
    road: str = _ROAD,
    s_range: str = _S_RANGE,
) -> None:
    """Fit Wiedemann 99 car-following parameters (e.g. cc1, the headway time) to per-vehicle
    car-following metrics of recordings: time headway, minimum TTC or acceleration spread
    (the paper's outlook)."""
    from aveas_format.fit.metrics import METRIC_OPTIONS

    try:
        options = parse_option_pairs(option or [], object)
    except ValueError as e:
        raise fail(f"{e} (NAME=NUMBER)", EXIT_USAGE) from None
    for k, v in options.items():
        if k not in METRIC_OPTIONS or isinstance(v, bool) or not isinstance(v, (int, float)):
            raise fail(f"--option {k}={v}: expected one of {', '.join(METRIC_OPTIONS)}=NUMBER",
                       EXIT_USAGE)
    options = {k: float(v) for k, v in options.items()}
    _fit(recordings, output, config, metric, param or ["cc1_car", "cc1_truck"], options, restarts,
         workers, scheduler, maxfev, seed, bandwidth, bounds, road, s_range,
         {"method": method, "starts": starts, "refine": refine, "refine_seeds": surface_seeds,
          "bootstrap": bootstrap, "bias_correction": bias_correction, "duration": duration})



@fit_app.command("study")
@handle_errors
def study(
    output: Path = typer.Option(..., "--output", "-o", help="Output directory (study.jsonl, "
                                "study.json, study.png); an existing one is resumed."),
    seeds: int = typer.Option(10, "--seeds", "-n", min=2, help="Replicates k = 1..N."),
    config: Path = _CONFIG,
    duration: float = typer.Option(900.0, "--duration", help="Demand period (s) of the recordings "
                                   "and of each evaluation."),
    sizes: str = typer.Option("paper,all", "--sizes", help="paper (178 cars, 33 trucks "
                              "subsampled) and/or all (every vehicle of --duration)."),
    restarts: int = typer.Option(1, "--restarts", "-r", min=1, help="Restarts per fit."),
    maxfev: int = typer.Option(100, "--maxfev", help="Evaluations per restart at most."),
    method: str = _METHOD,
    surface_seeds: int = _SURFACE_SEEDS,
    bootstrap: int = _BOOTSTRAP,
    bias_correction: bool = _BIAS,
    workers: int = workers_option(),
    scheduler: str = _SCHEDULER,
) -> None:
    """Parameter recovery as a statistic: simulate a recording at the paper's estimates with seed
    k, fit it back, for k = 1..N; report bias, RMSE, 95 % coverage and the sampling floor per
    parameter (exit 1 when a target of docs/fitting.md is missed)."""
    from pydantic import ValidationError

    from aveas_format.fit.optimize import FitConfig
    from aveas_format.fit.study import StudyConfig, paper_scenario, recovery_study
    from aveas_format.io.reader import format_validation_error
    from aveas_format.sim.scenario import Scenario

    sc = Scenario.from_toml(config).model_copy(update={"duration": duration}) if config \
        else paper_scenario(duration)
    try:
        cfg = StudyConfig(seeds=seeds, sizes=[s.strip() for s in sizes.split(",") if s.strip()],
                          fit=FitConfig(scenario=sc, restarts=restarts, maxfev=maxfev, method=method,
                                        refine_seeds=surface_seeds, bootstrap=bootstrap,
                                        bias_correction=bias_correction))
    except ValidationError as e:
        raise fail(f"study configuration: {format_validation_error(e)}", EXIT_USAGE) from None
    bad = set(cfg.sizes) - {"paper", "all"}
    if bad:
        raise fail(f"--sizes: unknown {sorted(bad)} (paper, all)", EXIT_USAGE)
    rows, summary = recovery_study(cfg, workers=workers, scheduler=scheduler, outdir=output,
                                   progress=True)
    for f in summary["failed"]:
        err.print(f"failed: {f}")
    if not rows:
        raise fail("every replicate failed")
    out.print(json.dumps(summary, indent=2))
    err.print(f"wrote {output}/study.jsonl, study.json, study.png")
    if not all(summary["targets"].values()):
        raise typer.Exit(1)
