"""Kinematics: speed, acceleration, jerk and yaw-rate bounds per class, heading vs motion, jumps.

Limits are per class (``[classes.<class>]`` in the config) and flag data errors, not unusual driving:
speed and acceleration beyond them are errors, jerk, yaw rate and heading disagreements warnings
(noisier estimates).
Estimates are finite differences over a time baseline (``[kinematics] window_s``, 0.5 s) so that
measurement noise at high sample rates does not fake violations, and a limit counts as exceeded only
by more than ``z`` (3) sigma of the estimate, propagated from the ``_std`` columns (null std = 0).

- speed: from positions (x, y);
- acceleration and jerk: from the velocity columns (vx, vy), so that a single bad position is
  reported once, by kinematics.position_jump, and not again as an acceleration;
- yaw rate: from heading differences (above walking speed) and the ``yaw_rate`` column if present.

Findings are per participant: the first offending sample, the peak value and the number of samples.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from aveas_format.numeric import wrap_angle
from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hits, rule
from aveas_format.validate.rules.interactions import in_accident
from aveas_format.validate.views import StatesView

_F = {"file": "states.parquet", "table": "states"}


def _std(sv: StatesView, name: str) -> np.ndarray:
    v = sv.col(name)
    return np.zeros(sv.n) if v is None else np.nan_to_num(v, nan=0.0)


def per_participant(sv: StatesView, mask: np.ndarray, value: np.ndarray, digits: int | None = 3,
                    **const) -> Hits | None:
    """One finding per participant with ``mask`` set: its first such sample, the peak ``value``
    (rounded to ``digits``; None: unrounded) and the number of samples (``n_samples``)."""
    if not mask.any():
        return None
    idx = np.flatnonzero(mask)
    seg = sv.seg[idx]
    first = np.r_[0, np.flatnonzero(np.diff(seg)) + 1]
    counts = np.diff(np.r_[first, len(idx)])
    peak = np.maximum.reduceat(np.abs(value[idx]), first)
    i = idx[first]
    return Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i], "time": sv.t[i],
                                      "value": peak if digits is None else np.round(peak, digits), "n_samples": counts,
                                      "class_": sv.cls[i]},
                const={**_F, **const})


def _window(ctx: Context, sv: StatesView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, dt): finite-difference pairs over the window (cached per validation)."""
    key = "kinematics.window"
    if key not in ctx.cache:
        j = sv.ahead(ctx.config.kinematics.window_s)
        i = np.flatnonzero(j >= 0)
        j = j[i]
        ctx.cache[key] = (i, j, sv.t[j] - sv.t[i])
    return ctx.cache[key]


def _limit(ctx: Context, sv: StatesView, attr: str) -> np.ndarray:
    return sv.per_sample({c: getattr(lim, attr) for c, lim in ctx.config.classes.items()})


@rule("kinematics.speed", "error", "Speed impossible for the class",
      "states.parquet: row {row}: participant {participant_id} ({class_}) moves at {value} m/s "
      "(from positions; {n_samples} samples), above the {limit} m/s plausible for its class",
      enforces="docs/format.md §5: x, y are the participant's real positions; beyond the class's physical "
               "limit (configurable, by more than z sigma) they are a data error", scope="rows")
def speed(ctx: Context) -> Iterator[Hits]:
    """The speed over ground, estimated from positions over ``window_s``, exceeds the class's
    ``speed_max`` by more than z sigma (e.g. a car faster than 75 m/s: positions in the wrong unit,
    or two objects merged into one track)."""
    sv = ctx.states_view
    x, y = (sv.col("x"), sv.col("y")) if sv is not None else (None, None)
    if x is None or y is None:
        return
    i, j, dt = _window(ctx, sv)
    v = np.full(sv.n, np.nan)
    v[i] = np.hypot(x[j] - x[i], y[j] - y[i]) / dt
    sx, sy = _std(sv, "x_std"), _std(sv, "y_std")
    sig = np.zeros(sv.n)
    sig[i] = np.sqrt(sx[i] ** 2 + sx[j] ** 2 + sy[i] ** 2 + sy[j] ** 2) / dt
    lim = _limit(ctx, sv, "speed_max")
    bad = _exceeds(ctx, v, sig, lim)
    h = _with_limit(per_participant(sv, bad, v, None, column="x,y"), sv, lim)
    if h is not None:
        yield h


def _accel(ctx: Context, sv: StatesView):
    key = "kinematics.accel"
    if key not in ctx.cache:
        vx, vy = sv.col("vx"), sv.col("vy")
        if vx is None or vy is None:
            ctx.cache[key] = None
        else:
            i, j, dt = _window(ctx, sv)
            ax = np.full(sv.n, np.nan)
            ay = np.full(sv.n, np.nan)
            ax[i] = (vx[j] - vx[i]) / dt
            ay[i] = (vy[j] - vy[i]) / dt
            svx, svy = _std(sv, "vx_std"), _std(sv, "vy_std")
            sig = np.full(sv.n, np.nan)
            sig[i] = np.sqrt(svx[i] ** 2 + svx[j] ** 2 + svy[i] ** 2 + svy[j] ** 2) / dt
            ctx.cache[key] = (ax, ay, sig)
    return ctx.cache[key]


def _with_limit(h: Hits | None, sv: StatesView, lim: np.ndarray) -> Hits | None:
    """The limit of each finding's sample, and the value with enough digits to show the excess
    (40.0003 m/s above a 40.0 m/s limit, not "40.0 above 40.0")."""
    if h is not None:
        pos = np.empty(sv.n, np.int64)
        pos[sv.row] = np.arange(sv.n)
        h.arrays["limit"] = lim[pos[h.arrays["row"]]]
        h.arrays["value"] = distinct_digits(h.arrays["value"], h.arrays["limit"])
    return h


def distinct_digits(value: np.ndarray, limit: np.ndarray, least: int = 3, most: int = 9) -> np.ndarray:
    """``value`` rounded to ``least`` decimals, or to as many more (up to ``most``) as it takes to
    differ from ``limit`` rounded alike."""
    v, lim = np.asarray(value, np.float64), np.asarray(limit, np.float64)
    out = np.round(v, least)
    for d in range(least + 1, most + 1):
        same = np.round(v, d - 1) == np.round(lim, d - 1)
        if not same.any():
            break
        out = np.where(same, np.round(v, d), out)
    return out


def _exceeds(ctx: Context, value: np.ndarray, sig: np.ndarray, lim: np.ndarray) -> np.ndarray:
    """``value`` exceeds ``lim`` by more than z sigma; exact values (sigma 0: simulated) by more
    than ``exact_rel_tolerance`` of the limit (their last digit is the simulator's rounding)."""
    k = ctx.config.kinematics
    tol = np.where(np.nan_to_num(sig) == 0, k.exact_rel_tolerance * np.abs(lim), 0.0)
    with np.errstate(invalid="ignore"):
        return value - k.z * sig - lim > tol


@rule("kinematics.acceleration", "error", "Acceleration impossible for the class",
      "states.parquet: row {row}: participant {participant_id} ({class_}) accelerates at {value} "
      "m/s² (from vx, vy; {n_samples} samples), above the {limit} m/s² plausible for its class",
      enforces="docs/format.md §5: vx, vy are the participant's real velocity; accelerations beyond the "
               "class's physical limit (configurable, by more than z sigma) are a data error", scope="rows")
def acceleration(ctx: Context) -> Iterator[Hits]:
    """The magnitude of the planar acceleration, estimated from the velocity columns over
    ``window_s``, exceeds the class's ``accel_max`` by more than z sigma (e.g. a car braking at
    -50 g). Samples covered by an ``accident`` event naming the participant are exempt."""
    sv = ctx.states_view
    a = _accel(ctx, sv) if sv is not None else None
    if a is None:
        return
    ax, ay, sig = a
    mag = np.hypot(ax, ay)
    lim = _limit(ctx, sv, "accel_max")
    bad = _exceeds(ctx, mag, sig, lim)
    if bad.any():  # collisions are allowed to decelerate violently
        bad &= ~in_accident(ctx, sv.pid, sv.pid, sv.t)
    h = _with_limit(per_participant(sv, bad, mag, None, column="vx,vy"), sv, lim)
    if h is not None:
        yield h


@rule("kinematics.jerk", "warning", "Jerk implausible for the class",
      "states.parquet: row {row}: participant {participant_id} ({class_}) has a jerk of {value} "
      "m/s³ ({n_samples} samples), above the {limit} m/s³ plausible for its class", scope="rows",
      enforces=quality("plausible_motion"))
def jerk(ctx: Context) -> Iterator[Hits]:
    """The change of acceleration (from the velocity columns, two successive windows) exceeds
    the class's ``jerk_max`` by more than z sigma: velocities that step instead of changing
    smoothly."""
    sv = ctx.states_view
    a = _accel(ctx, sv) if sv is not None else None
    if a is None:
        return
    ax, ay, sig = a
    i, j, dt = _window(ctx, sv)
    ok = ~np.isnan(ax[j]) & ~np.isnan(ax[i])
    i, j, dt = i[ok], j[ok], dt[ok]
    jk = np.full(sv.n, np.nan)
    jk[i] = np.hypot(ax[j] - ax[i], ay[j] - ay[i]) / dt
    s = np.full(sv.n, np.nan)
    s[i] = np.sqrt(sig[i] ** 2 + sig[j] ** 2) / dt
    lim = _limit(ctx, sv, "jerk_max")
    bad = _exceeds(ctx, jk, s, lim)
    h = _with_limit(per_participant(sv, bad, jk, None, column="vx,vy"), sv, lim)
    if h is not None:
        yield h


@rule("kinematics.yaw_rate", "warning", "Yaw rate implausible for the class",
      "states.parquet: row {row}: participant {participant_id} ({class_}) turns at {value} rad/s "
      "({source}; {n_samples} samples), above the {limit} rad/s plausible for its class", scope="rows",
      enforces=quality("plausible_motion"))
def yaw_rate(ctx: Context) -> Iterator[Hits]:
    """The yaw rate exceeds the class's ``yaw_rate_max`` by more than z sigma: from heading
    differences over ``window_s`` while moving faster than walking speed (heading is noise at rest),
    and from the ``yaw_rate`` column where present."""
    sv = ctx.states_view
    if sv is None:
        return
    h, vx, vy = sv.col("heading"), sv.col("vx"), sv.col("vy")
    lim = _limit(ctx, sv, "yaw_rate_max")
    if h is not None and vx is not None and vy is not None:
        i, j, dt = _window(ctx, sv)
        sp = np.hypot(vx, vy)
        moving = (sp[i] > ctx.config.kinematics.walking_speed) & (sp[j] > ctx.config.kinematics.walking_speed)
        i, j, dt = i[moving], j[moving], dt[moving]
        w = np.full(sv.n, np.nan)
        w[i] = np.abs(wrap_angle(h[j] - h[i])) / dt
        hs = _std(sv, "heading_std")
        s = np.zeros(sv.n)
        s[i] = np.sqrt(hs[i] ** 2 + hs[j] ** 2) / dt
        hh = _with_limit(per_participant(sv, _exceeds(ctx, w, s, lim), w, None, column="heading",
                                         source="from heading"), sv, lim)
        if hh is not None:
            yield hh
    yr = sv.col("yaw_rate")
    if yr is not None:
        s = _std(sv, "yaw_rate_std")
        hh = _with_limit(per_participant(sv, _exceeds(ctx, np.abs(yr), s, lim), yr, None,
                                         column="yaw_rate",
                                         source="column yaw_rate"), sv, lim)
        if hh is not None:
            yield hh


@rule("kinematics.heading_vs_motion", "warning", "Heading disagrees with the direction of motion",
      "states.parquet: row {row}: participant {participant_id} ({class_}) moves {value} rad away "
      "from its heading at {speed} m/s ({n_samples} samples)", scope="rows",
      enforces=quality("heading_motion"))
def heading_vs_motion(ctx: Context) -> Iterator[Hits]:
    """A vehicle (car, van, truck, bus, motorcycle, trailer, rail vehicle) moving faster than
    ``walking_speed`` has a heading more than ``heading_tolerance`` (+ z sigma) away from the
    direction of its velocity. Reversing (heading opposite to motion) is accepted below
    ``max_reverse_speed``. Typical causes: heading in degrees, or measured clockwise."""
    sv = ctx.states_view
    if sv is None:
        return
    h, vx, vy = sv.col("heading"), sv.col("vx"), sv.col("vy")
    if h is None or vx is None or vy is None:
        return
    k = ctx.config.kinematics
    sp = np.hypot(vx, vy)
    moving = sv.vehicle & (sp > k.walking_speed)
    diff = np.abs(wrap_angle(h - np.arctan2(vy, vx)))
    sig = np.sqrt(_std(sv, "heading_std") ** 2 +
                  (np.hypot(_std(sv, "vx_std"), _std(sv, "vy_std")) / np.maximum(sp, 1e-9)) ** 2)
    tol = k.heading_tolerance + k.z * sig
    reversing = (diff > np.pi - tol) & (sp < k.max_reverse_speed)
    bad = moving & (diff > tol) & ~reversing
    hh = per_participant(sv, bad, diff, column="heading")
    if hh is not None:
        pos = np.empty(sv.n, np.int64)
        pos[sv.row] = np.arange(sv.n)
        hh.arrays["speed"] = np.round(sp[pos[hh.arrays["row"]]], 2)
        yield hh


def _steps(sv: StatesView):
    """Consecutive samples of a participant, ``(i, j, dt)`` with dt > 0."""
    i = np.flatnonzero(sv.same)
    j = i + 1
    dt = sv.t[j] - sv.t[i]
    ok = dt > 0
    return i[ok], j[ok], dt[ok]


def instant_lane_change_steps(ctx: Context) -> np.ndarray | None:
    """Per sample j: the step from j-1 is an instantaneous lane change (cached;
    :func:`aveas_format.numeric.instant_lateral_steps` on the stored road coordinates through the
    map); None without road coordinates or map."""
    key = "kinematics.instant_lane_change"
    if key in ctx.cache:
        return ctx.cache[key]
    from aveas_format.numeric import instant_lateral_steps
    from aveas_format.validate.rules.map import road_eval

    sv = ctx.states_view
    out = None
    e = road_eval(ctx) if sv is not None and sv.n > 1 else None
    x, y, vx, vy = (sv.col(c) for c in ("x", "y", "vx", "vy")) if sv is not None else (None,) * 4
    if e is not None and x is not None and y is not None:
        hdg = np.where(e["known"], e["hdg"], np.nan)
        width = np.abs(e["outer"] - e["inner"])
        nx, ny = -np.sin(hdg), np.cos(hdg)
        vlat = (np.nan_to_num(vx) * nx + np.nan_to_num(vy) * ny) if vx is not None and vy is not None \
            else np.zeros(sv.n)
        changed = (e["codes"][1:] != e["codes"][:-1]) | (e["lane"][1:] != e["lane"][:-1])
        jumps = instant_lateral_steps(sv.same, np.diff(sv.t), np.diff(x), np.diff(y), hdg[:-1],
                                      width[:-1], changed, 0.5 * (vlat[1:] + vlat[:-1]),
                                      ctx.config.kinematics.max_lateral_speed)
        out = np.r_[False, jumps]
        ctx.cache[key + ".across"] = np.r_[0.0, np.abs(np.diff(x) * nx[:-1] + np.diff(y) * ny[:-1])]
    ctx.cache[key] = out
    return out


@rule("kinematics.instant_lane_change", "error", "Instantaneous lane change (a simulator artefact)",
      "states.parquet: row {row}: participant {participant_id} ({class_}) changes lane "
      "instantaneously {n_samples} time(s), first at {time} s: it jumps up to {value} m across the "
      "lane in {dt} s with no lateral velocity. A simulator moved it without a lateral manoeuvre "
      "(SUMO's default); remedies: simulate with --lanechange.duration (e.g. 3) or the sublane "
      "model (--lateral-resolution 0.8), or convert with -O lane_change_duration=3 (sumo-fcd) to "
      "reconstruct a smooth manoeuvre",
      enforces="docs/format.md §5: x, y are the participant's real positions and vx, vy its velocity: a "
               "vehicle crosses into the adjacent lane by moving across it, not in one time step",
      scope="rows")
def instant_lane_change(ctx: Context) -> Iterator[Hits]:
    """A vehicle jumps about one lane width (0.5-1.5 widths) into the adjacent lane in one step,
    faster than ``max_lateral_speed``, while its velocity explains less than half of the jump: an
    instantaneous lane change, which simulators write by default. One finding per participant
    (the first jump, the largest, their number); these steps are not reported again by
    ``kinematics.position_jump``."""
    sv = ctx.states_view
    jumps = instant_lane_change_steps(ctx) if sv is not None else None
    if jumps is None or not jumps.any():
        return
    h = per_participant(sv, jumps, ctx.cache["kinematics.instant_lane_change.across"], column="x,y")
    if h is not None:
        pos = np.empty(sv.n, np.int64)
        pos[sv.row] = np.arange(sv.n)
        k = pos[h.arrays["row"]]
        h.arrays["dt"] = np.round(sv.t[k] - sv.t[k - 1], 6)
        yield h


@rule("kinematics.position_jump", "error", "Position jump inconsistent with the velocity",
      "states.parquet: row {row}: participant {participant_id} moves {step} m in {dt} s, but its "
      "velocity integrates to {expected} m: off by {value} m ({along} m along its motion, {across} m "
      "across; tolerance {tolerance} m)",
      enforces="docs/format.md §5: vx, vy are the velocity of the reference point x, y in the local frame", scope="rows")
def position_jump(ctx: Context) -> Iterator[Hits]:
    """Between two consecutive samples of a participant, the displacement differs from the
    velocity integrated over the step (trapezoid rule) by more than ``jump_tolerance_m`` + ``jump_z``
    sigma (from the x/y and vx/vy ``_std`` columns) + half the class's acceleration limit times
    dt² — a teleport of the track (ID switch, bad frame), or velocities inconsistent with positions
    (wrong unit or frame). The message splits the offset along and across the integrated motion
    (a lateral offset of a lane width is a lane change without lateral motion); steps that
    ``kinematics.instant_lane_change`` reports are left to it."""
    sv = ctx.states_view
    if sv is None or sv.n < 2:
        return
    x, y, vx, vy = sv.col("x"), sv.col("y"), sv.col("vx"), sv.col("vy")
    if x is None or y is None or vx is None or vy is None:
        return
    i, j, dt = _steps(sv)
    mx, my = 0.5 * (vx[i] + vx[j]) * dt, 0.5 * (vy[i] + vy[j]) * dt
    ex = x[j] - x[i] - mx
    ey = y[j] - y[i] - my
    err = np.hypot(ex, ey)
    sx, sy, svx, svy = (_std(sv, c) for c in ("x_std", "y_std", "vx_std", "vy_std"))
    sig = np.sqrt(sx[i] ** 2 + sx[j] ** 2 + sy[i] ** 2 + sy[j] ** 2
                  + 0.25 * dt ** 2 * (svx[i] ** 2 + svx[j] ** 2 + svy[i] ** 2 + svy[j] ** 2))
    amax = np.nan_to_num(_limit(ctx, sv, "accel_max")[i], nan=15.0)
    k = ctx.config.kinematics
    tol = k.jump_tolerance_m + k.jump_z * sig + 0.5 * amax * dt ** 2
    bad = err > tol
    if bad.any():
        lane = instant_lane_change_steps(ctx)
        if lane is not None:
            bad &= ~lane[j]
    if bad.any():
        b = np.flatnonzero(bad)
        ii, jj = i[b], j[b]
        step = np.hypot(x[jj] - x[ii], y[jj] - y[ii])
        expected = np.hypot(mx[b], my[b])
        # the offset along the integrated motion (else along the heading, else the step) and across
        h = sv.col("heading")
        ang = np.arctan2(my[b], mx[b])
        if h is not None:
            ang = np.where(expected > 1e-6, ang, np.nan_to_num(h[ii]))
        along = ex[b] * np.cos(ang) + ey[b] * np.sin(ang)
        across = -ex[b] * np.sin(ang) + ey[b] * np.cos(ang)
        yield Hits(total=len(b), arrays={
            "row": sv.row[jj], "participant_id": sv.pid[jj], "time": sv.t[jj], "x": x[jj],
            "y": y[jj], "step": np.round(step, 3), "dt": np.round(dt[b], 6),
            "expected": np.round(expected, 3), "value": np.round(err[b], 3),
            "along": np.round(along, 3) + 0.0, "across": np.round(np.abs(across), 3),
            "tolerance": np.round(tol[b], 3)}, const={**_F, "column": "x,y"})
