"""Synthetic but realistic sample data: a highway scene as an aerial recording would give it.

Used by ``aveas-format demo``, the benchmarks and the tests. Vehicles drive on a generated straight
motorway (OpenDRIVE, geo-referenced near Karlsruhe like the paper's aerial recordings), following
each other by the Intelligent Driver Model with per-lane desired speeds (trucks keep right), and
faster cars change lanes smoothly where the target lane has a gap; positions get Gaussian
measurement noise whose standard deviation is stored in the ``_std`` columns, and road coordinates
are then computed from the noisy positions through the map, as a converter would. A bridge
occludes part of the road for the whole recording and the sensor drops out once (``unobserved``).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import shapely

from aveas_format.schema.pmf import one_hot
from aveas_format.schema.taxonomy import CLASSES

#: A transverse Mercator at the site: the A5 motorway between Karlsruhe and Rastatt.
SITE_CRS = ("+proj=tmerc +lat_0=48.9 +lon_0=8.35 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m "
            "+no_defs")

# class: (share, length mean/std, width mean/std, height, speed factor)
_FLEET = {
    "car": (0.78, 4.6, 0.35, 1.84, 0.08, 1.5, 1.0),
    "van": (0.07, 5.6, 0.4, 2.0, 0.06, 2.3, 0.93),
    "truck": (0.15, 16.0, 2.0, 2.55, 0.03, 3.8, 0.75),
}
_LANE_SPEED = {-3: 24.0, -2: 30.0, -1: 36.0}  # m/s, right (slow) to left (fast)


def highway_scene(
    n_vehicles: int = 60,
    duration_s: float = 30.0,
    rate_hz: float = 25.0,
    length_m: float = 1000.0,
    seed: int = 7,
    position_std: float = 0.1,
    heading_std: float = 0.02,
    velocity_std: float = 0.2,
    return_truth: bool = False,
):
    """A :class:`~aveas_format.io.Recording` of ``n_vehicles`` on a 3-lane straight motorway.

    ``return_truth=True`` returns ``(recording, truth)`` where ``truth`` holds the noise-free
    ``participant_id``, ``time``, ``x``, ``y``, ``vx``, ``vy``, ``ax``, ``ay`` of every state row
    (same order as the recording's states).
    """
    from aveas_format.mapref.build import build_recording
    from aveas_format.opendrive import load_map
    from aveas_format.opendrive.builder import straight_highway

    rng = np.random.default_rng(seed)
    xodr = straight_highway(length=length_m, lanes_right=3, lanes_left=0, lane_width=3.5,
                            geo_reference=SITE_CRS)
    net = load_map(xodr.encode())
    road_id = next(iter(net.roads))
    lane_w = 3.5

    classes = rng.choice(list(_FLEET), size=n_vehicles, p=[v[0] for v in _FLEET.values()])
    fleet = np.array([_FLEET[c] for c in classes])
    length = np.clip(rng.normal(fleet[:, 1], fleet[:, 2]), 2.5, 19.0)
    width = np.clip(rng.normal(fleet[:, 3], fleet[:, 4]), 1.5, 2.6)
    height = fleet[:, 5]
    # right-hand traffic with the reference line on the left edge: lane -1 is the left (fast)
    # lane, -3 the right one; trucks keep right (banned from the left lane, as in the paper)
    lane = np.where(classes == "truck", rng.choice([-3, -2], n_vehicles, p=[0.8, 0.2]),
                    rng.choice([-3, -2, -1], n_vehicles, p=[0.25, 0.4, 0.35]))
    v0 = np.array([_LANE_SPEED[int(k)] for k in lane]) * fleet[:, 6] * rng.normal(1.0, 0.05, n_vehicles)
    v0 = np.minimum(v0, np.where(classes == "truck", 25.0, 60.0))

    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    s, ds, dds, lane_now, tc, lc = _idm_traffic(rng, t, lane, v0, length, length_m)
    T = t[None, :]
    # lane changes (decided during the simulation when the target lane had room): cosine profile
    dur = rng.uniform(4.0, 6.0, n_vehicles)
    u = np.clip((T - tc[:, None]) / dur[:, None], 0.0, 1.0)
    shift = np.where(lc, lane_now - lane, 0)[:, None] * lane_w  # +: towards the left
    tt = (lane[:, None] + 0.5) * lane_w + shift * 0.5 * (1 - np.cos(np.pi * u))
    dt_du = shift * 0.5 * np.pi * np.sin(np.pi * u) / dur[:, None]
    dtt = np.where((u > 0) & (u < 1), dt_du, 0.0)
    # second derivative of the lateral profile (for the truth)
    ddtt = np.where((u > 0) & (u < 1), shift * 0.5 * (np.pi / dur[:, None]) ** 2 * np.cos(np.pi * u),
                    0.0)

    on = (s >= 0.5) & (s <= length_m - 0.5)  # margin: noisy positions stay on the map
    seen = on.any(axis=1)  # vehicles that enter the observed stretch at all
    s, ds, dds, tt, dtt, ddtt, on = (a[seen] for a in (s, ds, dds, tt, dtt, ddtt, on))
    classes, length, width, height = classes[seen], length[seen], width[seen], height[seen]
    n_vehicles = int(seen.sum())
    vid, ti = np.nonzero(on)
    S, TT, DS, DT = s[on], tt[on], ds[on], dtt[on]
    x, y, _, road_hdg = net.road_to_world(road_id, S, TT)
    x, y, road_hdg = np.asarray(x), np.asarray(y), np.asarray(road_hdg)
    heading = road_hdg + np.arctan2(DT, DS)
    c, sn = np.cos(road_hdg), np.sin(road_hdg)
    vx = DS * c - DT * sn
    vy = DS * sn + DT * c
    n = len(S)
    x_m = x + rng.normal(0, position_std, n)
    y_m = y + rng.normal(0, position_std, n)
    h_m = np.angle(np.exp(1j * (heading + rng.normal(0, heading_std, n))))
    vx_m = vx + rng.normal(0, velocity_std, n)
    vy_m = vy + rng.normal(0, velocity_std, n)

    # a bridge across the road occludes 20 m for the whole recording; the states under it are
    # interpolated (the tracker bridged the gap), and the sensor drops out for 0.4 s once
    bx0, bx1 = 0.62 * length_m, 0.62 * length_m + 20.0
    under_bridge = (S >= bx0) & (S <= bx1)
    outage = (t[ti] >= 0.5 * duration_s) & (t[ti] < 0.5 * duration_s + 0.4)
    keep = ~outage
    bs = np.array([bx0, bx1, bx1, bx0])
    bt = np.array([1.0, 1.0, -3 * lane_w - 1.0, -3 * lane_w - 1.0])
    bxw, byw = net.road_to_world(road_id, bs, bt)[:2]
    bridge = shapely.Polygon(np.column_stack([bxw, byw]))
    coverage = shapely.box(*np.round(_pad(net.bounds, 2.0), 2))

    pmf = 0.9 * one_hot(classes, "class")
    confusable = np.array([CLASSES.index(c) for c in ("car", "van", "truck")])
    pmf[:, confusable] += 0.1 / len(confusable)

    participants = {
        "participant_id": np.arange(n_vehicles, dtype=np.int64),
        "source_id": [f"track-{i:04d}" for i in range(n_vehicles)],
        "class": classes.astype(object),
        "class_pmf": pmf,
        "length": length,
        "width": width,
        "height": height,
        "length_std": np.full(n_vehicles, 0.25),
        "width_std": np.full(n_vehicles, 0.1),
        "role": ["observed"] * n_vehicles,
        "provenance": ["natural"] * n_vehicles,
    }
    k = keep
    states = {
        "participant_id": vid[k].astype(np.int64),
        "time": t[ti][k],
        "x": x_m[k], "y": y_m[k], "heading": h_m[k], "vx": vx_m[k], "vy": vy_m[k],
        "x_std": np.full(k.sum(), position_std), "y_std": np.full(k.sum(), position_std),
        "heading_std": np.full(k.sum(), heading_std),
        "vx_std": np.full(k.sum(), velocity_std), "vy_std": np.full(k.sum(), velocity_std),
        "xy_corr": np.zeros(k.sum(), np.float32),
        "interpolated": under_bridge[k],
        "source_frame": ti[k].astype(np.int64),
    }
    unobserved = {
        "region_id": np.array([0, 1], np.int64),
        "time_start": np.array([0.0, 0.5 * duration_s]),
        "time_end": np.array([t[-1], 0.5 * duration_s + 0.4]),
        "kind": ["occlusion", "sensor_outage"],
        "geometry": [shapely.to_wkb(bridge), shapely.to_wkb(coverage)],
        "sensor_id": ["cam"] * 2,
    }
    rec = build_recording(
        map_source=xodr,
        participants=participants,
        states=states,
        unobserved=unobserved,
        method="aerial",
        partner="aveas-format sample data",
        provenance="natural",
        start_time="2024-05-13T08:15:00Z",
        nominal_rate_hz=rate_hz,
        duration_s=float(t[-1]),
        recording_id=f"sample-highway-{seed}",
        source={"converter": "aveas_format.sample.highway_scene", "converter_version": "1",
                "inputs": [], "options": {"n_vehicles": int(seen.size), "duration_s": duration_s,
                                          "rate_hz": rate_hz, "seed": seed,
                                          "position_std": position_std}},
        title=f"Sample: {n_vehicles} vehicles on a 3-lane motorway, {duration_s:g} s at {rate_hz:g} Hz",
        acquisition={
            "platform": "ultralight aircraft, 4K camera, 25 fps, GSD 0.125 m (synthetic)",
            "sensors": [{"id": "cam", "kind": "rgb_camera", "rate_hz": rate_hz}],
            "not_observable": ["light_", "interior"],
            "site": {"name": "A5 Karlsruhe-Rastatt (synthetic)", "country": "DE",
                     "road_type": "motorway", "selection_reason": "demonstration"},
        },
        coverage=coverage.wkt,
        rights={"right_of_use": "research_only", "license": "CC-BY-4.0",
                "owner": "aveas-format sample data"},
        conditions={"weather": {"clear": 0.9, "cloudy": 0.1},
                    "lighting": {"day": 1.0}, "road_surface": {"dry": 1.0}, "temperature_c": 14.0},
        thresholds={"ttc_s": 3.0, "pet_s": 1.5, "thw_s": 1.0},
    )
    if return_truth:
        # the road is straight: world accelerations rotate the road-frame ones by the road heading
        dd_s, dd_t = dds[on][k], ddtt[on][k]
        ck, sk = c[k], sn[k]
        order = np.lexsort((t[ti][k], vid[k]))  # the states table is sorted by (id, time)
        truth = {
            "participant_id": vid[k].astype(np.int64)[order], "time": t[ti][k][order],
            "x": x[k][order], "y": y[k][order], "vx": vx[k][order], "vy": vy[k][order],
            "ax": (dd_s * ck - dd_t * sk)[order], "ay": (dd_s * sk + dd_t * ck)[order],
        }
        return rec, truth
    return rec


def _idm_traffic(rng: np.random.Generator, t: np.ndarray, lane: np.ndarray, v0: np.ndarray,
                 length: np.ndarray, road_length: float):
    """Longitudinal motion of every vehicle by the Intelligent Driver Model, vectorised over
    vehicles (one loop over time steps), with some cars changing lanes when the target lane has
    room. Returns s, ds/dt, d2s/dt2 (vehicles x steps), the final lane, the lane-change start time
    (inf = none) and whether the vehicle changed lanes."""
    n, n_t = len(v0), len(t)
    dt = float(t[1] - t[0]) if n_t > 1 else 0.04
    a_max, b_comf, s_min, headway = 1.2, 2.0, 2.0, 1.4
    # place each lane's vehicles one behind the other, from the road's end upstream
    s_cur = np.empty(n)
    for ln in np.unique(lane):
        idx = rng.permutation(np.flatnonzero(lane == ln))
        spacing = length[idx] + s_min + v0[idx] * headway * rng.uniform(1.2, 3.0, len(idx))
        s_cur[idx] = road_length - np.cumsum(spacing)
    v = v0 * rng.uniform(0.95, 1.0, n)
    lane_now = lane.copy()
    wants = (rng.random(n) < 0.35) & (v0 > 26.0)  # faster cars try to move one lane left
    target = np.where(lane < -1, lane + 1, lane)
    t_try = rng.uniform(1.0, max(t[-1] - 6.0, 1.5), n) if n_t else np.zeros(n)
    tc = np.full(n, np.inf)
    S, V, A = (np.empty((n, n_t)) for _ in range(3))
    for k in range(n_t):
        order = np.lexsort((s_cur, lane_now))
        same = lane_now[order][1:] == lane_now[order][:-1]
        leader = np.full(n, -1)
        leader[order[:-1][same]] = order[1:][same]
        has = leader >= 0
        li = np.where(has, leader, 0)
        gap = np.where(has, s_cur[li] - s_cur - 0.5 * (length[li] + length), np.inf)
        dv = np.where(has, v - v[li], 0.0)
        s_star = s_min + np.maximum(v * headway + v * dv / (2 * np.sqrt(a_max * b_comf)), 0.0)
        a = a_max * (1 - (v / v0) ** 4 - (s_star / np.maximum(gap, 0.5)) ** 2)
        a = np.clip(a, -8.0, a_max)
        S[:, k], V[:, k], A[:, k] = s_cur, v, a
        # lane changes starting now: only into a gap of at least a 1.5 s headway on both sides
        start = wants & (tc == np.inf) & (t_try <= t[k]) & (target != lane_now)
        for i in np.flatnonzero(start):
            others = np.flatnonzero((lane_now == target[i]) & (np.arange(n) != i))
            ahead = s_cur[others] - s_cur[i]
            front = ahead[ahead >= 0].min(initial=np.inf) - length[i]
            back = -ahead[ahead < 0].max(initial=-np.inf) - length[i]
            if front > max(15.0, 1.5 * v[i]) and back > max(15.0, 1.5 * v[i]):
                lane_now[i], tc[i] = target[i], t[k]
            else:
                t_try[i] = t[k] + 2.0  # try again later
        s_cur = s_cur + v * dt + 0.5 * a * dt * dt
        v = np.maximum(v + a * dt, 0.0)
    return S, V, A, lane_now, tc, tc < np.inf


def _pad(b: tuple[float, float, float, float], d: float) -> tuple[float, float, float, float]:
    return b[0] - d, b[1] - d, b[2] + d, b[3] + d


def synthetic_states(n_participants: int = 1000, n_steps: int = 1000, rate_hz: float = 25.0,
                     seed: int = 0) -> pa.Table:
    """A large states table for benchmarks: straight-line motion with noise and ``_std`` columns,
    road coordinates filled analytically for a straight road along +x (no map projection)."""
    rng = np.random.default_rng(seed)
    n = n_participants * n_steps
    pid = np.repeat(np.arange(n_participants, dtype=np.int64), n_steps)
    t = np.tile(np.arange(n_steps) / rate_hz, n_participants)
    lane = rng.integers(1, 4, n_participants)
    v = rng.normal(30.0, 4.0, n_participants)
    s = np.repeat(rng.uniform(0, 500, n_participants), n_steps) + np.repeat(v, n_steps) * t
    road_t = -(np.repeat(lane, n_steps) - 0.5) * 3.5
    x = s + rng.normal(0, 0.1, n)
    y = road_t + rng.normal(0, 0.1, n)
    lon = 8.35 + x * 1.37e-5
    lat = 48.9 + y * 9.0e-6
    cols = {
        "participant_id": pid, "time": t, "x": x, "y": y,
        "heading": rng.normal(0, 0.01, n), "vx": np.repeat(v, n_steps) + rng.normal(0, 0.2, n),
        "vy": rng.normal(0, 0.2, n), "lon": lon, "lat": lat,
        "road_id": pa.DictionaryArray.from_arrays(pa.array(np.zeros(n, np.int32)), pa.array(["1"])),
        "lane_id": (-np.repeat(lane, n_steps)).astype(np.int16), "road_s": s, "road_t": road_t,
        "lane_offset": y - road_t,
    }
    for c in ("x", "y", "heading", "vx", "vy"):
        cols[f"{c}_std"] = np.full(n, 0.1)
    return pa.table(cols)
