"""Behaviour-parameter fitting: maximum likelihood of recorded metrics under SUMO simulations.

>>> from aveas_format.fit import FitConfig, fit_desired_speed, recorded_mean_speeds
>>> rec_speeds = recorded_mean_speeds(aveas_format.open("highway.aveas"))   # doctest: +SKIP
>>> res = fit_desired_speed(rec_speeds, FitConfig(restarts=100), workers=8, outdir="fit")  # doctest: +SKIP

``fit_parameters(..., FitConfig(metric="time_headway", parameters=["cc1_car"]))`` fits W99
car-following parameters to per-vehicle metrics (:mod:`aveas_format.fit.metrics`). See
docs/fitting.md for the method and the SUMO-vs-Vissim differences.
"""

from __future__ import annotations

from aveas_format.fit.objective import (
    METRICS,
    Metric,
    kde_logpdf,
    neg_log_likelihood,
    recorded_mean_speeds,
    scott_bandwidth,
    silverman_bandwidth,
)
from aveas_format.fit.optimize import (
    FitConfig,
    FitResult,
    evaluate,
    fit_desired_speed,
    fit_parameters,
    initial_simplex,
    load_runs,
    run_restart,
)
from aveas_format.fit.search import METHODS

__all__ = ["METHODS", "METRICS", "FitConfig", "FitResult", "Metric", "evaluate", "fit_desired_speed",
           "fit_parameters", "initial_simplex", "kde_logpdf", "load_runs", "neg_log_likelihood",
           "recorded_mean_speeds", "run_restart", "scott_bandwidth", "silverman_bandwidth"]
