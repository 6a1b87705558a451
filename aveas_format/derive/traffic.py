"""``derived/traffic``: Edie's generalised flow, density and space-mean speed per lane, road
stretch and time window; plus the AVEAS OpenLABEL local density (vehicles within ±50 m).

For a space-time cell ``A = [s0, s1) x [t0, t1)`` of one lane (Edie 1963)::

    flow q = Σ d_i / |A|        density k = Σ τ_i / |A|        mean speed v = q / k

with ``d_i`` the distance participant i travels inside the cell and ``τ_i`` the time it spends
there. Trajectories are linear between consecutive samples of the same participant, road and lane
(a lane change splits the step at its midpoint; steps across roads or longer than ``max_gap_s``
are left out) and every step is clipped exactly to the cell boundaries in s and t, so the sums are
exact for piecewise-linear motion (no rounding to frames). The reference point is the footprint
centre (``road_s``). Cells start at ``s = 0`` of each road and at ``time = 0``; the last stretch of
a road ends at the road's length.

Uncertainty: ``density_std`` from the timing of the s-boundary crossings (``σ_s / |v|`` each),
``flow_std`` from the positions of track ends inside a cell (``σ_s`` each), ``mean_speed_std`` by
the delta method of ``q / k``; ``σ_s² = (x_std² + y_std²)/2``.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.derive._samples import ragged, road_columns, searchsorted_segments
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.io.arrow import column_numpy
from aveas_format.schema.columns import MUST, col, gaussian, interval_cols
from aveas_format.schema.tables import derived_table


class TrafficParams(Params):
    """Parameters of ``traffic``."""

    cell_length_m: float = Field(100.0, gt=0, description="length of a road stretch (m)")
    cell_duration_s: float = Field(60.0, gt=0, description="duration of a time window (s)")
    max_gap_s: float = Field(1.0, gt=0, description="steps longer than this are not counted")


def edie_cells(pid, t, s, lane_key, sigma_s, ds: float, dT: float, max_gap: float):
    """Edie sums per cell. ``lane_key`` groups samples that share a road and lane (int, -1 = off
    map). Returns a dict of arrays keyed by cell: lane_key, s index, t index, distance, time,
    count, var_distance, var_time."""
    n = len(t)
    if n < 2:
        return None
    same = (pid[1:] == pid[:-1]) & (lane_key[:-1] >= 0) & (lane_key[1:] >= 0)
    dt = np.diff(t)
    same &= (dt > 0) & (dt <= max_gap)
    k = np.flatnonzero(same)
    t0, t1, s0, s1 = t[k], t[k + 1], s[k], s[k + 1]
    lk0, lk1 = lane_key[k], lane_key[k + 1]
    # lane change inside the step: split at the midpoint (each half keeps its lane)
    split = lk0 != lk1
    tm, sm = 0.5 * (t0 + t1), 0.5 * (s0 + s1)
    seg_t0 = np.r_[t0, tm[split]]
    seg_t1 = np.r_[np.where(split, tm, t1), t1[split]]
    seg_s0 = np.r_[s0, sm[split]]
    seg_s1 = np.r_[np.where(split, sm, s1), s1[split]]
    seg_lk = np.r_[lk0, lk1[split]]
    seg_pid = np.r_[pid[k], pid[k + 1][split]]
    seg_sig = np.r_[sigma_s[k], sigma_s[k + 1][split]]
    # exact clipping at cell boundaries: breakpoints where s or t crosses a multiple of ds / dT
    lam = [np.zeros(len(seg_t0)), np.ones(len(seg_t0))]
    owner = [np.arange(len(seg_t0))] * 2
    for a0, a1, step in ((seg_s0, seg_s1, ds), (seg_t0, seg_t1, dT)):
        c0 = np.floor(np.minimum(a0, a1) / step).astype(np.int64)
        c1 = np.floor(np.maximum(a0, a1) / step).astype(np.int64)
        cnt = c1 - c0
        if int(cnt.sum()):
            seg, j = ragged(cnt)  # the j-th boundary after the start (from 0)
            bound = (c0[seg] + j + 1) * step
            with np.errstate(divide="ignore", invalid="ignore"):
                lm = (bound - a0[seg]) / (a1[seg] - a0[seg])
            ok = np.isfinite(lm) & (lm > 0) & (lm < 1)
            lam.append(lm[ok])
            owner.append(seg[ok])
    lam_all = np.concatenate(lam)
    own = np.concatenate(owner)
    o = np.lexsort((lam_all, own))
    lam_all, own = lam_all[o], own[o]
    nxt_same = own[1:] == own[:-1]
    la, lb, so = lam_all[:-1][nxt_same], lam_all[1:][nxt_same], own[:-1][nxt_same]
    keep = lb > la
    la, lb, so = la[keep], lb[keep], so[keep]
    ta = seg_t0[so] + la * (seg_t1[so] - seg_t0[so])
    tb = seg_t0[so] + lb * (seg_t1[so] - seg_t0[so])
    sa = seg_s0[so] + la * (seg_s1[so] - seg_s0[so])
    sb = seg_s0[so] + lb * (seg_s1[so] - seg_s0[so])
    si = np.floor(0.5 * (sa + sb) / ds).astype(np.int64)
    ti = np.floor(0.5 * (ta + tb) / dT).astype(np.int64)
    lk = seg_lk[so]
    cell = np.stack([lk, si, ti], 1)
    uc, inv = np.unique(cell, axis=0, return_inverse=True)
    inv = inv.ravel()
    dist = np.bincount(inv, np.abs(sb - sa), len(uc))
    tim = np.bincount(inv, tb - ta, len(uc))
    pc = np.unique(np.stack([inv, seg_pid[so]], 1), axis=0)
    count = np.bincount(pc[:, 0], minlength=len(uc))
    # uncertainty: crossings of s boundaries (timing) and free track ends (distance)
    sig = seg_sig[so]
    speed = np.abs(sb - sa) / np.maximum(tb - ta, 1e-12)
    on_s_bound = np.isclose(np.mod(sa, ds), 0.0) | np.isclose(np.mod(sb, ds), 0.0)
    var_time = np.bincount(inv, np.where(on_s_bound & (speed > 0.1),
                                         (sig / np.maximum(speed, 0.1)) ** 2, 0.0), len(uc))
    # track ends: first/last sub-step of each (participant, lane) run inside the cell
    first_of = np.r_[True, (seg_pid[so][1:] != seg_pid[so][:-1]) | (inv[1:] != inv[:-1])]
    last_of = np.r_[first_of[1:], True]
    free = (first_of & ~on_s_bound) .astype(float) + (last_of & ~on_s_bound).astype(float)
    var_dist = np.bincount(inv, free * sig ** 2, len(uc))
    return {"lane_key": uc[:, 0], "si": uc[:, 1], "ti": uc[:, 2], "distance": dist, "time": tim,
            "count": count, "var_distance": var_dist, "var_time": var_time}


def compute(rec, p: TrafficParams) -> pa.Table:
    """The ``derived/traffic`` table of ``rec``."""
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = column_numpy(s, "time", missing=np.nan)
    road_np, lane, rs, on = road_columns(s)
    sx, sy = (column_numpy(s, c, nonfinite=0.0, missing=0.0) for c in ("x_std", "y_std"))
    sigma = np.sqrt(0.5 * (sx ** 2 + sy ** 2))
    roads = sorted({r for r in road_np[on]})
    rmap = {r: i for i, r in enumerate(roads)}
    lane_i = np.where(on, np.nan_to_num(lane).astype(np.int64), 0)
    rid_i = np.array([rmap.get(r, -1) if r is not None else -1 for r in road_np], np.int64)
    lane_key = np.where(on, rid_i * 1024 + (lane_i + 512), -1)
    res = edie_cells(pid, t, np.nan_to_num(rs), lane_key, sigma, p.cell_length_m,
                     p.cell_duration_s, p.max_gap_s)
    if res is None or len(res["lane_key"]) == 0:
        return _empty()
    lk = res["lane_key"]
    r_id = np.array(roads, dtype=object)[lk // 1024]
    l_id = (lk % 1024) - 512
    s_start = res["si"] * p.cell_length_m
    lengths = {r: rec.map.roads[r].length if r in rec.map.roads else np.inf for r in roads}
    road_len = np.array([lengths[r] for r in r_id])
    s_end = np.minimum(s_start + p.cell_length_m, road_len)
    s_end = np.where(s_end > s_start, s_end, s_start + p.cell_length_m)
    t_start = res["ti"] * p.cell_duration_s
    t_end = t_start + p.cell_duration_s
    area = (s_end - s_start) * (t_end - t_start)
    q = res["distance"] / area
    k = res["time"] / area
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(k > 0, q / k, np.nan)
        q_std = np.sqrt(res["var_distance"]) / area
        k_std = np.sqrt(res["var_time"]) / area
        v_std = np.abs(v) * np.sqrt(np.where(q > 0, (q_std / q) ** 2, 0.0)
                                    + np.where(k > 0, (k_std / k) ** 2, 0.0))
    return pa.table({
        "road_id": pa.array(list(r_id), pa.string()),
        "lane_id": pa.array(l_id.astype(np.int16)),
        "s_start": pa.array(s_start.astype(float)),
        "s_end": pa.array(s_end.astype(float)),
        "time_start": pa.array(t_start.astype(float)),
        "time_end": pa.array(t_end.astype(float)),
        "density": pa.array(k * 1000.0), "density_std": pa.array(k_std * 1000.0),
        "flow": pa.array(q * 3600.0), "flow_std": pa.array(q_std * 3600.0),
        "mean_speed": pa.array(v, mask=~np.isfinite(v)),
        "mean_speed_std": pa.array(v_std, mask=~np.isfinite(v_std)),
        "count": pa.array(res["count"].astype(np.int64)),
    })


def _empty() -> pa.Table:
    f = pa.array([], pa.float64())
    return pa.table({"road_id": pa.array([], pa.string()), "lane_id": pa.array([], pa.int16()),
                     "s_start": f, "s_end": f, "time_start": f, "time_end": f, "density": f,
                     "density_std": f, "flow": f, "flow_std": f, "mean_speed": f,
                     "mean_speed_std": f, "count": pa.array([], pa.int64())})


def local_density(rec, radius_m: float = 50.0) -> pa.Table:
    """The AVEAS OpenLABEL density per participant and time: the number of *other* participants on
    the same road and side (direction of travel: sign of ``lane_id``) whose ``road_s`` lies within
    ``±radius_m``, and that count per km (``count / (2 radius) * 1000``).

    Returns a table ``participant_id, time, local_count, local_density`` (veh/km; null off-map)."""
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = column_numpy(s, "time", missing=np.nan)
    road_np, lane, rs, on = road_columns(s)
    idx = np.flatnonzero(on)
    count = np.full(len(t), -1, np.int64)
    if len(idx):
        tk = np.unique(np.round(t[idx] * 1e6).astype(np.int64), return_inverse=True)[1].ravel()
        rk = np.unique(road_np[idx].astype(str), return_inverse=True)[1].ravel()
        side = (lane[idx] > 0).astype(np.int64)
        grp = (tk * (rk.max() + 1) + rk) * 2 + side
        o = np.lexsort((rs[idx], grp))
        g_sorted, s_sorted = grp[o], rs[idx][o]
        lo = np.searchsorted(g_sorted, grp, "left")
        hi = np.searchsorted(g_sorted, grp, "right")
        a = searchsorted_segments(s_sorted, lo, hi, rs[idx] - radius_m - 1e-9)
        b = searchsorted_segments(s_sorted, lo, hi, rs[idx] + radius_m + 1e-9)
        count[idx] = (b - a) - 1
    dens = np.where(count >= 0, count / (2 * radius_m) * 1000.0, np.nan)
    return pa.table({"participant_id": pa.array(pid, pa.int64()), "time": pa.array(t),
                     "local_count": pa.array(count, mask=count < 0),
                     "local_density": pa.array(dens, mask=~np.isfinite(dens))})


TABLE = derived_table(
    "traffic",
    doc="Macroscopic traffic quantities per lane, road stretch and time window, after Edie's "
    "generalized definitions.",
    key=("road_id", "lane_id", "s_start", "time_start"),
    sort=("road_id", "lane_id", "s_start", "time_start"),
    columns=(
        col("road_id", "dict<string>", MUST, "OpenDRIVE road", nullable=False),
        col("lane_id", "int16", MUST, "OpenDRIVE lane", nullable=False),
        col("s_start", "float64", MUST, "start of the road stretch", "m", nullable=False),
        col("s_end", "float64", MUST, "end of the road stretch", "m", nullable=False),
        *interval_cols(),
        *gaussian("density", "veh/km", MUST, "density (Edie)", minimum=0.0),
        *gaussian("flow", "veh/h", MUST, "flow (Edie)", minimum=0.0),
        *gaussian("mean_speed", "m/s", MUST, "space-mean speed (flow / density)", minimum=0.0),
        col("count", "int64", MUST, "participants seen in the space-time window", minimum=0),
    ),
)

TRAFFIC = register(Derivation(
    name="traffic",
    spec=TABLE,
    version="1.0.0",
    params=TrafficParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "road_id", "lane_id", "road_s")},
    doc="Edie's generalised flow, density and space-mean speed per lane, road stretch and time "
        "window",
    method=lambda p: "edie",
))
