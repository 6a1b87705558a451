"""The collision probability of an encounter: the share of variations of the recorded encounter
in which the two footprints touch.

The paper's near miss is "a scenario in which an accident was averted predominantly due to
stochastic effects, not (exclusively) due to the controlled behaviour of the involved parties";
"a variation of a near miss scenario under stochastic parameters determined from the
data-driven approach should approximate the actual accident statistics". A constant-velocity
extrapolation collides whenever TTC is finite, so it cannot tell the two apart; the recorded
motion can: it contains the evasive action that was taken. So each participant keeps its
recorded (smoothed) path and speed profile from the reference time ``t_r`` on — the evasive
action as it happened — varied by what is not fixed:

- its state at ``t_r`` within the stated uncertainty: position, velocity (the smoothed states'
  covariances of derived/kinematics), heading and size;
- its acceleration over the horizon, along and across its path, by a Gaussian process with a
  squared-exponential kernel of length ``length_s`` (1.4 s): along the path with the variance of
  the recorded acceleration's uncertainty (kinematics' ``ax_std``/``ay_std``) plus a driver's
  own variability ``driver_std`` (0.2 m/s², the stochastic IDM calibrated on highD, docs), across
  it with the recorded uncertainty only (lane keeping is controlled);
- along the path the speed is ``max(v(τ) + δv(τ), 0)`` while the participant moves; one that
  stopped stays stopped (a stop is a decision the variation keeps; where it stops varies with
  the braking); across, the offset grows by the integral of the lateral deviation while it moves.

Contact between two draws' consecutive samples is exact for the constant velocity between them
(the separating-axis first contact of :func:`~aveas_format.derive.interactions.ttc_boxes` within
the step). The probability is the share of ``samples`` draws (keyed by seed, pair and time, so it
does not depend on the other rows) that touch within ``horizon`` s after ``t_r``; its std is the
binomial one (Agresti-Coull), with a 95 % Wilson interval. docs/derive.md "Collision
probability" has the calibration.
"""

from __future__ import annotations

import numpy as np

from aveas_format.derive._samples import Samples
from aveas_format.derive.events._episodes import wilson
from aveas_format.derive.interactions import ttc_boxes
from aveas_format.numeric import keyed_normals

#: below this speed (m/s) a participant stands: no variation moves it
V_STOP = 0.5


class Tracks:
    """The rows of :class:`Samples` per participant in time order."""

    def __init__(self, S: Samples) -> None:
        self.S = S
        self.order = np.lexsort((S.t, S.pid))
        self.pid = S.pid[self.order]
        self.t = S.t[self.order]

    def rows(self, pid: int, t0: float, t1: float) -> np.ndarray:
        """The rows of participant ``pid`` with ``t0 <= time <= t1`` (in time order)."""
        lo = int(np.searchsorted(self.pid, pid, "left"))
        hi = int(np.searchsorted(self.pid, pid, "right"))
        a = lo + int(np.searchsorted(self.t[lo:hi], t0 - 1e-9, "left"))
        b = lo + int(np.searchsorted(self.t[lo:hi], t1 + 1e-9, "right"))
        return self.order[a:b]

    def first_time(self, pid: int) -> float:
        lo = int(np.searchsorted(self.pid, pid, "left"))
        return float(self.t[lo]) if lo < len(self.t) and self.pid[lo] == pid else np.nan


def _path(S: Samples, rows: np.ndarray, times: np.ndarray) -> dict[str, np.ndarray]:
    """The recorded motion of one participant at ``times`` (interpolated) and its uncertainty at
    the first of them."""
    t = S.t[rows]
    h = np.unwrap(S.h[rows])
    out = {c: np.interp(times, t, getattr(S, c)[rows]) for c in ("x", "y", "vx", "vy")}
    out["h"] = np.interp(times, t, h)
    k = rows[int(np.searchsorted(t, times[0] - 1e-9))] if len(rows) else rows[0]
    for c in ("sx", "sy", "rxy", "svx", "svy", "rv", "sax", "say", "sh", "L", "W", "sL", "sW"):
        out[c] = float(np.nan_to_num(getattr(S, c)[k]))
    return out


def _gp_factor(times: np.ndarray, length_s: float) -> np.ndarray:
    """A factor ``F`` with ``F F^T`` the squared-exponential correlation of ``times`` (unit
    variance): ``z @ F.T`` turns ``(K, M)`` standard normals into ``K`` paths of the process."""
    d = times[:, None] - times[None, :]
    C = np.exp(-0.5 * (d / max(length_s, 1e-6)) ** 2)
    w, V = np.linalg.eigh(C)  # the kernel matrix is near-singular on a fine grid: no Cholesky
    return V * np.sqrt(np.clip(w, 0.0, None))


def _vary(path: dict[str, np.ndarray], times: np.ndarray, z: np.ndarray, F: np.ndarray,
          driver_std: float):
    """``(x, y, heading, length, width)`` of the ``K`` variations (each ``(K, M)`` or ``(K, 1)``)
    of one participant's recorded motion; ``z``: ``(7 + 2 M, K)`` standard normals, ``F``: the
    acceleration process's factor (:func:`_gp_factor`)."""
    P = path
    M = len(times)
    r = np.clip(P["rxy"], -0.999, 0.999)
    rv = np.clip(P["rv"], -0.999, 0.999)
    dpx = P["sx"] * z[0]
    dpy = P["sy"] * (r * z[0] + np.sqrt(1 - r * r) * z[1])
    dvx = P["svx"] * z[2]
    dvy = P["svy"] * (rv * z[2] + np.sqrt(1 - rv * rv) * z[3])
    speed = np.hypot(P["vx"], P["vy"])
    moving = speed > V_STOP
    with np.errstate(invalid="ignore", divide="ignore"):
        ux = np.where(moving, P["vx"] / speed, np.cos(P["h"]))
        uy = np.where(moving, P["vy"] / speed, np.sin(P["h"]))
    u0x, u0y = ux[0], uy[0]
    dv_lon, dv_lat = dvx * u0x + dvy * u0y, -dvx * u0y + dvy * u0x
    # the recorded acceleration's uncertainty along and across the path at t_r
    sa_lon = np.sqrt((P["sax"] * u0x) ** 2 + (P["say"] * u0y) ** 2 + driver_std ** 2)
    sa_lat = np.sqrt((P["sax"] * u0y) ** 2 + (P["say"] * u0x) ** 2)
    da_lon = sa_lon * (z[7:7 + M].T @ F.T)  # (K, M)
    da_lat = sa_lat * (z[7 + M:7 + 2 * M].T @ F.T)
    dt = np.diff(times)[None, :]
    K = z.shape[1]

    def integral(a):  # (K, M): the integral from t_r, trapezoidal
        return np.concatenate([np.zeros((K, 1)), np.cumsum(0.5 * (a[:, 1:] + a[:, :-1]) * dt,
                                                           axis=1)], axis=1)

    vp = np.where(moving, np.maximum(speed + dv_lon[:, None] + integral(da_lon), 0.0), 0.0)
    ds = integral(vp - np.where(moving, speed, 0.0))
    dd = integral(np.where(moving, dv_lat[:, None] + integral(da_lat), 0.0))
    x = P["x"] + dpx[:, None] + ds * ux - dd * uy
    y = P["y"] + dpy[:, None] + ds * uy + dd * ux
    h = P["h"] + P["sh"] * z[4][:, None]
    L = np.maximum(P["L"] + P["sL"] * z[5], 0.1)[:, None]
    W = np.maximum(P["W"] + P["sW"] * z[6], 0.1)[:, None]
    return x, y, h, L, W


def collision_probability(tracks: Tracks, a: int, b: int, t_ref: float, horizon: float,
                          samples: int, seed: int, driver_std: float = 0.2,
                          length_s: float = 1.4) -> dict[str, float] | None:
    """The collision probability of participants ``a`` and ``b`` from ``t_ref`` on (module
    docstring): ``{"p", "std", "low", "high", "t_ref", "horizon"}``, None where the two are not
    both observed at two or more common times in the window. Its matrices are small (one row
    per time step of the horizon): callers of many run them within :func:`one_blas_thread`."""
    return _probability(tracks, a, b, t_ref, horizon, samples, seed, driver_std, length_s)


def one_blas_thread():
    """A context in which BLAS runs on one thread: the collision probabilities' small matrices
    would only oversubscribe the cores with BLAS's threads (docs/architecture.md "Dependencies
    and why"); entered once per batch of encounters (entering it costs ~2 ms)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1)


def _first_contacts(xa, ya, ha, La, Wa, xb, yb, hb, Lb, Wb, dt) -> np.ndarray:
    """The draws (``(K, M)`` positions and headings, ``(K, 1)`` sizes) whose footprints touch
    between consecutive samples (constant velocity within a step): a boolean ``(K,)``. The exact
    box test (:func:`~aveas_format.derive.interactions.ttc_boxes`) runs only where the two discs
    around the footprints (radius half the diagonal) can meet within the step — the centres'
    distance less their relative displacement within reach — a necessary condition, so the
    result is the test's on every step."""
    vax, vay = np.diff(xa, axis=1) / dt, np.diff(ya, axis=1) / dt
    vbx, vby = np.diff(xb, axis=1) / dt, np.diff(yb, axis=1) / dt
    reach = 0.5 * (np.hypot(La, Wa) + np.hypot(Lb, Wb)) + 1e-6
    near = (np.hypot(xb[:, :-1] - xa[:, :-1], yb[:, :-1] - ya[:, :-1])
            - np.hypot(vbx - vax, vby - vay) * dt) <= reach
    k, m = np.nonzero(near)
    first = ttc_boxes(xa[k, m], ya[k, m], ha[k, m], La[k, 0], Wa[k, 0], vax[k, m], vay[k, m],
                      xb[k, m], yb[k, m], hb[k, m], Lb[k, 0], Wb[k, 0], vbx[k, m], vby[k, m])
    hit = np.zeros(len(xa), bool)
    hit[k[first <= dt[0, m]]] = True
    return hit


def _probability(tracks: Tracks, a: int, b: int, t_ref: float, horizon: float, samples: int,
                 seed: int, driver_std: float, length_s: float) -> dict[str, float] | None:
    S = tracks.S
    ra = tracks.rows(a, t_ref, t_ref + horizon)
    rb = tracks.rows(b, t_ref, t_ref + horizon)
    if len(ra) < 2 or len(rb) < 2 or samples < 1:
        return None
    times = S.t[ra]
    times = times[(times >= S.t[rb][0] - 1e-9) & (times <= S.t[rb][-1] + 1e-9)]
    if len(times) < 2:
        return None
    tkey = np.array([int(round(times[0] * 1e6))], np.int64)
    F = _gp_factor(times, length_s)
    n = 7 + 2 * len(times)
    var = []
    for p, q in ((a, b), (b, a)):
        z = keyed_normals(seed, (np.array([p]), np.array([q]), tkey), n * samples)
        var.append(_vary(_path(S, tracks.rows(p, t_ref, t_ref + horizon), times), times,
                         z.reshape(n, samples), F, driver_std))
    (xa, ya, ha, La, Wa), (xb, yb, hb, Lb, Wb) = var
    hits = float(_first_contacts(xa, ya, ha, La, Wa, xb, yb, hb, Lb, Wb,
                                 np.diff(times)[None, :]).sum())
    pt = (hits + 2.0) / (samples + 4.0)  # Agresti-Coull
    lo, hi = wilson(np.array(hits), samples)
    return {"p": hits / samples, "std": float(np.sqrt(pt * (1 - pt) / (samples + 4.0))),
            "low": float(lo), "high": float(hi), "t_ref": float(times[0]),
            "horizon": float(times[-1] - times[0])}


__all__ = ["V_STOP", "Tracks", "collision_probability", "one_blas_thread"]
