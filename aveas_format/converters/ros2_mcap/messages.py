"""Per-message readers: a decoded ROS 2 message -> flat rows (object rows, ego samples, transform
samples), filled message by message and vectorised afterwards."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aveas_format.converters.labels import ROAD_USER, label_kind
from aveas_format.converters.ros2_mcap.options import (
    AUTOWARE_LABELS,
    AUTOWARE_NOT_ROAD_USERS,
    CLS,
    DERIVED_LABELS,
    DERIVED_NOT_ROAD_USERS,
    NCLS,
    T_DERIVED,
    T_DET3D,
    T_TRACKED,
    Ros2McapOptions,
)
from aveas_format.converters.ros2_mcap.tree import TransformSamples

# 3x3 sub-blocks (x, y, yaw) of a row-major 6x6 covariance and (vx, vy, wz) of a twist covariance
_SUB = np.array([0, 1, 5, 6, 7, 11, 30, 31, 35])

@dataclass
class ObjectRows:
    """Flat per-object rows of every object topic (filled per message, then vectorised)."""

    t_ns: list[int] = field(default_factory=list)
    topic: list[int] = field(default_factory=list)
    frame: list[str] = field(default_factory=list)
    oid: list[str] = field(default_factory=list)
    pose: list[tuple] = field(default_factory=list)      # x, y, z, qx, qy, qz, qw
    pcov: list[tuple] = field(default_factory=list)      # 9 = (x, y, yaw) block
    twist: list[tuple] = field(default_factory=list)     # vx, vy, wz (nan: none)
    tcov: list[tuple] = field(default_factory=list)      # 9
    twist_kind: list[int] = field(default_factory=list)  # 0 body, 1 header frame, 2 none
    dims: list[tuple] = field(default_factory=list)
    pmf: list[np.ndarray] = field(default_factory=list)
    nru: list[float] = field(default_factory=list)     # probability of a label that is no road user
    nru_label: list[str] = field(default_factory=list)  # that label's name (or "")
    orient: list[int] = field(default_factory=list)      # Autoware orientation_availability
    where: list[tuple[int, int]] = field(default_factory=list)  # (message index, object index)


def header_stamp(header, log_time: int) -> tuple[int, bool]:
    t = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return (t, True) if t != 0 else (int(log_time), False)


def _vec(v) -> tuple[float, float, float]:
    return (v.x, v.y, v.z)


def _pose7(p) -> tuple:
    return (p.position.x, p.position.y, p.position.z,
            p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)


def _sub9(cov) -> tuple:
    if len(cov) != 36:
        raise ValueError(f"covariance has {len(cov)} values, not 36")
    return tuple(cov[i] for i in _SUB)


def _pmf_one(label: str, p: float = 1.0) -> np.ndarray:
    out = np.full(NCLS, (1.0 - p) / NCLS)
    out[CLS[label]] += p
    return out


def read_tracked(msg, objs: ObjectRows, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
    frame = msg.header.frame_id
    for oi, o in enumerate(msg.objects):
        if o.existence_probability < opts.min_existence_probability:
            continue
        k = o.kinematics
        pmf = np.zeros(NCLS)
        nru, nru_label = 0.0, ""
        for c in o.classification:
            pmf[CLS[AUTOWARE_LABELS.get(int(c.label), "other")]] += max(float(c.probability), 0.0)
            if int(c.label) in AUTOWARE_NOT_ROAD_USERS:
                nru += max(float(c.probability), 0.0)
                nru_label = AUTOWARE_NOT_ROAD_USERS[int(c.label)]
        if pmf.sum() <= 0:
            pmf[CLS["other"]] = 1.0
        objs.nru.append(nru / pmf.sum())
        objs.nru_label.append(nru_label)
        sh = o.shape
        d = sh.dimensions
        if sh.type == 1:  # cylinder: x = diameter
            dims = (d.x, d.x, d.z)
        elif sh.type == 2 and len(sh.footprint.points) >= 3:
            px = [p.x for p in sh.footprint.points]
            py = [p.y for p in sh.footprint.points]
            dims = (max(px) - min(px), max(py) - min(py), d.z)
        else:
            dims = (d.x, d.y, d.z)
        tw = k.twist_with_covariance
        objs.t_ns.append(t_ns)
        objs.topic.append(ti)
        objs.frame.append(frame)
        objs.oid.append(bytes(o.object_id.uuid).hex())
        objs.pose.append(_pose7(k.pose_with_covariance.pose))
        objs.pcov.append(_sub9(k.pose_with_covariance.covariance))
        objs.twist.append((tw.twist.linear.x, tw.twist.linear.y, tw.twist.angular.z))
        objs.tcov.append(_sub9(tw.covariance))
        objs.twist_kind.append(0)
        objs.dims.append(dims)
        objs.pmf.append(pmf / pmf.sum())
        objs.orient.append(int(k.orientation_availability))
        objs.where.append((mi, oi))


def read_derived(msg, objs: ObjectRows, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
    for oi, o in enumerate(msg.objects):
        frame = o.header.frame_id or msg.header.frame_id
        dims_in = list(o.shape.dimensions)
        st = int(o.shape.type)
        if st == 1 and len(dims_in) >= 3:
            dims = (dims_in[0], dims_in[1], dims_in[2])
        elif st == 3 and len(dims_in) >= 2:  # cylinder: height, radius
            dims = (2 * dims_in[1], 2 * dims_in[1], dims_in[0])
        elif st == 2 and dims_in:  # sphere: radius
            dims = (2 * dims_in[0],) * 3
        else:
            dims = (np.nan, np.nan, np.nan)
        label = DERIVED_LABELS.get(int(o.classification), "other")
        cert = int(o.classification_certainty)
        nru_label = DERIVED_NOT_ROAD_USERS.get(int(o.classification), "")
        objs.nru.append(1.0 if nru_label else 0.0)
        objs.nru_label.append(nru_label)
        objs.t_ns.append(t_ns)
        objs.topic.append(ti)
        objs.frame.append(frame)
        objs.oid.append(str(o.id))
        objs.pose.append(_pose7(o.pose.pose))
        objs.pcov.append(_sub9(o.pose.covariance))
        objs.twist.append((o.twist.twist.linear.x, o.twist.twist.linear.y, o.twist.twist.angular.z))
        objs.tcov.append(_sub9(o.twist.covariance))
        objs.twist_kind.append(1)
        objs.dims.append(dims)
        objs.pmf.append(_pmf_one(label, 1.0 if cert == 0 else cert / 255.0))
        objs.orient.append(2)
        objs.where.append((mi, oi))


def read_det3d(msg, objs: ObjectRows, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
    for oi, d in enumerate(msg.detections):
        frame = d.header.frame_id or msg.header.frame_id
        pmf = np.zeros(NCLS)
        best, best_score = None, -np.inf
        nru, nru_label = 0.0, ""
        for h in d.results:
            s = float(h.hypothesis.score)
            cls, kind = label_kind(h.hypothesis.class_id, opts.class_map)
            pmf[CLS[cls]] += max(s, 0.0)
            if kind != ROAD_USER:
                nru += max(s, 0.0)
                nru_label = str(h.hypothesis.class_id)
            if s > best_score:
                best, best_score = h, s
        if pmf.sum() <= 0:
            pmf[CLS["other"]] = 1.0
        objs.nru.append(nru / pmf.sum())
        objs.nru_label.append(nru_label)
        objs.t_ns.append(t_ns)
        objs.topic.append(ti)
        objs.frame.append(frame)
        objs.oid.append(d.id if d.id else f"~{mi}.{oi}")
        objs.pose.append(_pose7(d.bbox.center))
        objs.pcov.append(_sub9(best.pose.covariance) if best is not None else (0.0,) * 9)
        objs.twist.append((np.nan, np.nan, np.nan))
        objs.tcov.append((0.0,) * 9)
        objs.twist_kind.append(2)
        objs.dims.append(_vec(d.bbox.size))
        objs.pmf.append(pmf / pmf.sum())
        objs.orient.append(2)
        objs.where.append((mi, oi))


OBJECT_READERS = {T_TRACKED: read_tracked, T_DERIVED: read_derived, T_DET3D: read_det3d}



def read_tf(msg, edges: TransformSamples, topic: str, log_time: int) -> None:
    """The transforms of a tf2_msgs/TFMessage (static on a topic named ``*tf_static``)."""
    static = topic.endswith("tf_static")
    for tr in msg.transforms:
        t_ns, ok = header_stamp(tr.header, log_time)
        q = tr.transform.rotation
        edges.add(tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"),
                  t_ns, _vec(tr.transform.translation), (q.x, q.y, q.z, q.w),
                  static, topic)


def read_odometry(msg, ego_odom: dict[str, list], t_ns: int) -> None:
    """One nav_msgs/Odometry sample of the ego."""
    ego_odom["t"].append(t_ns)
    ego_odom["pose"].append(_pose7(msg.pose.pose))
    ego_odom["pcov"].append(_sub9(msg.pose.covariance))
    tw = msg.twist.twist
    ego_odom["twist"].append((tw.linear.x, tw.linear.y, tw.angular.z))
    ego_odom["tcov"].append(_sub9(msg.twist.covariance))
    ego_odom["frame"].append(msg.header.frame_id.lstrip("/"))
    ego_odom["child"].append(msg.child_frame_id.lstrip("/"))


def read_navsatfix(msg, ego_fix: dict[str, list], t_ns: int) -> None:
    """One sensor_msgs/NavSatFix sample of the ego (a fix; the caller skips status < 0)."""
    ego_fix["t"].append(t_ns)
    ego_fix["lonlat"].append((msg.longitude, msg.latitude))
    c = list(msg.position_covariance)
    known = int(msg.position_covariance_type) > 0 and len(c) == 9
    ego_fix["cov"].append((c[0], c[1], c[3], c[4]) if known else (np.nan,) * 4)
