"""``convert_ros2_mcap`` (registered as ``ros2-mcap``) and its named steps: the ego track, the
objects in the map frame, the states, the participants. The converter's documentation is the
package's docstring (:mod:`aveas_format.converters.ros2_mcap`), which docs/converters.md shows."""

from __future__ import annotations

import json
import warnings
from collections import Counter
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import (
    bounded_states,
    participant_columns,
    to_recording,
    write_by_buckets,
)
from aveas_format.converters.common.boxes import MEASURED, Boxes, Rows, Sensor, Sizes, repeat_message
from aveas_format.converters.common.geometry import covariance_std_corr
from aveas_format.converters.common.timestamps import utc_iso_from_ns
from aveas_format.converters.registry import converter
from aveas_format.converters.ros2_mcap.frames import apply_offset, cov3, to_map, twist_to_map
from aveas_format.converters.ros2_mcap.objects import object_boxes, objects_in_map, skipped_message
from aveas_format.converters.ros2_mcap.options import CLS, NCLS, Ros2McapOptions
from aveas_format.converters.ros2_mcap import rows as object_rows
from aveas_format.converters.ros2_mcap.read import read_topics
from aveas_format.converters.ros2_mcap.tree import TransformTree
from aveas_format.errors import FormatError
from aveas_format.io.arrow import column_numpy
from aveas_format.io.resort import StatesWriter
from aveas_format.mapref.build import load_map_bytes
from aveas_format.numeric import central_differences
from aveas_format.schema.taxonomy import CLASSES


def convert_ros2_mcap_to(inputs: list[Path], output: Path, *, map_source, options: Ros2McapOptions,
                         overwrite: bool = False):
    """The recording written to ``output`` in bounded memory: the object rows held in a
    :class:`~aveas_format.io.resort.StatesWriter` (spilled next to the output beyond its memory),
    the states made and written a bucket of whole tracks at a time (``convert`` of one recording,
    ``validate FILE``): the same recording as :func:`convert_ros2_mcap`."""
    with bounded_states(output, overwrite, key="track", memory=object_rows.MEMORY) as w:
        ctx = _recording(inputs, map_source, options, w)
        return write_by_buckets(w, partial(_bucket, ctx=ctx), ctx.sensor, None, output=output,
                                overwrite=overwrite, converter="ros2-mcap", inputs=inputs,
                                options=options, map_bytes=ctx.map_bytes,
                                participants=partial(_finish, ctx=ctx), key_map=ctx.key_map)


@converter("ros2-mcap", description="ROS 2 MCAP of a road vehicle: Autoware/derived_object_msgs/"
           "vision_msgs objects + Odometry/NavSatFix ego + /tf",
           patterns=("*.mcap",), method="road_vehicle", options=Ros2McapOptions,
           requires=("mcap", "mcap_ros2"), extra="ros2", provides=("start_time",),
           sniff=(b"ros2msg", b"ros2idl"), writes=convert_ros2_mcap_to)
def convert_ros2_mcap(inputs: list[Path], *, map_source, options: Ros2McapOptions):
    with StatesWriter(memory=None, key="track") as w:
        ctx = _recording(inputs, map_source, options, w)
        boxes, info = _bucket(next(w.buckets()), ctx)
    _, participants = _finish([info], ctx)  # (one bucket: the boxes have every source id)
    return to_recording(boxes, ctx.sensor, converter="ros2-mcap", inputs=inputs, options=options,
                        map_bytes=ctx.map_bytes, participants=participants)


def _recording(inputs: list[Path], map_source, o: Ros2McapOptions, writer: StatesWriter) -> SimpleNamespace:
    """The messages read (the object rows into ``writer``, the ego's states added as track 0)
    and what the import decides over all rows: the transform tree, the ego, the errors that name
    a message, the rows outside the transforms' time spans (a warning), time zero, the tracks'
    order (``key_map``: final code of each track code) and source ids, the sensor."""
    if o.ego_class not in CLASSES:
        raise FormatError(f"ego_class {o.ego_class!r} is not one of {list(CLASSES)}")
    types, obj_topics, odom, fix, sink, edges, ego_odom, ego_fix = read_topics(inputs, o, writer)
    map_bytes = load_map_bytes(map_source)
    tree = TransformTree(edges, o.map_frame, int(o.tf_tolerance_s * 1e9))
    first = inputs[0]

    ego = None
    if ego_odom["t"]:
        ego = _ego_from_odometry(ego_odom, odom, tree, o, first)
    elif ego_fix["t"]:
        ego = _ego_from_navsatfix(ego_fix, fix, tree, o, map_bytes)
    t_ns, fcode, track = sink.columns()
    valid = _valid(sink, t_ns, fcode, obj_topics, tree, ego, o, first)
    stamps = [a for a in (t_ns[valid], None if ego is None else ego["t"]) if a is not None and len(a)]
    if not stamps:
        raise FormatError("no samples: the object topics are empty and there is no ego pose",
                          path=first)
    t0 = int(min(int(a.min()) for a in stamps))
    # the tracks in the order of their first valid row (0: the ego; without a valid row: last)
    u, fi = np.unique(track[valid], return_index=True)
    by_first = u[np.argsort(fi, kind="stable")]
    key_map = np.full(len(sink.keys) + 1, len(u) + 1, np.int64)
    key_map[0] = 0
    key_map[by_first] = np.arange(1, len(u) + 1)
    del t_ns, fcode, track, valid
    if ego is not None:  # participant 0
        e = _ego_states(ego, o)
        e["time"] = (e.pop("t_ns") - t0) / 1e9
        e.pop("participant_id")
        writer.add({"track": np.zeros(len(e["time"]), np.int64), **e})
    sensor = Sensor(method="road_vehicle", start_time=utc_iso_from_ns(t0),
                    platform="road vehicle (ROS 2)", sensors=_sensors(ego, obj_topics, types, o))
    return SimpleNamespace(options=o, tree=tree, ego=ego, frames=sink.frames, first=first, t0=t0,
                           key_map=key_map, source_ids=np.asarray(sink.keys, dtype=object)[by_first - 1],
                           map_bytes=map_bytes, sensor=sensor, next_id=int(ego is not None), found=[])


def _valid(sink, t_ns: np.ndarray, fcode: np.ndarray, obj_topics: list[str], tree: TransformTree,
           ego: dict[str, Any] | None, o: Ros2McapOptions, first: Path) -> np.ndarray:
    """Whether each object row has a transform to the map frame at its stamp; a non-finite pose
    or a frame without transform is an error naming its first message; the rows without a
    warning with their count."""
    if sink.bad is not None:
        ti, mi, oi = sink.bad
        raise FormatError(f"topic {obj_topics[ti]} message {mi}: object {oi}: pose is "
                          "not finite", path=first)
    valid = np.ones(len(t_ns), bool)
    for fr in sorted(sink.frames):
        k = sink.frame_of[fr]
        frn = fr.lstrip("/") or o.map_frame
        if not tree.reaches(frn, o.map_frame):
            ti, mi = sink.frame_first[k]
            raise FormatError(
                f"topic {obj_topics[ti]} message {mi}: frame {fr!r} has no transform to "
                f"{o.map_frame!r} (needs /tf, an odometry with child frame {fr!r} or a NavSatFix "
                f"ego with base_frame={fr!r})", path=first)
        sel = np.flatnonzero(fcode == k)
        valid[sel] = tree.valid(frn, t_ns[sel])
    if len(t_ns):
        if not valid.all():
            warnings.warn(f"{int((~valid).sum())} object samples lie outside the transforms' time "
                          f"span (+- {o.tf_tolerance_s} s) and are dropped", stacklevel=4)
        if not valid.any() and ego is None:
            raise FormatError("no object sample has a transform to the map frame", path=first)
    return valid


#: the ego's states columns as :func:`_ego_states` makes them (then ``time``)
_EGO = ("x", "y", "heading", "vx", "vy", "x_std", "y_std", "xy_corr", "heading_std", "vx_std",
        "vy_std", "vxvy_corr")


def _bucket(bucket: pa.Table, ctx: SimpleNamespace) -> tuple[Boxes, dict[str, Any]]:
    """The boxes of a bucket of whole tracks (the ego's too in the first), their participant ids
    final (the buckets made in order, one at a time), and what the bucket found (``info``: its
    participants' source ids and per-object aggregates, repeats, skipped tracks, an error)."""
    b = bucket.combine_chunks()
    is_ego = b.column("track").to_numpy() == 0
    parts: list[dict[str, Any]] = []
    info: dict[str, Any] = {"source_ids": [], "repeats": [], "skipped": 0, "labels": Counter(),
                            "objects": None, "error": None}
    if is_ego.any():
        eg = b.filter(pa.array(is_ego))
        parts.append({"participant_id": np.zeros(eg.num_rows, np.int64),
                      **{k: column_numpy(eg, k) for k in _EGO}, "time": column_numpy(eg, "time")})
        info["source_ids"].append("ego")
        b = b.filter(pa.array(~is_ego))
    rows = objects_in_map(b, ctx) if b.num_rows else {}
    if rows and len(rows["t_ns"]):
        obj = object_boxes(rows, ctx, info)
        parts.append({k: v for k, v in obj.columns.items() if k not in MEASURED}
                     | {"participant_id": obj.pid + ctx.next_id, "time": obj.time})
        ctx.next_id += obj.m
        info["source_ids"] += list(obj.source_ids)
        if obj.m:
            try:
                info["objects"] = participant_columns(obj, Sizes(), None)
            except FormatError as e:  # (raised after the warnings, as by the import in memory)
                info["error"] = e
    if not parts:  # (tracks without a valid row only)
        parts.append({"participant_id": np.zeros(0, np.int64), "time": np.zeros(0),
                      **{k: np.zeros(0) for k in _EGO}})
    cols = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in parts[0]}
    boxes = Boxes(cols.pop("participant_id"), cols.pop("time"), cols.pop("x"), cols.pop("y"),
                  source_ids=info["source_ids"], rows=Rows([ctx.first]), **cols)
    return boxes, info


def _finish(infos: list[dict[str, Any]], ctx: SimpleNamespace) -> tuple[list[str], dict[str, Any]]:
    """After the last bucket: the warnings of the repeats and of the tracks that are no road
    user (one each, with the counts over all buckets), an error of a bucket (a track without a
    positive length, then width), and the participants' source ids and columns."""
    repeats = [r for i in infos for r in i["repeats"]]
    if repeats:
        _, path, who, t = repeats[0]
        warnings.warn(repeat_message(sum(r[0] for r in repeats), path, who, t), stacklevel=3)
    skipped = sum(i["skipped"] for i in infos)
    if skipped:
        warnings.warn(skipped_message(skipped, sum((i["labels"] for i in infos), Counter())),
                      stacklevel=3)
    errors = [i["error"] for i in infos if i["error"] is not None]
    if errors:  # (the in-memory import checks every track's length before any width)
        raise min(errors, key=lambda e: "positive length" not in str(e))
    source_ids = [s for i in infos for s in i["source_ids"]]
    objects = [i["objects"] for i in infos if i["objects"] is not None]
    return source_ids, _participants(ctx.ego, objects, ctx.options)


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


# --- participants and sensors ----------------------------------------------------------------------

def _participants(ego: dict[str, Any] | None, objects: list[dict[str, Any]], o: Ros2McapOptions
                  ) -> dict[str, Any]:
    """The participants' columns: the ego (from the options) first, then the objects (their
    boxes' mean dimensions with their spread, mean class PMF: ``objects``, the
    :func:`~aveas_format.converters.common.assemble.participant_columns` of each bucket's boxes)."""
    n_ego = int(ego is not None)
    nobj = sum(len(p["class_pmf"]) for p in objects)
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
    at = n_ego
    for p in objects:
        m = len(p["class_pmf"])
        pmf_all[at:at + m] = p["class_pmf"]
        for a, k in ((length, "length"), (width, "width"), (height, "height"), (lstd, "length_std"),
                     (wstd, "width_std"), (hstd, "height_std")):
            a[at:at + m] = np.asarray(p[k].to_numpy(zero_copy_only=False) if hasattr(p[k], "to_numpy")
                                      else p[k], np.float64)
        at += m
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
