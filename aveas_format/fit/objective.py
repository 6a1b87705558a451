"""The fitting objective: -ln L of recorded metrics under simulated distributions (Gaussian KDE).

    -ln L = - sum_classes sum_k ln phi_class(v_class,k)

where ``phi_class`` is a Gaussian kernel density estimate of the simulated metric of the class and
``v_class,k`` the recorded values (the paper's equation "objective"). The bandwidth is computed from
the simulated sample: Silverman's rule ``0.9 min(sd, IQR/1.34) n^(-1/5)`` (default; in the data's
units, unlike scikit-learn's ``bandwidth="silverman"``, which assumes unit-scaled data), Scott's rule
``1.06 sd n^(-1/5)``, or a fixed number.

Metrics are pluggable (:class:`Metric`): each turns a recording and a simulation result into values
per class. ``mean_speed`` (per-vehicle mean speed, km/h) is the paper's; ``time_headway``,
``min_ttc`` and ``a_lon_std`` (:mod:`aveas_format.fit.metrics`) are the car-following metrics of
its outlook.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

#: log-density floor: a recorded value far outside the simulated support costs at most this much
LOG_FLOOR = np.log(1e-12)


def silverman_bandwidth(x: np.ndarray) -> float:
    """Silverman's rule of thumb, scaled to the data: ``0.9 min(sd, IQR/1.34) n^(-1/5)``."""
    x = np.asarray(x, np.float64)
    n = len(x)
    if n < 2:
        return 1.0
    sd = float(np.std(x, ddof=1))
    q75, q25 = np.percentile(x, [75, 25])
    a = min(sd, (q75 - q25) / 1.34) or sd
    return max(0.9 * a * n ** -0.2, 1e-6) if a > 0 else 1e-3


def scott_bandwidth(x: np.ndarray) -> float:
    x = np.asarray(x, np.float64)
    sd = float(np.std(x, ddof=1)) if len(x) > 1 else 1.0
    return max(1.06 * sd * len(x) ** -0.2, 1e-6)


def bandwidth_of(x: np.ndarray, bandwidth: str | float) -> float:
    if isinstance(bandwidth, str):
        if bandwidth == "silverman":
            return silverman_bandwidth(x)
        if bandwidth == "scott":
            return scott_bandwidth(x)
        raise ValueError(f"bandwidth {bandwidth!r}: expected 'silverman', 'scott' or a number")
    return float(bandwidth)


def kde_logpdf(samples: np.ndarray, points: np.ndarray, bandwidth: str | float = "silverman",
               backend: str = "numpy", variance_correction: bool = False) -> np.ndarray:
    """ln of the Gaussian KDE of ``samples`` at ``points`` (floored at :data:`LOG_FLOOR`).

    ``backend="sklearn"`` uses ``sklearn.neighbors.KernelDensity`` (as the paper did) with the same
    numeric bandwidth; the default is an exact NumPy implementation (same result, no dependency).
    ``variance_correction``: shrink the samples towards their mean by ``sqrt(1 - h^2 / s^2)``
    before smoothing, so that the estimate's variance is the samples' ``s^2`` (ddof 0) rather than
    ``s^2 + h^2`` (Jones 1991, "On correcting for variance inflation in kernel density estimation"): a
    fitted sigma is then not pulled low by the bandwidth.
    """
    samples = np.asarray(samples, np.float64)
    points = np.asarray(points, np.float64)
    if len(samples) == 0:
        return np.full(len(points), LOG_FLOOR)
    h = bandwidth_of(samples, bandwidth)
    if variance_correction and len(samples) > 1:
        m, sd = samples.mean(), samples.std()
        if sd > h:
            samples = m + (samples - m) * np.sqrt(1.0 - (h / sd) ** 2)
    if backend == "sklearn":
        from aveas_format.errors import require

        KernelDensity = require("sklearn.neighbors", extra="fit", what="the scikit-learn KDE "
                                "backend").KernelDensity

        out = KernelDensity(kernel="gaussian", bandwidth=h).fit(samples[:, None]).score_samples(points[:, None])
    else:
        z = (points[:, None] - samples[None, :]) / h
        out = logsumexp(-0.5 * z * z, axis=1) - np.log(len(samples) * h * np.sqrt(2 * np.pi))
    return np.maximum(out, LOG_FLOOR)


def neg_log_likelihood(recorded: dict[str, np.ndarray], simulated: dict[str, np.ndarray],
                       bandwidth: str | float = "silverman", backend: str = "numpy",
                       variance_correction: bool = False) -> float:
    """-ln L summed over the classes of ``recorded`` (see :func:`kde_logpdf` for the options)."""
    total = 0.0
    for c, v in recorded.items():
        if len(v) == 0:
            continue
        total -= float(np.sum(kde_logpdf(simulated.get(c, np.empty(0)), v, bandwidth, backend,
                                         variance_correction)))
    return total


@dataclass(frozen=True)
class Metric:
    """A per-class metric: ``recorded(rec, **kw)`` and ``simulated(sim_result, **options)`` both
    return ``{class: values}``."""

    name: str
    unit: str
    recorded: Callable[..., dict[str, np.ndarray]]
    simulated: Callable[..., dict[str, np.ndarray]]
    #: the simulated side reads the run's recording (converted FCD), not only the FCD
    needs_recording: bool = False
    label: str = ""
    #: the simulated side needs only the measurement-section crossings (``SimResult.mean_speeds``),
    #: so SUMO writes no FCD (``simulate(fcd=False)``)
    section_only: bool = False


def recorded_mean_speeds(rec, *, classes: tuple[str, ...] = ("car", "truck"), road_id: str | None = None,
                         s_range: tuple[float, float] | None = None, min_samples: int = 2
                         ) -> dict[str, np.ndarray]:
    """Per class: each participant's mean speed (km/h) over its samples (optionally only those on
    ``road_id`` with ``road_s`` in ``s_range``)."""
    from aveas_format.fit.metrics import section_states

    st = section_states(rec.states, road_id, s_range)
    pid = st["participant_id"].to_numpy()
    v = np.hypot(st["vx"].to_numpy(zero_copy_only=False), st["vy"].to_numpy(zero_copy_only=False)) * 3.6
    ok = np.isfinite(v)
    pid, v = pid[ok], v[ok]
    parts = rec.participants
    cls_of = dict(zip(parts["participant_id"].to_pylist(), parts["class"].cast("string").to_pylist(),
                      strict=True))
    out: dict[str, np.ndarray] = {c: np.empty(0) for c in classes}
    if len(pid) == 0:
        return out
    uniq, inv, counts = np.unique(pid, return_inverse=True, return_counts=True)
    means = np.bincount(inv, weights=v) / counts
    pc_ = np.array([cls_of.get(int(p)) for p in uniq], dtype=object)
    for c in classes:
        out[c] = means[(pc_ == c) & (counts >= min_samples)]
    return out


def _sim_mean_speeds(res, **options) -> dict[str, np.ndarray]:
    return res.mean_speeds(**options)


def _metrics() -> dict[str, Metric]:
    from aveas_format.fit.metrics import recorded_metric, simulated_metric

    out = {"mean_speed": Metric("mean_speed", "km/h", recorded_mean_speeds, _sim_mean_speeds,
                                label="mean speed", section_only=True)}
    for name, unit, label in (("time_headway", "s", "median time headway while following"),
                              ("min_ttc", "s", "minimum TTC to the lane leader"),
                              ("a_lon_std", "m/s²", "std of the longitudinal acceleration")):
        out[name] = Metric(name, unit, recorded_metric(name), simulated_metric(name),
                           needs_recording=True, label=label)
    return out


#: the metrics by name: ``mean_speed`` (the paper's) and the car-following metrics of
#: :mod:`aveas_format.fit.metrics`
METRICS: dict[str, Metric] = _metrics()
