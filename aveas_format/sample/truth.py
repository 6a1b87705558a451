"""The collision probability of the scenes' truth, simulated independently of the derivations
(docs/derive.md "Collision probability"): the model of
:mod:`aveas_format.derive.events._collision` written again from its description — the true
(noise-free) motion of both participants from the event's reference time, varied within the
distributions the recording states (the smoothed states' std of derived/kinematics at that time,
the heading and size std, a driver's acceleration variability), positions integrated on a 100 Hz
grid, footprints intersected by shapely. :func:`truth_collides` is what the calibration of
``benchmarks/bench_near_miss.py`` and ``tests/derive/test_near_miss.py`` compares the derived
probability with.
"""

from __future__ import annotations

import json

import numpy as np

def se_factor(times: np.ndarray, length_s: float) -> np.ndarray:
    """A factor ``F`` with ``F F^T`` the squared-exponential correlation of ``times``."""
    d = times[:, None] - times[None, :]
    w, V = np.linalg.eigh(np.exp(-0.5 * (d / length_s) ** 2))
    return V * np.sqrt(np.clip(w, 0.0, None))


def _truth_variation(tr: dict, pid: int, t_ref: float, grid: np.ndarray, sd: dict,
                     rng: np.random.Generator, F: np.ndarray, driver_std: float = 0.2):
    """One variation of participant ``pid``'s true motion from ``t_ref`` on (the model of
    docs/derive.md "Collision probability", written again here: positions on ``grid`` by the
    trapezoidal rule, the acceleration process from ``F``); returns ``(x, y, heading, L, W)``."""
    m = tr["participant_id"] == pid
    t = tr["time"][m]
    x, y, vx, vy, h = (np.interp(grid, t, tr[c][m]) for c in ("x", "y", "vx", "vy", "heading"))
    speed = np.hypot(vx, vy)
    moving = speed > 0.5
    ux, uy = np.where(moving, vx / np.maximum(speed, 1e-9), np.cos(h)), \
        np.where(moving, vy / np.maximum(speed, 1e-9), np.sin(h))
    dp = rng.normal(0, [sd["sx"], sd["sy"]])
    dv = rng.normal(0, [sd["svx"], sd["svy"]])
    dvl, dvt = dv[0] * ux[0] + dv[1] * uy[0], -dv[0] * uy[0] + dv[1] * ux[0]
    sl = np.sqrt((sd["sax"] * ux[0]) ** 2 + (sd["say"] * uy[0]) ** 2 + driver_std ** 2)
    st_ = np.sqrt((sd["sax"] * uy[0]) ** 2 + (sd["say"] * ux[0]) ** 2)
    al = sl * (F @ rng.standard_normal(len(grid)))
    at = st_ * (F @ rng.standard_normal(len(grid)))
    dt = np.diff(grid)

    def cum(a):
        return np.r_[0.0, np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)]

    vp = np.where(moving, np.maximum(speed + dvl + cum(al), 0.0), 0.0)
    ds = cum(vp - np.where(moving, speed, 0.0))
    dd = cum(np.where(moving, dvt + cum(at), 0.0))
    return (x + dp[0] + ds * ux - dd * uy, y + dp[1] + ds * uy + dd * ux,
            h + rng.normal(0, sd["sh"]), max(sd["L"] + rng.normal(0, sd["sL"]), 0.1),
            max(sd["W"] + rng.normal(0, sd["sW"]), 0.1))


def _footprints(x, y, h, L, W):
    """Shapely rectangles of the footprints (arrays of centres and headings)."""
    import shapely

    c, s = np.cos(h), np.sin(h)
    corners = []
    for a, b in ((0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)):
        corners.append(np.stack([x + a * L * c - b * W * s, y + a * L * s + b * W * c], -1))
    return shapely.polygons(np.stack(corners, -2))


def _stated(rec, pid: int, t_ref: float) -> dict:
    """What the recording states about participant ``pid`` at ``t_ref``: the smoothed states'
    std (derived/kinematics), the heading std (states) and the size with its std."""
    import pyarrow.compute as pc

    k = rec.derived["kinematics"]
    k = k.filter(pc.equal(k["participant_id"], pid)).to_pandas()
    r = k.iloc[int(np.argmin(np.abs(k.time.to_numpy() - t_ref)))]
    s = rec.states.filter(pc.equal(rec.states["participant_id"], pid)).to_pandas()
    p = rec.participants.filter(pc.equal(rec.participants["participant_id"], pid)).to_pylist()[0]
    f = lambda v: 0.0 if v is None or not np.isfinite(v) else float(v)  # noqa: E731
    return {"sx": f(r.x_std), "sy": f(r.y_std), "svx": f(r.vx_std), "svy": f(r.vy_std),
            "sax": f(r.ax_std), "say": f(r.ay_std), "sh": f(s.heading_std.median()),
            "L": p["length"], "W": p["width"], "sL": f(p["length_std"]), "sW": f(p["width_std"])}


def truth_collides(rec, truth: dict, event: dict, rng: np.random.Generator, draws: int = 1
                   ) -> float:
    """The share of ``draws`` variations of the *true* encounter of ``event`` (its pair, from the
    reference time its attributes record, over its horizon) whose footprints intersect on a
    100 Hz grid (shapely)."""
    import shapely

    a, b = event["participant_ids"]
    cp = json.loads(event["attributes"])["collision_probability"]
    grid = cp["t_ref"] + np.arange(int(round(cp["horizon_s"] * 100)) + 1) / 100.0
    F = se_factor(grid, 1.4)
    sa, sb = _stated(rec, a, cp["t_ref"]), _stated(rec, b, cp["t_ref"])
    hits = 0
    for _ in range(draws):
        A = _footprints(*_truth_variation(truth["states"], a, cp["t_ref"], grid, sa, rng, F))
        B = _footprints(*_truth_variation(truth["states"], b, cp["t_ref"], grid, sb, rng, F))
        hits += bool(shapely.intersects(A, B).any())
    return hits / draws


__all__ = ["se_factor", "truth_collides"]
