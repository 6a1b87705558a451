"""Positions and velocities of the interactions: the choice between the measured and the smoothed
ones (parameter ``velocities``), projections on a direction and the range rate of a pair."""

from __future__ import annotations

import numpy as np

from aveas_format.derive._samples import Samples


def smoothed_velocities(S: Samples, mode: str) -> int:
    """Replace the states' positions and velocities by derived/kinematics' smoothed ones where
    ``mode`` is ``smoothed``, or ``auto`` and the smoothed ones are the more precise: each vector
    with its covariance (``x``, ``y`` or ``vx``, ``vy``, their std and correlation) where the
    smoothed covariance has the smaller trace (``S.shift_x``, ``S.shift_y``: smoothed minus
    measured position, 0 where kept, for the lane coordinates); where the kinematics table carries
    no velocity vector (written before it did), the along-motion component only (the smoothed
    ``speed``), keeping the measured across-motion component and its variance, for samples moving
    at >= 0.5 m/s. Exact positions and velocities (std 0) are kept by ``auto``. Returns the number
    of velocities replaced."""
    x0, y0 = np.array(S.x, np.float64), np.array(S.y, np.float64)
    _take_smoothed(S, ("x", "y", "sx", "sy", "rxy"), mode)
    S.shift_x, S.shift_y = S.x - x0, S.y - y0
    vec = _take_smoothed(S, ("vx", "vy", "svx", "svy", "rv"), mode)
    have = np.isfinite(S.k_vx)
    speed, speed_std = S.k_speed, S.k_speed_std
    v = np.hypot(S.vx, S.vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        c, sn = S.vx / v, S.vy / v
    cxy = S.rv * S.svx * S.svy
    var_along = c * c * S.svx ** 2 + sn * sn * S.svy ** 2 + 2 * c * sn * cxy
    var_across = sn * sn * S.svx ** 2 + c * c * S.svy ** 2 - 2 * c * sn * cxy
    use = ~have & (v >= 0.5) & np.isfinite(speed) & np.isfinite(speed_std)
    if mode == "auto":
        use &= speed_std ** 2 < var_along
    if not use.any():
        return int(vec.sum())
    c, sn, sa, sw = c[use], sn[use], speed_std[use] ** 2, np.maximum(var_across[use], 0.0)
    S.vx[use], S.vy[use] = speed[use] * c, speed[use] * sn
    vxx, vyy, vxy = sa * c * c + sw * sn * sn, sa * sn * sn + sw * c * c, (sa - sw) * c * sn
    S.svx[use], S.svy[use] = np.sqrt(vxx), np.sqrt(vyy)
    with np.errstate(invalid="ignore", divide="ignore"):
        S.rv[use] = np.where((vxx > 0) & (vyy > 0), vxy / np.sqrt(vxx * vyy), 0.0)
    return int(vec.sum() + use.sum())


def _take_smoothed(S: Samples, names: tuple[str, str, str, str, str], mode: str) -> np.ndarray:
    """Replace the vector ``names`` (two components, their std and correlation) of ``S`` by
    derived/kinematics' (``k_`` + name) where it is given and, for ``auto``, its covariance has
    the smaller trace; returns where it was replaced."""
    cur = [np.array(getattr(S, n), np.float64) for n in names]
    new = [getattr(S, f"k_{n}") for n in names]
    use = np.isfinite(new[0]) & np.isfinite(new[1]) & np.isfinite(new[2]) & np.isfinite(new[3])
    if mode == "auto":
        use &= new[2] ** 2 + new[3] ** 2 < cur[2] ** 2 + cur[3] ** 2
    for n, c, k in zip(names, cur, new):
        c[use] = np.nan_to_num(k[use]) if n in ("rxy", "rv") else k[use]
        setattr(S, n, c)
    return use


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


def range_rate_var(S: Samples, i, j):
    """Variance of :func:`range_rate` by the delta method: the relative velocity's covariance
    along the line of centres plus the relative position's covariance across it, scaled by the
    across component of the relative velocity over the distance."""
    dx, dy = S.x[j] - S.x[i], S.y[j] - S.y[i]
    wx, wy = S.vx[j] - S.vx[i], S.vy[j] - S.vy[i]
    d = np.hypot(dx, dy)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux, uy = np.where(d > 0, dx / d, 1.0), np.where(d > 0, dy / d, 0.0)
        along = wx * ux + wy * uy
        cx, cy = (wx - along * ux) / np.where(d > 0, d, np.inf), (wy - along * uy) / np.where(
            d > 0, d, np.inf)

    def quad(a, b, sx, sy, r):
        return (a * sx) ** 2 + (b * sy) ** 2 + 2 * a * b * r * sx * sy

    return (quad(ux, uy, S.svx[i], S.svy[i], S.rv[i]) + quad(ux, uy, S.svx[j], S.svy[j], S.rv[j])
            + quad(cx, cy, S.sx[i], S.sy[i], S.rxy[i]) + quad(cx, cy, S.sx[j], S.sy[j], S.rxy[j]))
