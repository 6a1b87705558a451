"""The kinematics estimator's common steps: :func:`estimate` checks the rows, cuts them into track
segments and runs the chosen estimator (:mod:`._smoother` or :mod:`._savgol`); :func:`_combine`
turns the velocity and acceleration vectors and their covariances into speed, ``a_lon``,
``a_lat`` and ``jerk_lon`` with their std."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from aveas_format.derive._samples import segments
from aveas_format.derive.kinematics._savgol import savgol
from aveas_format.derive.kinematics._smoother import kalman
from aveas_format.errors import FormatError

if TYPE_CHECKING:
    from aveas_format.derive.kinematics import KinematicsParams


def estimate(pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray, x_std: np.ndarray,
             y_std: np.ndarray, xy_corr: np.ndarray, heading: np.ndarray | None,
             p: KinematicsParams) -> dict[str, np.ndarray]:
    """Kinematics of rows sorted by (participant, time): a dict of output columns (NaN where a
    segment is too short: fewer than 3 samples)."""
    n = len(t)
    out = {k: np.full(n, np.nan) for k in
           ("x", "y", "x_std", "y_std", "xy_corr", "speed", "vx", "vy", "ax", "ay", "a_lon",
            "a_lat", "jerk_lon", "speed_std", "vx_std", "vy_std", "vxvy_corr", "ax_std", "ay_std", "a_lon_std", "a_lat_std", "jerk_lon_std")}
    if n == 0:
        return out
    if n > 1:
        same = pid[1:] == pid[:-1]
        bad = same & ~(np.diff(t) > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise FormatError(f"derivation kinematics: table states: participant {int(pid[i])} has "
                              f"non-increasing time at {t[i + 1]!r} (rows must be sorted by "
                              "participant_id, time, unique)")
    bad = ~(np.isfinite(x) & np.isfinite(y) & np.isfinite(t))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FormatError(f"derivation kinematics: table states: participant {int(pid[i])} has a "
                          f"non-finite position or time at row {i}")
    sx = np.maximum(x_std, p.min_position_std)
    sy = np.maximum(y_std, p.min_position_std)
    rho = np.clip(np.nan_to_num(xy_corr), -0.999, 0.999)
    start, length = segments(pid, t, p.max_gap_s)
    if p.method == "savitzky_golay":
        res = savgol(t, x, y, sx, sy, start, length, p)
    else:
        res = kalman(t, x, y, sx, sy, rho, start, length, p)
    vx, vy, ax, ay, cov, jx, jy, jcov, px, py = res
    ok = np.repeat(length >= 3, length)
    _combine(out, vx, vy, ax, ay, cov, jx, jy, jcov, heading, p.min_speed)
    if "xx" in cov:
        out["x"], out["y"] = px, py
        out["x_std"], out["y_std"], out["xy_corr"] = _std_corr(cov["xx"], cov["yy"], cov["xy"])
    for k in out:
        out[k][~ok] = np.nan
    return out


def _combine(out, vx, vy, ax, ay, cov, jx, jy, jcov, heading, min_speed):
    """speed, the velocity (vx, vy, their std and correlation), a_lon, a_lat, jerk_lon and their
    std (delta method) into ``out``."""
    s = np.hypot(vx, vy)
    moving = s >= max(min_speed, 1e-9)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(moving, vx / s, np.cos(heading) if heading is not None else 1.0)
        uy = np.where(moving, vy / s, np.sin(heading) if heading is not None else 0.0)
        a_lon = ax * ux + ay * uy
        a_lat = ay * ux - ax * uy
        inv_s = np.where(moving, 1.0 / s, 0.0)
    # Jacobians w.r.t. (vx, vy, ax, ay); the velocity terms vanish when the heading gives u
    J_lon = ((ax - a_lon * ux) * inv_s, (ay - a_lon * uy) * inv_s, ux, uy)
    J_lat = ((ay - a_lat * ux) * inv_s, (-ax - a_lat * uy) * inv_s, -uy, ux)
    C = {("vx", "vx"): cov["vxvx"], ("vy", "vy"): cov["vyvy"], ("vx", "vy"): cov["vxvy"],
         ("ax", "ax"): cov["axax"], ("ay", "ay"): cov["ayay"], ("ax", "ay"): cov["axay"],
         ("vx", "ax"): cov["vxax"], ("vy", "ay"): cov["vyay"], ("vx", "ay"): cov["vxay"],
         ("vy", "ax"): cov["vyax"]}
    names = ("vx", "vy", "ax", "ay")

    def quad(J):
        v = np.zeros_like(s)
        for i, a in enumerate(names):
            for j, b in enumerate(names):
                c = C.get((a, b), C.get((b, a)))
                v = v + J[i] * J[j] * c
        return np.sqrt(np.maximum(v, 0.0))

    out["speed"] = s
    out["vx"], out["vy"] = vx, vy
    out["vx_std"], out["vy_std"], out["vxvy_corr"] = _std_corr(cov["vxvx"], cov["vyvy"],
                                                               cov["vxvy"])
    out["speed_std"] = np.sqrt(np.maximum(ux * ux * cov["vxvx"] + uy * uy * cov["vyvy"]
                                          + 2 * ux * uy * cov["vxvy"], 0.0))
    out["ax"], out["ay"] = ax, ay
    out["ax_std"] = np.sqrt(np.maximum(cov["axax"], 0.0))
    out["ay_std"] = np.sqrt(np.maximum(cov["ayay"], 0.0))
    out["a_lon"], out["a_lat"] = a_lon, a_lat
    out["a_lon_std"], out["a_lat_std"] = quad(J_lon), quad(J_lat)
    out["jerk_lon"] = jx * ux + jy * uy + a_lat * a_lat * inv_s
    out["jerk_lon_std"] = np.sqrt(np.maximum(ux * ux * jcov["xx"] + uy * uy * jcov["yy"]
                                             + 2 * ux * uy * jcov["xy"], 0.0))


def _std_corr(vxx: np.ndarray, vyy: np.ndarray, vxy: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Standard deviations and correlation of a 2x2 covariance ``[[vxx, vxy], [vxy, vyy]]``."""
    sx, sy = np.sqrt(np.maximum(vxx, 0.0)), np.sqrt(np.maximum(vyy, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(sx * sy > 0, np.clip(vxy / (sx * sy), -1.0, 1.0), 0.0)
    return sx, sy, r
