"""Velocities of the interactions: the choice between the measured and the smoothed speed along
the motion (parameter ``velocities``), projections on a direction and the range rate of a pair."""

from __future__ import annotations

import numpy as np

from aveas_format.derive._samples import Samples


def smoothed_velocities(S: Samples, mode: str) -> int:
    """Replace the along-motion component of the states' velocity by derived/kinematics' smoothed
    speed (with its std), keeping the across-motion component and its variance, where ``mode`` is
    ``smoothed``, or ``auto`` and the smoothed std is the smaller. Only samples moving at >= 0.5
    m/s (a defined direction of motion). Returns the number of samples replaced."""
    speed, speed_std = S.k_speed, S.k_speed_std
    v = np.hypot(S.vx, S.vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        c, sn = S.vx / v, S.vy / v
    cxy = S.rv * S.svx * S.svy
    var_along = c * c * S.svx ** 2 + sn * sn * S.svy ** 2 + 2 * c * sn * cxy
    var_across = sn * sn * S.svx ** 2 + c * c * S.svy ** 2 - 2 * c * sn * cxy
    use = (v >= 0.5) & np.isfinite(speed) & np.isfinite(speed_std)
    if mode == "auto":
        use &= speed_std ** 2 < var_along
    if not use.any():
        return 0
    c, sn, sa, sw = c[use], sn[use], speed_std[use] ** 2, np.maximum(var_across[use], 0.0)
    S.vx, S.vy, S.svx, S.svy, S.rv = (np.array(a, np.float64)
                                      for a in (S.vx, S.vy, S.svx, S.svy, S.rv))
    S.vx[use], S.vy[use] = speed[use] * c, speed[use] * sn
    vxx, vyy, vxy = sa * c * c + sw * sn * sn, sa * sn * sn + sw * c * c, (sa - sw) * c * sn
    S.svx[use], S.svy[use] = np.sqrt(vxx), np.sqrt(vyy)
    with np.errstate(invalid="ignore", divide="ignore"):
        S.rv[use] = np.where((vxx > 0) & (vyy > 0), vxy / np.sqrt(vxx * vyy), 0.0)
    return int(use.sum())


def var_along(S: Samples, i, c, sn):
    """Variances of position, velocity and acceleration of rows ``i`` projected on the unit
    vector (c, sn)."""
    vp = (c * S.sx[i]) ** 2 + (sn * S.sy[i]) ** 2 + 2 * c * sn * S.rxy[i] * S.sx[i] * S.sy[i]
    vv = (c * S.svx[i]) ** 2 + (sn * S.svy[i]) ** 2 + 2 * c * sn * S.rv[i] * S.svx[i] * S.svy[i]
    va = (c * S.sax[i]) ** 2 + (sn * S.say[i]) ** 2
    return vp, vv, va


def range_rate(S: Samples, i, j):
    """Rate at which the centre distance of rows i and j shrinks (positive = approaching)."""
    dx, dy = S.x[j] - S.x[i], S.y[j] - S.y[i]
    dvx, dvy = S.vx[j] - S.vx[i], S.vy[j] - S.vy[i]
    d = np.hypot(dx, dy)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, -(dx * dvx + dy * dvy) / d, 0.0)
