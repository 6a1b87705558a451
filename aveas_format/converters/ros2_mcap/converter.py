"""``convert_ros2_mcap`` (registered as ``ros2-mcap``) and its named steps: the ego track, the
objects in the map frame, the states, the participants. The converter's documentation is the
package's docstring (:mod:`aveas_format.converters.ros2_mcap`), which docs/converters.md shows."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.converters.common import (
    covariance_std_corr,
    factorize,
    group_mean,
    group_std,
    load_map_bytes,
    nullable,
    utc_iso_from_ns,
    wrap_recording,
)
from aveas_format.converters.registry import converter
from aveas_format.converters.ros2_mcap.frames import _apply_offset, _cov3, _to_map, _twist_to_map
from aveas_format.converters.ros2_mcap.messages import _Objects
from aveas_format.converters.ros2_mcap.options import CLS, NCLS, Ros2McapOptions
from aveas_format.converters.ros2_mcap.read import _read
from aveas_format.converters.ros2_mcap.tree import _Tree
from aveas_format.errors import FormatError
from aveas_format.numeric import central_differences
from aveas_format.schema.taxonomy import CLASSES

#: the uncertainty columns of states, null where unknown
_STD_COLUMNS = ("x_std", "y_std", "xy_corr", "heading_std", "vx_std", "vy_std", "vxvy_corr")


@converter("ros2-mcap", description="ROS 2 MCAP of a road vehicle: Autoware/derived_object_msgs/"
           "vision_msgs objects + Odometry/NavSatFix ego + /tf",
           patterns=("*.mcap",), method="road_vehicle", options=Ros2McapOptions,
           requires=("mcap", "mcap_ros2"), extra="ros2", provides=("start_time",))
def convert_ros2_mcap(inputs: list[Path], *, map_source, options: Ros2McapOptions):
    o = options
    if o.ego_class not in CLASSES:
        raise FormatError(f"ego_class {o.ego_class!r} is not one of {list(CLASSES)}")
    types, obj_topics, odom, fix, objs, edges, ego_odom, ego_fix = _read(inputs, o)
    map_bytes = load_map_bytes(map_source)
    tree = _Tree(edges, o.map_frame, int(o.tf_tolerance_s * 1e9))
    first = inputs[0]

    ego = None
    if ego_odom["t"]:
        ego = _ego_from_odometry(ego_odom, odom, tree, o, first)
    elif ego_fix["t"]:
        ego = _ego_from_navsatfix(ego_fix, fix, tree, o, map_bytes)
    rows = _objects_in_map(objs, obj_topics, tree, ego, o, first)
    t0 = _time_zero(rows, ego, first)

    n_ego = int(ego is not None)
    parts = [] if ego is None else [_ego_states(ego, o)]
    p_extra: dict[str, Any] = {}
    if rows and len(rows["t_ns"]):
        obj_states, p_extra = _object_states(rows, t0, n_ego, o, first)
        parts.append(obj_states)
    states = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in parts[0]}
    states["time"] = (states.pop("t_ns") - t0) / 1e9
    for k in _STD_COLUMNS:
        states[k] = nullable(states[k])

    return wrap_recording(
        "ros2-mcap", inputs, options, map_bytes=map_bytes,
        participants=_participants(ego, p_extra, o), states=states, method="road_vehicle",
        provenance="natural", start_time=utc_iso_from_ns(t0),
        acquisition={"platform": "road vehicle (ROS 2)",
                     "sensors": _sensors(ego, obj_topics, types, o)},
    )


# --- ego track -------------------------------------------------------------------------------------

def _sorted_unique(t_ns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Order of the samples by stamp with repeated stamps dropped (the first kept), and the
    stamps in that order."""
    t = np.asarray(t_ns, np.int64)
    order = np.argsort(t, kind="stable")
    keep = np.r_[True, np.diff(t[order]) > 0]
    order = order[keep]
    return order, t[order]


def _ego_from_odometry(ego_odom: dict[str, list], odom: str, tree: _Tree, o: Ros2McapOptions,
                       first: Path) -> dict[str, Any]:
    """The ego track in the map frame from the odometry; its frame joins the transform tree
    (with its pose covariance) unless /tf has it."""
    order, t = _sorted_unique(ego_odom["t"])
    pose = np.asarray(ego_odom["pose"], np.float64)[order]
    pcov = _cov3(np.asarray(ego_odom["pcov"])[order])
    twist = np.asarray(ego_odom["twist"], np.float64)[order]
    tcov = _cov3(np.asarray(ego_odom["tcov"])[order])
    parent, child = ego_odom["frame"][0], ego_odom["child"][0] or o.base_frame
    if child not in tree.e:
        tree.add(parent, child, t, pose[:, :3], pose[:, 3:], pcov.reshape(-1, 9), odom)
    # the odometry's pose in map: its parent frame's pose composed with the message
    if not tree.reaches(parent, o.map_frame):
        raise FormatError(f"odometry frame {parent!r} has no transform to {o.map_frame!r} "
                          f"(topic {odom}); set map_frame or record /tf", path=first)
    r_p, p_p, ok_p, _ = tree.lookup(parent, t)
    pos, heading, cov, th = _to_map(r_p, p_p, None, pose, pcov)
    v, vcov = _twist_to_map(heading, twist, tcov, cov[:, 2, 2])
    return {"t": t, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2], "heading": heading,
            "cov": cov, "v": v, "vcov": vcov, "yaw_rate": twist[:, 2],
            "yaw_rate_var": tcov[:, 2, 2], "source": odom, "frame": child}


def _ego_from_navsatfix(ego_fix: dict[str, list], fix: str, tree: _Tree, o: Ros2McapOptions,
                        map_bytes: bytes) -> dict[str, Any]:
    """The ego track in the map frame from NavSatFix lon/lat (projected through the map's CRS;
    heading and velocity from the motion); map -> base_frame joins the transform tree unless the
    tree already reaches base_frame."""
    from aveas_format.mapref.crs import LocalFrame
    from aveas_format.opendrive import load_map

    net = load_map(map_bytes)
    if not net.header.geo_reference:
        raise FormatError("NavSatFix needs a map with a <geoReference> to project lon/lat")
    order, t = _sorted_unique(ego_fix["t"])
    ll = np.asarray(ego_fix["lonlat"], np.float64)[order]
    lx, ly = LocalFrame(net.header.geo_reference, net.header.offset, warn=False).from_wgs84(
        ll[:, 0], ll[:, 1])
    fc = np.asarray(ego_fix["cov"], np.float64)[order].reshape(-1, 2, 2)
    # local frame -> ROS map frame (inverse frame_offset), so objects can use the same tree
    ox, oy, oyaw = o.frame_offset
    c, s = np.cos(-oyaw), np.sin(-oyaw)
    mx, my = c * (lx - ox) - s * (ly - oy), s * (lx - ox) + c * (ly - oy)
    pid0 = np.zeros(len(t), np.int64)
    ts = (t - t[0]) / 1e9
    sx = np.sqrt(np.clip(fc[:, 0, 0], 0, None))
    sy = np.sqrt(np.clip(fc[:, 1, 1], 0, None))
    vx, vy, vxs, vys = central_differences(pid0, ts, mx, my, sx, sy)
    from aveas_format.mapref.build import heading_from_velocity

    heading = heading_from_velocity(pid0, vx, vy)
    speed = np.hypot(vx, vy)
    with np.errstate(divide="ignore", invalid="ignore"):
        hstd = np.where(speed > 0.5, np.hypot(vxs, vys) / speed, np.nan)
    cov = np.zeros((len(t), 3, 3))
    rot = np.array([[c, -s], [s, c]])
    cov[:, :2, :2] = np.einsum("ij,njk,lk->nil", rot, fc, rot)
    cov[:, 2, 2] = hstd ** 2
    pos = np.c_[mx, my, np.zeros(len(t))]
    q = np.c_[np.zeros((len(t), 2)), np.sin(heading / 2), np.cos(heading / 2)]
    if not tree.reaches(o.base_frame, o.map_frame):
        tree.add(o.map_frame, o.base_frame, t, pos, q, cov.reshape(-1, 9), fix)
    vcov = np.zeros((len(t), 2, 2))
    vcov[:, 0, 0], vcov[:, 1, 1] = vxs ** 2, vys ** 2
    return {"t": t, "x": mx, "y": my, "z": None, "heading": heading, "cov": cov,
            "v": np.c_[vx, vy], "vcov": vcov, "yaw_rate": None, "yaw_rate_var": None,
            "source": fix, "frame": o.base_frame}


# --- objects ---------------------------------------------------------------------------------------

def _objects_in_map(objs: _Objects, obj_topics: list[str], tree: _Tree, ego: dict[str, Any] | None,
                    o: Ros2McapOptions, first: Path) -> dict[str, np.ndarray]:
    """Every object row in the map frame (positions, headings, velocities, covariances), frame by
    frame; rows outside the transforms' time spans are dropped with a warning. {} without rows."""
    n = len(objs.t_ns)
    if not n:
        return {}
    t_ns = np.asarray(objs.t_ns, np.int64)
    pose = np.asarray(objs.pose, np.float64)
    pcov = _cov3(objs.pcov)
    twist = np.asarray(objs.twist, np.float64)
    tcov = _cov3(objs.tcov)
    kind = np.asarray(objs.twist_kind)
    topic = np.asarray(objs.topic)
    bad = ~np.isfinite(pose).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        mi, oi = objs.where[i]
        raise FormatError(f"topic {obj_topics[topic[i]]} message {mi}: object {oi}: pose is "
                          "not finite", path=first)
    x = np.empty(n)
    y = np.empty(n)
    z = np.empty(n)
    heading = np.empty(n)
    cov = np.empty((n, 3, 3))
    vel = np.full((n, 2), np.nan)
    vcov = np.full((n, 2, 2), np.nan)
    valid = np.ones(n, bool)
    frames, fcodes = np.unique(np.asarray(objs.frame, dtype=object).astype(str),
                               return_inverse=True)
    for k, fr in enumerate(frames):
        fr = str(fr)
        sel = np.flatnonzero(fcodes == k)
        frn = fr.lstrip("/") or o.map_frame
        if not tree.reaches(frn, o.map_frame):
            i = sel[0]
            mi, _ = objs.where[i]
            raise FormatError(
                f"topic {obj_topics[topic[i]]} message {mi}: frame {fr!r} has no transform to "
                f"{o.map_frame!r} (needs /tf, an odometry with child frame {fr!r} or a NavSatFix "
                f"ego with base_frame={fr!r})", path=first)
        r_f, p_f, ok, cov_f = tree.lookup(frn, t_ns[sel])
        valid[sel] = ok
        pos, hd, cv, th = _to_map(r_f, p_f, cov_f, pose[sel], pcov[sel])
        x[sel], y[sel], z[sel] = pos[:, 0], pos[:, 1], pos[:, 2]
        heading[sel] = hd
        cov[sel] = cv
        # velocities: object body frame (rotate by heading) or header frame (rotate by frame yaw)
        body = kind[sel] == 0
        hdr = kind[sel] == 1
        if body.any():
            b = sel[body]
            v, vc = _twist_to_map(hd[body], twist[b], tcov[b], cv[body, 2, 2])
            vel[b], vcov[b] = v, vc
        if hdr.any():
            h = sel[hdr]
            var_th = cov_f[0][hdr, 2, 2] if cov_f is not None else np.zeros(hdr.sum())
            v, vc = _twist_to_map(th[hdr], twist[h], tcov[h], var_th)
            if o.relative_velocity and ego is not None and frn != o.map_frame:
                v, vc = _add_ego_motion(v, vc, t_ns[h], x[h], y[h], ego)
            vel[h], vcov[h] = v, vc
    if not valid.all():
        warnings.warn(f"{int((~valid).sum())} object samples lie outside the transforms' time "
                      f"span (+- {o.tf_tolerance_s} s) and are dropped", stacklevel=3)
    keys = [f"{topic[i]}:{objs.oid[i]}" for i in range(n)] if len(obj_topics) > 1 else objs.oid
    rows = {"t_ns": t_ns, "key": np.asarray(keys, dtype=object), "x": x, "y": y, "z": z,
            "heading": heading, "cov": cov, "vel": vel, "vcov": vcov,
            "dims": np.asarray(objs.dims, np.float64), "pmf": np.asarray(objs.pmf),
            "nru": np.asarray(objs.nru, np.float64), "nru_label": np.asarray(objs.nru_label, dtype=object),
            "orient": np.asarray(objs.orient), "valid": valid}
    rows = {k: v[valid] for k, v in rows.items()}
    if not len(rows["t_ns"]) and ego is None:
        raise FormatError("no object sample has a transform to the map frame", path=first)
    return rows


def _road_users(r: dict[str, np.ndarray], codes: np.ndarray, uniq: np.ndarray, o: Ros2McapOptions):
    """Drop the tracks whose classification is mostly a label that is no road user (unless
    ``keep_non_road_users``), with a warning counting them by label; ``(rows, codes, uniq)``."""
    if o.keep_non_road_users or not len(codes) or not (r["nru"] > 0.5).any():
        return r, codes, uniq
    skip = group_mean(codes, r["nru"], len(uniq)) > 0.5
    if not skip.any():
        return r, codes, uniq
    from collections import Counter

    first = np.unique(codes, return_index=True)[1]
    names = Counter(str(r["nru_label"][i]) or "no road user" for i in first[skip])
    warnings.warn(f"skipped {int(skip.sum())} tracks: " + ", ".join(f"{c} {n}" for n, c in sorted(names.items()))
                  + " (no road user); option keep_non_road_users=true imports them", stacklevel=4)
    keep = ~skip[codes]
    r = {k: v[keep] for k, v in r.items()}
    codes, uniq = factorize(r["key"])
    return r, codes, uniq


def _add_ego_motion(v: np.ndarray, vc: np.ndarray, t_ns: np.ndarray, x: np.ndarray, y: np.ndarray,
                    ego: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Velocities relative to the moving ego -> absolute: the ego's velocity (interpolated at the
    stamps) plus ``omega x r`` about its position, its velocity covariance added."""
    tq = (t_ns - ego["t"][0]).astype(np.float64)
    te = (ego["t"] - ego["t"][0]).astype(np.float64)
    evx = np.interp(tq, te, ego["v"][:, 0])
    evy = np.interp(tq, te, ego["v"][:, 1])
    w = np.interp(tq, te, ego["yaw_rate"]) if ego["yaw_rate"] is not None else 0.0
    ex = np.interp(tq, te, ego["x"])
    ey = np.interp(tq, te, ego["y"])
    v = v + np.c_[evx - w * (y - ey), evy + w * (x - ex)]
    vc = vc + np.nan_to_num(np.stack(
        [np.interp(tq, te, ego["vcov"][:, a, b]) for a in range(2) for b in range(2)],
        -1).reshape(-1, 2, 2))
    return v, vc


def _time_zero(rows: dict[str, np.ndarray], ego: dict[str, Any] | None, first: Path) -> int:
    """The earliest stamp of the object rows and the ego track (ns)."""
    stamps = [a for a in (rows.get("t_ns"), None if ego is None else ego["t"])
              if a is not None and len(a)]
    if not stamps:
        raise FormatError("no samples: the object topics are empty and there is no ego pose",
                          path=first)
    return int(min(int(a.min()) for a in stamps))


# --- states ----------------------------------------------------------------------------------------

def _ego_states(ego: dict[str, Any], o: Ros2McapOptions) -> dict[str, np.ndarray]:
    """The ego's state rows (participant 0): footprint centre ``ego_center_offset`` ahead of
    base_frame (its covariance through the lever arm), in the OpenDRIVE map's frame."""
    te = ego["t"]
    d = o.ego_center_offset
    hx, hy = np.cos(ego["heading"]), np.sin(ego["heading"])
    ex, ey = ego["x"] + d * hx, ego["y"] + d * hy
    ecov = ego["cov"].copy()
    j = np.zeros((len(te), 2, 3))
    j[:, 0, 0] = j[:, 1, 1] = 1.0
    j[:, 0, 2], j[:, 1, 2] = -d * hy, d * hx
    cxy = np.einsum("nij,njk,nlk->nil", j, ecov, j)
    ex, ey, eh, cxy, evx, evy, evc = _apply_offset(o.frame_offset, ex, ey, ego["heading"], cxy,
                                                  ego["v"][:, 0], ego["v"][:, 1], ego["vcov"])
    sx, sy, rho = covariance_std_corr(cxy)
    vsx, vsy, vrho = covariance_std_corr(evc)
    return dict(participant_id=np.zeros(len(te), np.int64), t_ns=te, x=ex, y=ey, heading=eh,
                vx=evx, vy=evy, x_std=sx, y_std=sy, xy_corr=rho,
                heading_std=np.sqrt(ecov[:, 2, 2]), vx_std=vsx, vy_std=vsy, vxvy_corr=vrho)


def _object_states(rows: dict[str, np.ndarray], t0: int, n_ego: int, o: Ros2McapOptions,
                   first: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The objects' state rows (participants from ``n_ego`` on, one per track key, repeated
    (track, stamp) samples dropped with a warning) and per participant its source id, mean PMF,
    mean dimensions and their spread."""
    codes, uniq = factorize(rows["key"])
    order = np.lexsort((rows["t_ns"], codes))
    r = {k: v[order] for k, v in rows.items()}
    codes = codes[order]
    dup = np.r_[False, (codes[1:] == codes[:-1]) & (r["t_ns"][1:] == r["t_ns"][:-1])]
    if dup.any():
        k = int(np.flatnonzero(dup)[0])
        warnings.warn(f"{first}: {int(dup.sum())} object sample(s) repeat a (track, stamp) and "
                      f"were dropped, the first kept (e.g. track {uniq[codes[k]]!r} at stamp "
                      f"{int(r['t_ns'][k])} ns)", stacklevel=3)
    r = {k: v[~dup] for k, v in r.items()}
    codes = codes[~dup]
    r, codes, uniq = _road_users(r, codes, uniq, o)
    m = len(uniq)
    ts = (r["t_ns"] - t0) / 1e9
    # velocities where the source has none: from positions
    psx = np.sqrt(np.clip(r["cov"][:, 0, 0], 0, None))
    psy = np.sqrt(np.clip(r["cov"][:, 1, 1], 0, None))
    fvx, fvy, fvxs, fvys = central_differences(codes, ts, r["x"], r["y"], psx, psy)
    nov = np.isnan(r["vel"]).any(axis=1)
    r["vel"][nov] = np.c_[fvx, fvy][nov]
    r["vcov"][nov] = 0.0
    r["vcov"][nov, 0, 0], r["vcov"][nov, 1, 1] = fvxs[nov] ** 2, fvys[nov] ** 2
    # heading where unavailable or only known up to its sign
    from aveas_format.mapref.build import heading_from_velocity

    hv = heading_from_velocity(codes, r["vel"][:, 0], r["vel"][:, 1])
    moving = np.hypot(r["vel"][:, 0], r["vel"][:, 1]) >= 0.5
    h = r["heading"]
    h = np.where(r["orient"] == 0, hv, h)
    flip = (r["orient"] == 1) & moving & (np.cos(h - hv) < 0)
    h = np.where(flip, h + np.pi, h)
    r["cov"][r["orient"] == 0, 2, 2] = np.nan
    x, y, h, cxy, vx, vy, vc = _apply_offset(o.frame_offset, r["x"], r["y"], h,
                                             r["cov"][:, :2, :2], r["vel"][:, 0],
                                             r["vel"][:, 1], r["vcov"])
    sx, sy, rho = covariance_std_corr(cxy)
    vsx, vsy, vrho = covariance_std_corr(vc)
    states = dict(participant_id=codes + n_ego, t_ns=r["t_ns"], x=x, y=y, heading=h, vx=vx, vy=vy,
                  x_std=sx, y_std=sy, xy_corr=rho, heading_std=np.sqrt(r["cov"][:, 2, 2]),
                  vx_std=vsx, vy_std=vsy, vxvy_corr=vrho)
    dims = r["dims"]
    mean_dims = group_mean(codes, dims, m)
    std_dims = np.stack([group_std(codes, dims[:, k], m) for k in range(3)], -1)
    pmf = group_mean(codes, r["pmf"], m)
    pmf = pmf / pmf.sum(axis=1, keepdims=True)
    sizes = np.where(np.isfinite(mean_dims) & (mean_dims > 0), mean_dims, np.nan)
    if np.isnan(sizes[:, :2]).any():
        bad = int(np.flatnonzero(np.isnan(sizes[:, :2]).any(axis=1))[0])
        raise FormatError(f"object {uniq[bad]!r} has no positive length/width in any message",
                          path=first)
    return states, {"source_id": list(uniq), "pmf": pmf, "sizes": sizes, "size_std": std_dims}


# --- participants and sensors ----------------------------------------------------------------------

def _participants(ego: dict[str, Any] | None, p_extra: dict[str, Any],
                  o: Ros2McapOptions) -> dict[str, Any]:
    """The participants table: the ego (from the options) first, then the objects."""
    n_ego = int(ego is not None)
    nobj = len(p_extra.get("source_id", []))
    mtot = n_ego + nobj
    pmf_all = np.zeros((mtot, NCLS), np.float32)
    length = np.empty(mtot)
    width = np.empty(mtot)
    height = np.full(mtot, np.nan)
    lstd = np.full(mtot, np.nan)
    wstd = np.full(mtot, np.nan)
    hstd = np.full(mtot, np.nan)
    if n_ego:
        pmf_all[0, CLS[o.ego_class]] = 1.0
        length[0], width[0], height[0] = o.ego_length, o.ego_width, o.ego_height
        lstd[0] = wstd[0] = hstd[0] = 0.0
    if nobj:
        pmf_all[n_ego:] = p_extra["pmf"]
        length[n_ego:], width[n_ego:], height[n_ego:] = p_extra["sizes"].T
        lstd[n_ego:], wstd[n_ego:], hstd[n_ego:] = p_extra["size_std"].T
    participants = {
        "participant_id": np.arange(mtot, dtype=np.int64),
        "source_id": (["ego"] if n_ego else []) + [str(s) for s in p_extra.get("source_id", [])],
        "class": np.asarray(CLASSES, dtype=object)[np.argmax(pmf_all, axis=1)],
        "class_pmf": pmf_all,
        "length": length, "width": width, "height": nullable(height),
        "length_std": nullable(lstd), "width_std": nullable(wstd), "height_std": nullable(hstd),
        "role": (["recording_vehicle"] if n_ego else []) + ["observed"] * nobj,
        "provenance": ["natural"] * mtot,
    }
    if n_ego:
        participants["attributes"] = [json.dumps({"base_frame": o.base_frame,
                                                  "pose_topic": ego["source"]})] + [None] * nobj
    return participants


def _sensors(ego: dict[str, Any] | None, obj_topics: list[str], types: dict[str, str],
             o: Ros2McapOptions) -> list[dict[str, Any]]:
    """acquisition.sensors: the ego's pose topic, then every object topic."""
    sensors = []
    if ego is not None:
        sensors.append({"id": ego["source"], "kind": "gnss_imu",
                        "description": types.get(ego["source"], "")})
    for tp in obj_topics:
        sensors.append({"id": tp, "kind": o.object_sensor_kind, "description": types[tp],
                        "pose": {"frame": "platform"}})
    return sensors
