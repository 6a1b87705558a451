"""``convert_ros2_mcap`` (registered as ``ros2-mcap``) and its named steps: the ego track, the
objects in the map frame, the states, the participants. The converter's documentation is the
package's docstring (:mod:`aveas_format.converters.ros2_mcap`), which docs/converters.md shows."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.converters.common.assemble import group_mean, participant_columns, to_recording
from aveas_format.converters.common.boxes import MEASURED, Boxes, Rows, Sensor, Sizes
from aveas_format.converters.common.geometry import covariance_std_corr
from aveas_format.converters.common.tables import factorize
from aveas_format.converters.common.timestamps import utc_iso_from_ns
from aveas_format.converters.registry import converter
from aveas_format.converters.ros2_mcap.frames import apply_offset, cov3, to_map, twist_to_map
from aveas_format.converters.ros2_mcap.messages import ObjectRows
from aveas_format.converters.ros2_mcap.options import CLS, NCLS, Ros2McapOptions
from aveas_format.converters.ros2_mcap.read import read_topics
from aveas_format.converters.ros2_mcap.tree import TransformTree
from aveas_format.errors import FormatError
from aveas_format.mapref.build import load_map_bytes
from aveas_format.numeric import central_differences
from aveas_format.schema.taxonomy import CLASSES

@converter("ros2-mcap", description="ROS 2 MCAP of a road vehicle: Autoware/derived_object_msgs/"
           "vision_msgs objects + Odometry/NavSatFix ego + /tf",
           patterns=("*.mcap",), method="road_vehicle", options=Ros2McapOptions,
           requires=("mcap", "mcap_ros2"), extra="ros2", provides=("start_time",),
           sniff=(b"ros2msg", b"ros2idl"))
def convert_ros2_mcap(inputs: list[Path], *, map_source, options: Ros2McapOptions):
    o = options
    if o.ego_class not in CLASSES:
        raise FormatError(f"ego_class {o.ego_class!r} is not one of {list(CLASSES)}")
    types, obj_topics, odom, fix, objs, edges, ego_odom, ego_fix = read_topics(inputs, o)
    map_bytes = load_map_bytes(map_source)
    tree = TransformTree(edges, o.map_frame, int(o.tf_tolerance_s * 1e9))
    first = inputs[0]

    ego = None
    if ego_odom["t"]:
        ego = _ego_from_odometry(ego_odom, odom, tree, o, first)
    elif ego_fix["t"]:
        ego = _ego_from_navsatfix(ego_fix, fix, tree, o, map_bytes)
    rows = _objects_in_map(objs, obj_topics, tree, ego, o, first)
    t0 = _time_zero(rows, ego, first)
    parts = []
    if ego is not None:  # participant 0
        e = _ego_states(ego, o)
        parts.append(e | {"time": (e.pop("t_ns") - t0) / 1e9})
    obj = _object_boxes(rows, t0, o, first) if rows and len(rows["t_ns"]) else None
    if obj is not None:
        parts.append({k: v for k, v in obj.columns.items() if k not in MEASURED}
                     | {"participant_id": obj.pid + len(parts), "time": obj.time})
    cols = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in parts[0]}
    source_ids = (["ego"] if ego is not None else []) + ([] if obj is None else list(obj.source_ids))
    boxes = Boxes(cols.pop("participant_id"), cols.pop("time"), cols.pop("x"), cols.pop("y"),
                  source_ids=source_ids, rows=Rows([first]), **cols)
    sensor = Sensor(method="road_vehicle", start_time=utc_iso_from_ns(t0),
                    platform="road vehicle (ROS 2)", sensors=_sensors(ego, obj_topics, types, o))
    return to_recording(boxes, sensor, converter="ros2-mcap", inputs=inputs, options=options,
                        map_bytes=map_bytes, participants=_participants(ego, obj, o))


# --- ego track -------------------------------------------------------------------------------------

def _sorted_unique(t_ns: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Order of the samples by stamp with repeated stamps dropped (the first kept), and the
    stamps in that order."""
    t = np.asarray(t_ns, np.int64)
    order = np.argsort(t, kind="stable")
    keep = np.r_[True, np.diff(t[order]) > 0]
    order = order[keep]
    return order, t[order]


def _ego_from_odometry(ego_odom: dict[str, list], odom: str, tree: TransformTree, o: Ros2McapOptions,
                       first: Path) -> dict[str, Any]:
    """The ego track in the map frame from the odometry; its frame joins the transform tree
    (with its pose covariance) unless /tf has it."""
    order, t = _sorted_unique(ego_odom["t"])
    pose = np.asarray(ego_odom["pose"], np.float64)[order]
    pcov = cov3(np.asarray(ego_odom["pcov"])[order])
    twist = np.asarray(ego_odom["twist"], np.float64)[order]
    tcov = cov3(np.asarray(ego_odom["tcov"])[order])
    parent, child = ego_odom["frame"][0], ego_odom["child"][0] or o.base_frame
    if child not in tree.e:
        tree.add(parent, child, t, pose[:, :3], pose[:, 3:], pcov.reshape(-1, 9), odom)
    # the odometry's pose in map: its parent frame's pose composed with the message
    if not tree.reaches(parent, o.map_frame):
        raise FormatError(f"odometry frame {parent!r} has no transform to {o.map_frame!r} "
                          f"(topic {odom}); set map_frame or record /tf", path=first)
    r_p, p_p, ok_p, _ = tree.lookup(parent, t)
    pos, heading, cov, th = to_map(r_p, p_p, None, pose, pcov)
    v, vcov = twist_to_map(heading, twist, tcov, cov[:, 2, 2])
    return {"t": t, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2], "heading": heading,
            "cov": cov, "v": v, "vcov": vcov, "yaw_rate": twist[:, 2],
            "yaw_rate_var": tcov[:, 2, 2], "source": odom, "frame": child}


def _ego_from_navsatfix(ego_fix: dict[str, list], fix: str, tree: TransformTree, o: Ros2McapOptions,
                        map_bytes: bytes) -> dict[str, Any]:
    """The ego track in the map frame from NavSatFix lon/lat (projected through the map's CRS;
    heading and velocity from the motion); map -> base_frame joins the transform tree unless the
    tree already reaches base_frame."""
    from aveas_format.converters.common.geometry import map_crs, missing_crs
    from aveas_format.crs import LocalFrame
    from aveas_format.opendrive import load_map

    net = load_map(map_bytes)
    crs = map_crs(net.header, o)
    if crs is None:
        raise missing_crs("NavSatFix (lon/lat) needs the map frame's CRS to project")
    order, t = _sorted_unique(ego_fix["t"])
    ll = np.asarray(ego_fix["lonlat"], np.float64)[order]
    lx, ly = LocalFrame(crs, net.header.offset, warn=False).from_wgs84(
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

def _objects_in_map(objs: ObjectRows, obj_topics: list[str], tree: TransformTree, ego: dict[str, Any] | None,
                    o: Ros2McapOptions, first: Path) -> dict[str, np.ndarray]:
    """Every object row in the map frame (positions, headings, velocities, covariances), frame by
    frame; rows outside the transforms' time spans are dropped with a warning. {} without rows."""
    n = len(objs.t_ns)
    if not n:
        return {}
    t_ns = np.asarray(objs.t_ns, np.int64)
    pose = np.asarray(objs.pose, np.float64)
    pcov = cov3(objs.pcov)
    twist = np.asarray(objs.twist, np.float64)
    tcov = cov3(objs.tcov)
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
        pos, hd, cv, th = to_map(r_f, p_f, cov_f, pose[sel], pcov[sel])
        x[sel], y[sel], z[sel] = pos[:, 0], pos[:, 1], pos[:, 2]
        heading[sel] = hd
        cov[sel] = cv
        # velocities: object body frame (rotate by heading) or header frame (rotate by frame yaw)
        body = kind[sel] == 0
        hdr = kind[sel] == 1
        if body.any():
            b = sel[body]
            v, vc = twist_to_map(hd[body], twist[b], tcov[b], cv[body, 2, 2])
            vel[b], vcov[b] = v, vc
        if hdr.any():
            h = sel[hdr]
            var_th = cov_f[0][hdr, 2, 2] if cov_f is not None else np.zeros(hdr.sum())
            v, vc = twist_to_map(th[hdr], twist[h], tcov[h], var_th)
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


def _road_users(boxes: Boxes, nru: np.ndarray, nru_label: np.ndarray, o: Ros2McapOptions) -> Boxes:
    """The boxes without the tracks whose classification is mostly a label that is no road user
    (unless ``keep_non_road_users``), with a warning counting them by label."""
    if o.keep_non_road_users or not len(boxes) or not (nru > 0.5).any():
        return boxes
    skip = group_mean(boxes.pid, nru, boxes.m) > 0.5
    if not skip.any():
        return boxes
    from collections import Counter

    first = boxes.first_rows()
    names = Counter(str(nru_label[i]) or "no road user" for i in first[skip])
    warnings.warn(f"skipped {int(skip.sum())} tracks: " + ", ".join(f"{c} {n}" for n, c in sorted(names.items()))
                  + " (no road user); option keep_non_road_users=true imports them", stacklevel=4)
    return boxes.drop_participants(skip)


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
    ex, ey, eh, cxy, evx, evy, evc = apply_offset(o.frame_offset, ex, ey, ego["heading"], cxy,
                                                  ego["v"][:, 0], ego["v"][:, 1], ego["vcov"])
    sx, sy, rho = covariance_std_corr(cxy)
    vsx, vsy, vrho = covariance_std_corr(evc)
    return dict(participant_id=np.zeros(len(te), np.int64), t_ns=te, x=ex, y=ey, heading=eh,
                vx=evx, vy=evy, x_std=sx, y_std=sy, xy_corr=rho,
                heading_std=np.sqrt(ecov[:, 2, 2]), vx_std=vsx, vy_std=vsy, vxvy_corr=vrho)


def _object_boxes(rows: dict[str, np.ndarray], t0: int, o: Ros2McapOptions, first: Path) -> Boxes:
    """The objects' boxes (sorted; a repeated (track, stamp) keeps the first, with a warning;
    tracks that are no road user dropped): velocities from positions where the source has none,
    the heading from the motion where it is unavailable or only known up to its sign, everything
    in the OpenDRIVE map's frame, with the per-box dimensions and class PMFs."""
    from aveas_format.mapref.build import heading_from_velocity

    codes, uniq = factorize(rows["key"])
    boxes = Boxes(codes, (rows["t_ns"] - t0) / 1e9, rows["x"], rows["y"], source_ids=list(uniq),
                  rows=Rows([first]), duplicates="first", length=rows["dims"][:, 0],
                  width=rows["dims"][:, 1], height=rows["dims"][:, 2], class_pmf=rows["pmf"]).sort()
    r = {k: rows[k][boxes.order] for k in ("heading", "cov", "vel", "vcov", "orient", "nru", "nru_label")}
    keep = _road_users(boxes, r["nru"], r["nru_label"], o)
    if keep is not boxes:
        sel = np.flatnonzero(np.isin(boxes.order, keep.order))
        r = {k: v[sel] for k, v in r.items()}
        boxes = keep
    codes, ts = boxes.pid, boxes.time
    # velocities where the source has none: from positions
    psx = np.sqrt(np.clip(r["cov"][:, 0, 0], 0, None))
    psy = np.sqrt(np.clip(r["cov"][:, 1, 1], 0, None))
    fvx, fvy, fvxs, fvys = central_differences(codes, ts, boxes["x"], boxes["y"], psx, psy)
    nov = np.isnan(r["vel"]).any(axis=1)
    r["vel"][nov] = np.c_[fvx, fvy][nov]
    r["vcov"][nov] = 0.0
    r["vcov"][nov, 0, 0], r["vcov"][nov, 1, 1] = fvxs[nov] ** 2, fvys[nov] ** 2
    # heading where unavailable or only known up to its sign
    hv = heading_from_velocity(codes, r["vel"][:, 0], r["vel"][:, 1])
    moving = np.hypot(r["vel"][:, 0], r["vel"][:, 1]) >= 0.5
    h = np.where(r["orient"] == 0, hv, r["heading"])
    h = np.where((r["orient"] == 1) & moving & (np.cos(h - hv) < 0), h + np.pi, h)
    r["cov"][r["orient"] == 0, 2, 2] = np.nan
    x, y, h, cxy, vx, vy, vc = apply_offset(o.frame_offset, boxes["x"], boxes["y"], h,
                                            r["cov"][:, :2, :2], r["vel"][:, 0], r["vel"][:, 1],
                                            r["vcov"])
    sx, sy, rho = covariance_std_corr(cxy)
    vsx, vsy, vrho = covariance_std_corr(vc)
    for k, v in dict(x=x, y=y, heading=h, vx=vx, vy=vy, x_std=sx, y_std=sy, xy_corr=rho,
                     heading_std=np.sqrt(r["cov"][:, 2, 2]), vx_std=vsx, vy_std=vsy,
                     vxvy_corr=vrho).items():
        boxes[k] = v
    return boxes


# --- participants and sensors ----------------------------------------------------------------------

def _participants(ego: dict[str, Any] | None, obj: Boxes | None, o: Ros2McapOptions
                  ) -> dict[str, Any]:
    """The participants' columns: the ego (from the options) first, then the objects (their
    boxes' mean dimensions with their spread, mean class PMF)."""
    n_ego = int(ego is not None)
    nobj = 0 if obj is None else obj.m
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
        p = participant_columns(obj, Sizes(), None)
        pmf_all[n_ego:] = p["class_pmf"]
        for a, k in ((length, "length"), (width, "width"), (height, "height"), (lstd, "length_std"),
                     (wstd, "width_std"), (hstd, "height_std")):
            a[n_ego:] = np.asarray(p[k].to_numpy(zero_copy_only=False) if hasattr(p[k], "to_numpy")
                                   else p[k], np.float64)
    participants = {
        "class": np.asarray(CLASSES, dtype=object)[np.argmax(pmf_all, axis=1)],
        "class_pmf": pmf_all, "length": length, "width": width, "height": height,
        "length_std": lstd, "width_std": wstd, "height_std": hstd,
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
