"""``derived/conflicts``: crossing and merging conflicts at the crossing point of two paths, per
time step, as SUMO's SSM device defines them (docs/derive.md "Crossing conflicts"): predicted
entry and exit of the conflict area, crossing TTC, DRAC and predicted PET (PPET), and the PET
observed at that point.

**Conflict point.** The paths are the recorded tracks of the participants' front bumpers (the
footprint centre moved forward by half the length along the heading: the point SUMO keeps on its
lane centre line); the conflict point of a pair is the first intersection of the two paths whose
directions differ by at least ``min_angle``. As SUMO does, the conflict area of participant A is
the stretch of its path from ``W_B / 2`` before the point to ``W_B / 2 + L_A`` after it (its front
enters when the other's half width before the point, its rear leaves when the other's half width
past it: crossing lanes treated as orthogonal).

**Per time step**, while neither has left the area: A's distance along its path to the entry
``d_A``, its speed ``v_A`` and acceleration ``a_A`` (the measured ``ax``/``ay`` of states, else
derived/kinematics, along the motion). Entry and exit times are extrapolated with the current
speed and, only when it is braking (``a < 0``), the current deceleration (a vehicle that stops
before the point never enters). With A the participant expected to enter first:

- ``ttc`` ``= d_B / v_B`` where B's expected entry is not later than A's expected exit (their
  occupancies would overlap), else null; 0 once B is inside while A is;
- ``drac``: the smaller of the decelerations either participant would need to let the other
  pass first, ``2 (v_X − d_X / t_Y,exit) / t_Y,exit`` (``v_X² / 2 d_X`` where Y would stop
  inside the area), null where either needs none (it passes behind anyway) or both are inside,
  0 once one has left (SUMO's ``computeDRAC`` for crossings: it is positive only where both
  would have to brake, whether or not TTC is defined);
- ``ppet`` ``= t_B,entry − t_A,exit`` (predicted post-encroachment time; negative: the
  occupancies overlap).

``pet``: the observed PET at the same point (the time B's front reaches its entry minus the time
A's rear leaves its exit, interpolated within frames along the path), repeated in every row of the
conflict. It is the lane-crossing counterpart of ``derived/encroachments`` (swept footprints):
for straight crossings both agree; with a turning vehicle they differ (docs/derive.md).

Uncertainty: ``_std`` of ttc, drac and ppet by the delta method (central differences) on the
distances (position std along the path), speeds and accelerations of both.

One row per participant, time and other participant, both directions (the participant's own
``distance`` to the entry and ``first`` telling who is expected first).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import shapely
from pydantic import Field

from aveas_format.derive._samples import Samples
from aveas_format.derive.encroachments import track_directions
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.schema.columns import MAY, MUST, col, gaussian, pid_col, time_col
from aveas_format.schema.tables import derived_table


class ConflictsParams(Params):
    """Parameters of ``conflicts``."""

    min_angle: float = Field(0.35, ge=0, description="smallest angle (rad) between the paths at "
                             "the crossing point")
    horizon: float = Field(10.0, gt=0, description="rows only while the first expected entry "
                           "is at most this far ahead (s)")
    time_resolution: float = Field(1e-6, gt=0, description="times closer than this (s) are one "
                                   "time step")


def _front_paths(S: Samples) -> tuple[list[slice], np.ndarray, np.ndarray, np.ndarray]:
    """Per track: its rows, and the front-bumper positions and cumulative path length of all rows."""
    starts = np.r_[0, np.flatnonzero(np.diff(S.pid)) + 1] if S.n else np.zeros(0, np.int64)
    ends = np.r_[starts[1:], S.n]
    fx = S.x + 0.5 * S.L * np.cos(S.h)
    fy = S.y + 0.5 * S.L * np.sin(S.h)
    step = np.r_[0.0, np.hypot(np.diff(fx), np.diff(fy))]
    step[starts] = 0.0
    arc = np.cumsum(step)
    arc -= np.repeat(arc[starts], ends - starts)
    return [slice(a, b) for a, b in zip(starts, ends)], fx, fy, arc


def _crossing(lines, a: int, b: int, fx, fy, arc, tracks, min_angle: float):
    """The first crossing of paths a and b at an angle >= min_angle: (arc position along a, along
    b) or None."""
    inter = shapely.intersection(lines[a], lines[b])
    if inter.is_empty:
        return None
    pts = shapely.get_coordinates(inter)
    best = None
    for px, py in pts:
        pos = []
        for k in (a, b):
            sl = tracks[k]
            d = np.hypot(fx[sl] - px, fy[sl] - py)
            i = int(np.argmin(d))
            j = min(i + 1, sl.stop - sl.start - 1)
            i0 = max(j - 1, 0)
            seg = np.array([fx[sl][j] - fx[sl][i0], fy[sl][j] - fy[sl][i0]])
            nrm = np.hypot(*seg)
            if nrm == 0:
                return None
            u = seg / nrm
            along = float(np.clip((px - fx[sl][i0]) * u[0] + (py - fy[sl][i0]) * u[1], 0, nrm))
            pos.append((arc[sl][i0] + along, np.arctan2(u[1], u[0])))
        ang = abs(np.angle(np.exp(1j * (pos[0][1] - pos[1][1]))))
        if ang < min_angle:
            continue
        cand = (pos[0][0], pos[1][0])
        if best is None or cand[0] < best[0]:
            best = cand
    return best


def entry_time(d, v, a):
    """Time to travel ``d`` at speed ``v`` with acceleration ``a`` applied only when braking
    (``a < 0``; a vehicle that stops first never arrives: inf); 0 where ``d <= 0``."""
    d, v, a = np.broadcast_arrays(*(np.asarray(x, float) for x in (d, v, a)))
    a = np.where(np.isfinite(a) & (a < 0), a, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lin = np.where(v > 0, d / v, np.inf)
        disc = v * v + 2 * a * d
        quad = np.where(disc >= 0, (-v + np.sqrt(np.maximum(disc, 0))) / a, np.inf)
    t = np.where(a < 0, quad, lin)
    return np.where(d <= 0, 0.0, t)


def _brake_for(d, v, t_other_out, t_other_in):
    """The constant deceleration that brings a participant at distance ``d`` and speed ``v`` to
    the entry when the other leaves (``2 (v - d / t_out) / t_out``); where the other never leaves
    but enters, the deceleration to stop before the entry (``v² / 2d``); NaN where it is inside
    already or the other never arrives."""
    with np.errstate(divide="ignore", invalid="ignore"):
        leave = 2 * (v - d / t_other_out) / t_other_out
        stop = np.where(v > 0, 0.5 * v * v / d, 0.0)
    out = np.where(np.isfinite(t_other_out) & (t_other_out > 0), leave,
                   np.where(np.isfinite(t_other_in), stop, np.nan))
    return np.where(d > 0, out, np.nan)


def crossing_measures(dA, vA, aA, xA, dB, vB, aB, xB):
    """``(ttc, drac, ppet, first_is_A)`` of two participants approaching a conflict area:
    distances to the entry ``d``, speeds ``v``, accelerations ``a`` and the lengths of the area
    along their paths ``x`` (exit = entry + x); SUMO's definitions (module docstring)."""
    tA_in, tB_in = entry_time(dA, vA, aA), entry_time(dB, vB, aB)
    tA_out, tB_out = entry_time(dA + xA, vA, aA), entry_time(dB + xB, vB, aB)
    # SUMO: A first where it is expected strictly earlier; a tie (both inside, or never) goes to
    # the one further along
    a_first = (tA_in < tB_in) | ((tA_in == tB_in) & (dA <= dB))
    t1_out = np.where(a_first, tA_out, tB_out)
    t2_in = np.where(a_first, tB_in, tA_in)
    d2 = np.where(a_first, dB, dA)
    v2 = np.where(a_first, vB, vA)
    overlap = t2_in <= t1_out
    with np.errstate(divide="ignore", invalid="ignore"):
        # the second already inside while the first is: contact now (TTC 0)
        ttc = np.where(overlap & (d2 <= 0), 0.0,
                       np.where(overlap & (v2 > 0), np.maximum(d2, 0.0) / v2, np.nan))
        ppet = np.where(np.isfinite(t2_in) & np.isfinite(t1_out), t2_in - t1_out, np.nan)
    # DRAC: the smaller of the decelerations either would need to let the other pass first; none
    # where either needs none (it passes behind anyway), where both are inside (contact), and 0
    # once one has left
    da = _brake_for(dA, vA, tB_out, tB_in)
    db = _brake_for(dB, vB, tA_out, tA_in)
    drac = np.fmin(da, db)
    drac = np.where(drac > 0, drac, np.nan)
    drac = np.where((dA + xA <= 0) | (dB + xB <= 0), 0.0, drac)
    return ttc, drac, ppet, a_first


def _delta_std(args, variances):
    """Std of crossing_measures' ttc, drac and ppet by central differences."""
    base = crossing_measures(*args)[:3]
    var = [np.zeros(len(args[0])) for _ in range(3)]
    for k, v in variances.items():
        h = np.maximum(1e-4, 1e-3 * np.abs(args[k]))
        up, dn = list(args), list(args)
        up[k] = args[k] + h
        dn[k] = args[k] - h
        hi, lo = crossing_measures(*up)[:3], crossing_measures(*dn)[:3]
        for m in range(3):
            with np.errstate(invalid="ignore"):
                d = (hi[m] - lo[m]) / (2 * h)
            var[m] += np.where(np.isfinite(d), d * d * np.nan_to_num(v), 0.0)
    return [np.where(np.isfinite(b), np.sqrt(s), np.nan) for b, s in zip(base, var)]


def pair_rank(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rank of each row's unordered pair of participant ids among the distinct pairs (the
    conflict numbering of ``derived/conflicts``)."""
    lo, hi = np.minimum(a, b).astype(np.int64), np.maximum(a, b).astype(np.int64)
    keys = np.unique(np.stack([lo, hi], axis=1), axis=0, return_inverse=True)[1]
    return keys.ravel().astype(np.int64)


def _passage(t, arc, target):
    """Time the path position ``arc`` (increasing along a track) reaches ``target``, linearly
    interpolated within the frame (NaN if never)."""
    k = int(np.searchsorted(arc, target, side="left"))
    if k >= len(arc):
        return np.nan
    if k == 0:
        return float(t[0]) if arc[0] >= target else np.nan
    a0, a1 = arc[k - 1], arc[k]
    f = 0.0 if a1 == a0 else (target - a0) / (a1 - a0)
    return float(t[k - 1] + f * (t[k] - t[k - 1]))


def compute(rec, p: ConflictsParams) -> pa.Table:
    """The ``derived/conflicts`` table of ``rec``."""
    S = Samples(rec, p.time_resolution)
    tracks, fx, fy, arc = _front_paths(S)
    lines = np.array([shapely.LineString(np.column_stack([fx[sl], fy[sl]]))
                      if sl.stop - sl.start >= 2 else None for sl in tracks], dtype=object)
    valid = np.flatnonzero(lines != None)  # noqa: E711 — object array
    rows: dict[str, list] = {k: [] for k in ("i", "j", "cid", "dist", "dist_var", "ttc", "ttc_std",
                                             "drac", "drac_std", "ppet", "ppet_std", "first",
                                             "pet")}
    if len(valid) >= 2:
        tree = shapely.STRtree(lines[valid])
        qa, qb = tree.query(lines[valid])  # overlapping bounding boxes (cheap)
        keep = qa < qb
        qa, qb = valid[qa[keep]], valid[qb[keep]]
        # pairs that travel the same way everywhere cannot cross at min_angle (car following):
        # dropped before the exact intersection test, which is costly for long parallel paths
        mean_dir, spread = track_directions(S, tracks)
        dd = np.abs(np.angle(np.exp(1j * (mean_dir[qa] - mean_dir[qb]))))
        ok = dd + spread[qa] + spread[qb] >= p.min_angle
        qa, qb = qa[ok], qb[ok]
        ok = shapely.intersects(lines[qa], lines[qb]) if len(qa) else np.zeros(0, bool)
        pairs = list(zip(qa[ok].tolist(), qb[ok].tolist()))
    else:
        pairs = []
    speed = np.hypot(S.vx, S.vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux, uy = np.where(speed > 0, S.vx / speed, np.cos(S.h)), np.where(
            speed > 0, S.vy / speed, np.sin(S.h))
    acc = np.nan_to_num(S.ax * ux + S.ay * uy)
    acc_var = np.nan_to_num((S.sax * ux) ** 2 + (S.say * uy) ** 2)
    pos_var = (ux * S.sx) ** 2 + (uy * S.sy) ** 2 + 2 * ux * uy * S.rxy * S.sx * S.sy
    spd_var = (ux * S.svx) ** 2 + (uy * S.svy) ** 2 + 2 * ux * uy * S.rv * S.svx * S.svy
    cid = 0
    for a, b in pairs:
        cross = _crossing(lines, a, b, fx, fy, arc, tracks, p.min_angle)
        if cross is None:
            continue
        sa, sb = tracks[a], tracks[b]
        ka, kb = np.arange(sa.start, sa.stop), np.arange(sb.start, sb.stop)
        common, ia, ib = np.intersect1d(S.tstep[ka], S.tstep[kb], return_indices=True)
        if not len(common):
            continue
        ra, rb = ka[ia], kb[ib]
        wa, wb = S.W[ra], S.W[rb]
        # entry: front W_other / 2 before the point; exit: rear W_other / 2 past it
        dA = cross[0] - 0.5 * wb - arc[ra]
        dB = cross[1] - 0.5 * wa - arc[rb]
        xA, xB = S.L[ra] + wb, S.L[rb] + wa
        active = (dA + xA > 0) & (dB + xB > 0)
        args = [dA, speed[ra], acc[ra], xA, dB, speed[rb], acc[rb], xB]
        ttc, drac, ppet, a_first = crossing_measures(*args)
        t_first = np.minimum(entry_time(dA, speed[ra], acc[ra]), entry_time(dB, speed[rb], acc[rb]))
        active &= t_first <= p.horizon
        if not active.any():
            continue
        sel = np.flatnonzero(active)
        args = [x[sel] for x in args]
        sd = _delta_std(args, {0: pos_var[ra][sel], 1: spd_var[ra][sel], 2: acc_var[ra][sel],
                               4: pos_var[rb][sel], 5: spd_var[rb][sel], 6: acc_var[rb][sel]})
        # observed PET at the point: the first's rear leaves, the second's front enters
        t_a, t_b = S.t[sa], S.t[sb]
        a_in = _passage(t_a, arc[sa], cross[0] - 0.5 * float(S.W[sb.start]))
        a_out = _passage(t_a, arc[sa], cross[0] + 0.5 * float(S.W[sb.start]) + float(S.L[sa.start]))
        b_in = _passage(t_b, arc[sb], cross[1] - 0.5 * float(S.W[sa.start]))
        b_out = _passage(t_b, arc[sb], cross[1] + 0.5 * float(S.W[sa.start]) + float(S.L[sb.start]))
        if np.isfinite(a_in) and np.isfinite(b_in):
            pet = b_in - a_out if a_in <= b_in else a_in - b_out
            pet = pet if pet >= 0 else np.nan
        else:
            pet = np.nan
        m = len(sel)
        for (i, j, d, dv, first) in ((ra[sel], rb[sel], dA[sel], pos_var[ra][sel], a_first[sel]),
                                     (rb[sel], ra[sel], dB[sel], pos_var[rb][sel], ~a_first[sel])):
            rows["i"].append(i)
            rows["j"].append(j)
            rows["cid"].append(np.full(m, cid))
            rows["dist"].append(d)
            rows["dist_var"].append(dv)
            rows["ttc"].append(ttc[sel])
            rows["ttc_std"].append(sd[0])
            rows["drac"].append(drac[sel])
            rows["drac_std"].append(sd[1])
            rows["ppet"].append(ppet[sel])
            rows["ppet_std"].append(sd[2])
            rows["first"].append(first)
            rows["pet"].append(np.full(m, pet))
        cid += 1
    r = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in rows.items()}
    i = r["i"].astype(np.int64)
    j = r["j"].astype(np.int64)
    if len(i):
        # conflicts numbered in the order of their pairs of participant ids (one crossing per
        # pair): the same numbers whichever subset of the recording is derived
        r["cid"] = pair_rank(S.pid[i], S.pid[j])

    def f(v):
        v = np.asarray(v, float)
        return pa.array(v, pa.float64(), mask=~np.isfinite(v))

    first_id = np.where(r["first"].astype(bool), S.pid[i], S.pid[j]) if len(i) else np.zeros(0)
    t = pa.table({
        "participant_id": pa.array(S.pid[i], pa.int64()), "time": pa.array(S.t[i], pa.float64()),
        "other_id": pa.array(S.pid[j], pa.int64()),
        "conflict_id": pa.array(r["cid"].astype(np.int64)),
        "distance": f(r["dist"]), "distance_std": f(np.sqrt(r["dist_var"])),
        "first_id": pa.array(np.asarray(first_id, np.int64)),
        "ttc": f(r["ttc"]), "ttc_std": f(np.where(np.isfinite(r["ttc"]), r["ttc_std"], np.nan)),
        "drac": f(r["drac"]),
        "drac_std": f(np.where(np.isfinite(r["drac"]), r["drac_std"], np.nan)),
        "ppet": f(r["ppet"]),
        "ppet_std": f(np.where(np.isfinite(r["ppet"]), r["ppet_std"], np.nan)),
        "pet": f(r["pet"]),
    })
    if t.num_rows:
        t = t.sort_by([("participant_id", "ascending"), ("time", "ascending"),
                       ("other_id", "ascending")])
    return t


TABLE = derived_table(
    "conflicts",
    doc="Crossing conflicts at the crossing point of two paths per time step, as SUMO's SSM "
    "device defines them: distance to the conflict area, crossing TTC, DRAC, predicted PET and "
    "the observed PET at that point.",
    key=("participant_id", "time", "other_id"),
    sort=("participant_id", "time", "other_id"),
    columns=(
        pid_col(), time_col(),
        col("other_id", "int64", MUST, "the other participant", minimum=0, nullable=False),
        col("conflict_id", "int64", MUST, "the crossing (one per pair and crossing point)",
            minimum=0, nullable=False),
        *gaussian("distance", "m", MUST, "the participant's front-bumper distance along its path "
                  "to the entry of the conflict area (negative: inside)"),
        col("first_id", "int64", MUST, "the participant expected to enter first", minimum=0),
        *gaussian("ttc", "s", MAY, "crossing TTC: the second's distance to the entry / its "
                  "speed, where the expected occupancies overlap (null otherwise)", minimum=0.0),
        *gaussian("drac", "m/s²", MAY, "crossing DRAC: the smaller deceleration either would "
                  "need to let the other pass first, 2 (v - d / t_other,exit) / t_other,exit "
                  "(SUMO's)", minimum=0.0),
        *gaussian("ppet", "s", MAY, "predicted PET: expected entry of the second - expected exit "
                  "of the first (negative: overlap)"),
        col("pet", "float64", MAY, "observed PET at the crossing point (the same in every row of "
            "the conflict; null where both were never inside one after the other)", "s",
            minimum=0.0),
    ),
)

CONFLICTS = register(Derivation(
    name="conflicts",
    spec=TABLE,
    version="1.1.0",
    params=ConflictsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y", "heading", "vx", "vy"),
           "participants": ("participant_id", "length", "width")},
    optional=("derived/kinematics",),
    after=("kinematics",),
    doc="crossing conflicts at the crossing point of the paths as SUMO's SSM device defines "
        "them: crossing TTC, DRAC, predicted and observed PET",
    method=lambda p: "path_crossing",
))
