"""``derived/kinematics``: speed, accelerations and jerk with standard deviations from positions.

Default method ``ca_kalman_rts``: a constant-acceleration (white-jerk) Kalman filter with a
Rauch-Tung-Striebel smoother per track, state ``(p, v, a)`` per axis. Every sample's measurement
noise is its position covariance ``[[x_std², ρ x_std y_std], [ρ x_std y_std, y_std²]]``
(``ρ = xy_corr``); the process noise is a continuous white jerk of spectral density ``q``
(``jerk_density``, m²/s⁵ per axis)::

    Q(dt) = q [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]]

so irregular sampling and short gaps are handled exactly (gaps longer than ``max_gap_s`` start a
new track segment). All tracks run in lockstep: segments are packed into the rows of a
``(steps, rows)`` grid and each time step updates every row at once with closed-form 3x3
arithmetic (x and y are independent when ``xy_corr`` is 0; otherwise a batched 6x6 filter over the
rows with correlated noise). Standard deviations come from the smoothed covariance: speed,
``a_lon`` and ``a_lat`` by the delta method, jerk from the smoother's lag-one covariance.

``jerk_density="auto"`` (default) chooses ``q`` per track window and axis by maximum likelihood:
the innovations' log-likelihood over ``jerk_density_grid`` (decades) in one batched forward pass,
``jerk_density_refine`` bisections in ``log q`` around each window's best value, then the vertex of
a parabola. Rows with one sampling step and one noise variance run that pass with tabulated gains
(only the state recursion per step).

Option ``savitzky_golay``: a cubic Savitzky-Golay filter of ``savgol_window_s`` per track segment
(resampled to a uniform grid where the sampling is irregular); its standard deviations propagate
the position noise through the filter's linear weights (no model-error term).

Conventions: ``a_lon = (v·a)/|v|``, ``a_lat = (v×a)/|v| = (vx ay - vy ax)/|v|`` (ISO 8855, positive
to the left); below ``min_speed`` the direction of the ``heading`` column replaces ``v/|v|``.
``jerk_lon = d a_lon/dt = j·u + a_lat²/|v|``.

Modules (``aveas_format.derive.kinematics``): this one holds the parameters, :func:`compute`, the
table and the registration; private modules hold the rest: ``_estimate`` the estimator's common
steps (:func:`estimate`: checks, segments, speed and accelerations along the motion with their
std); ``_smoother`` the ``ca_kalman_rts`` driver (windows, the lockstep grid, the jerk);
``_filters`` the closed-form 3x3 and batched 6x6 filter and RTS smoother; ``_jerk_density`` the
maximum-likelihood choice of ``q`` (``auto``); ``_savgol`` the Savitzky-Golay option. Track
segments come from :func:`aveas_format.derive._samples.segments`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.derive.kinematics._estimate import estimate
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.io.arrow import column_numpy
from aveas_format.schema.columns import MAY, MUST, corr, gaussian, pid_col, time_col
from aveas_format.schema.tables import derived_table


class KinematicsParams(Params):
    """Parameters of ``kinematics``."""

    method: Literal["ca_kalman_rts", "savitzky_golay"] = Field(
        "ca_kalman_rts", description="estimator: constant-acceleration Kalman + RTS smoother, or "
        "Savitzky-Golay")
    jerk_density: float | Literal["auto"] = Field(
        "auto", description="process noise: spectral density q of the white jerk per axis "
        "(m²/s⁵), or 'auto': chosen per track window and axis by maximum likelihood over "
        "`jerk_density_grid`")
    jerk_density_grid: tuple[float, ...] = Field(
        (1e-15, 1e-12, 1e-9, 1e-6, 1e-5, 1e-4, 1e-3, 0.01, 0.1, 1.0, 10.0, 100.0), min_length=1,
        description="candidate values of q for 'auto' (m²/s⁵), evaluated in one batched pass; "
        "the smallest stands for 'no jerk' (the likelihood is flat towards 0)")
    jerk_density_refine: int = Field(
        1, ge=0, le=4, description="'auto': bisections in log q around each window's best "
        "candidate (two more candidates per bisection) before the parabolic refinement")
    default_position_std: float = Field(0.1, gt=0, description="position std (m) where x_std/"
                                        "y_std are null or absent")
    min_position_std: float = Field(0.001, gt=0, description="lower bound of the position std (m)")
    max_gap_s: float = Field(1.0, gt=0, description="a longer gap between samples starts a new "
                             "track segment")
    prior_speed_std: float = Field(50.0, gt=0, description="prior std of each velocity component "
                                   "at a segment start (m/s)")
    prior_accel_std: float = Field(10.0, gt=0, description="prior std of each acceleration "
                                   "component at a segment start (m/s²)")
    min_speed: float = Field(0.5, ge=0, description="below this speed (m/s) the heading column "
                             "gives the longitudinal direction")
    savgol_window_s: float = Field(1.6, gt=0, description="Savitzky-Golay window length (s)")
    savgol_polyorder: int = Field(3, ge=2, le=5, description="Savitzky-Golay polynomial order")
    batch_rows: int = Field(8192, ge=1, description="tracks run in lockstep (rows of the grid)")
    window_steps: int = Field(1024, ge=16, description="long segments are smoothed in windows of "
                              "this many samples (plus the overlap on each side)")
    overlap_steps: int = Field(128, ge=8, description="samples of overlap on each side of a window "
                               "(discarded; the smoother's memory is far shorter)")


def compute(rec, p: KinematicsParams) -> pa.Table:
    """The ``derived/kinematics`` table of ``rec``."""
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = column_numpy(s, "time")
    x = column_numpy(s, "x")
    y = column_numpy(s, "y")
    d = p.default_position_std
    sx, sy = (column_numpy(s, c, nonfinite=d, missing=d) for c in ("x_std", "y_std"))
    rho = column_numpy(s, "xy_corr", nonfinite=0.0, missing=0.0)
    heading = column_numpy(s, "heading", missing=None)
    order = None
    if len(t) > 1 and (np.any(np.diff(pid) < 0) or np.any((np.diff(pid) == 0) & (np.diff(t) < 0))):
        order = np.lexsort((t, pid))
        pid, t, x, y, sx, sy, rho = (a[order] for a in (pid, t, x, y, sx, sy, rho))
        heading = heading[order] if heading is not None else None
    res = estimate(pid, t, x, y, sx, sy, rho, heading, p)
    cols = {"participant_id": pa.array(pid, pa.int64()), "time": pa.array(t, pa.float64())}
    for name in ("x", "y", "speed", "vx", "vy", "ax", "ay", "a_lon", "a_lat", "jerk_lon"):
        for c in (name, f"{name}_std"):
            v = res[c]
            cols[c] = pa.array(v, pa.float64(), mask=~np.isfinite(v))
        if name in ("y", "vy"):
            c = "xy_corr" if name == "y" else "vxvy_corr"
            v = res[c]
            cols[c] = pa.array(v.astype(np.float32), pa.float32(), mask=~np.isfinite(v))
    return pa.table(cols)


TABLE = derived_table(
    "kinematics",
    doc="Smoothed position, speed, velocity, accelerations and jerk per participant and time, "
    "estimated from the positions with their uncertainty.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(
        pid_col(),
        time_col(),
        *gaussian("x", "m", MAY, "smoothed position x, local frame (ca_kalman_rts; null with "
                  "savitzky_golay)", std_req=MAY),
        *gaussian("y", "m", MAY, "smoothed position y, local frame", std_req=MAY),
        corr("xy_corr", "x", "y"),
        *gaussian("speed", "m/s", MUST, "speed over ground", minimum=0.0, std_req=MUST),
        *gaussian("vx", "m/s", MAY, "smoothed velocity x, local frame (the extrapolations of "
                  "derived/interactions and the events' collision probability use it)",
                  std_req=MAY),
        *gaussian("vy", "m/s", MAY, "smoothed velocity y, local frame", std_req=MAY),
        corr("vxvy_corr", "vx", "vy"),
        *gaussian("ax", "m/s²", MUST, "acceleration x, local frame", std_req=MUST),
        *gaussian("ay", "m/s²", MUST, "acceleration y, local frame", std_req=MUST),
        *gaussian("a_lon", "m/s²", MUST, "longitudinal acceleration (along the heading)",
                  std_req=MUST),
        *gaussian("a_lat", "m/s²", MUST, "lateral acceleration (to the left of the heading)",
                  std_req=MUST),
        *gaussian("jerk_lon", "m/s³", MUST, "longitudinal jerk", std_req=MUST),
    ),
)

KINEMATICS = register(Derivation(
    name="kinematics",
    spec=TABLE,
    version="1.2.0",
    params=KinematicsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y")},
    doc="smoothed x/y, speed, vx/vy, ax/ay, a_lon/a_lat and jerk_lon with standard deviations "
        "from the positions (constant-acceleration Kalman + RTS smoother, or Savitzky-Golay)",
    method=lambda p: p.method,
))

__all__ = ["KINEMATICS", "TABLE", "KinematicsParams", "compute", "estimate"]
