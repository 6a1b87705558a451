"""ROS 2 recordings of a road vehicle in MCAP (rosbag2's default storage) -> recording.

Reads the MCAP files with ``mcap`` and decodes the CDR messages with ``rosbags``' generated
deserialisers (``mcap-ros2-support``'s generic decoder for schemas rosbags does not parse); no ROS
installation: the message definitions travel in the file. Several input files are read as one
recording.

Objects (the observed participants), from every topic of these types (or ``object_topics``):

- ``autoware_perception_msgs/msg/TrackedObjects``: pose and twist **with covariance**, the
  classification list (label + probability -> class PMF), shape dimensions (bounding box;
  cylinder: diameter x diameter; polygon: the footprint's extent), the 16-byte UUID as source id.
  The twist is in the object's own frame (Autoware's convention). ``orientation_availability``
  UNAVAILABLE: heading from the direction of motion; SIGN_UNKNOWN: flipped where it opposes the
  motion.
- ``derived_object_msgs/msg/ObjectWithCovarianceArray``: pose/twist with covariance (twist in the
  header frame), ``shape`` BOX/CYLINDER/SPHERE dimensions, ``classification`` with
  ``classification_certainty`` (0..255; 0 = not set = certain) -> PMF: the certainty on the class,
  the rest spread evenly over all 13 classes.
- ``vision_msgs/msg/Detection3DArray``: ``bbox`` centre and size, the hypotheses' ``class_id``/
  ``score`` -> PMF (``class_map`` maps ids; names such as car, person, bicycle are known), the
  best hypothesis' pose covariance, ``id`` as track id (an empty id: one participant per
  detection). No twist: velocity from positions.

Class mapping: Autoware CAR/TRUCK/BUS/TRAILER/MOTORCYCLE/BICYCLE/PEDESTRIAN/ANIMAL -> the class of
that name, UNKNOWN/HAZARD/OVER_DRIVABLE/UNDER_DRIVABLE -> other; derived_object_msgs PEDESTRIAN ->
pedestrian, BIKE -> bicycle, CAR -> car, TRUCK -> truck, MOTORCYCLE -> motorcycle, the rest ->
other. A participant's ``class_pmf`` is the mean of its per-message PMFs; length/width/height the
mean of its dimensions, ``*_std`` their spread.

Ego (the recording vehicle, a participant with role ``recording_vehicle``): ``nav_msgs/msg/
Odometry`` (pose with covariance of ``child_frame_id`` in ``header.frame_id``, twist in the child
frame) and/or ``sensor_msgs/msg/NavSatFix`` (lon/lat projected through the map's CRS, the ENU
``position_covariance``; heading from the direction of motion). Its footprint centre lies
``ego_center_offset`` m ahead of ``base_frame`` (Autoware's base_link is the rear-axle centre).

Frames: every pose is transformed into ``map_frame`` through the transform tree of ``/tf`` and
``/tf_static`` (``tf2_msgs/msg/TFMessage``), the odometry (``header.frame_id`` ->
``child_frame_id``) and, without both, the NavSatFix ego track (map -> base_frame); dynamic
transforms are interpolated (linear, slerp) at each message's stamp. ``frame_offset`` = (x, y, yaw)
places ``map_frame`` in the OpenDRIVE map's local frame.

Uncertainty: the 6x6 covariances are reduced to (x, y, yaw) and (vx, vy, yaw rate) and propagated
with the full Jacobian of the frame change: ``C' = J_obj C J_obj^T + J_frame C_frame J_frame^T``,
where the frame's pose covariance is the ego odometry's (for objects in the vehicle's frames);
the twist covariance is rotated into the local frame with the heading's variance added through
the rotation's derivative. All-zero covariances mean "unknown" (null ``_std``). Velocity from a
twist in the header frame is absolute unless ``relative_velocity`` (then the ego velocity and
``omega x r`` are added).

Time: ``header.stamp`` (not the log time; a zero stamp falls back to the log time with a
warning); time zero = the earliest stamp, which also gives ``start_time``. Decoding is per
message; everything after it is vectorised per frame. Duplicate (participant, stamp) samples keep
the first. Provenance ``natural``, role ``observed`` for objects.
"""

from __future__ import annotations

import json
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.converters.common import (
    class_of,
    covariance_std_corr,
    factorize,
    group_mean,
    group_std,
    load_map_bytes,
    matrix_yaw,
    nullable,
    quaternion_matrix,
    rotation_2d,
    utc_iso_from_ns,
    velocity_with_std,
    wrap_recording,
)
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.safeio import check_mcap
from aveas_format.schema.taxonomy import CLASSES

CLS = {c: i for i, c in enumerate(CLASSES)}
NCLS = len(CLASSES)

AUTOWARE_LABELS = {0: "other", 1: "car", 2: "truck", 3: "bus", 4: "trailer", 5: "motorcycle",
                   6: "bicycle", 7: "pedestrian", 8: "animal", 9: "other", 10: "other", 11: "other"}
DERIVED_LABELS = {4: "pedestrian", 5: "bicycle", 6: "car", 7: "truck", 8: "motorcycle"}

T_TRACKED = "autoware_perception_msgs/msg/TrackedObjects"
T_DERIVED = "derived_object_msgs/msg/ObjectWithCovarianceArray"
T_DET3D = "vision_msgs/msg/Detection3DArray"
T_ODOM = "nav_msgs/msg/Odometry"
T_FIX = "sensor_msgs/msg/NavSatFix"
T_TF = "tf2_msgs/msg/TFMessage"
OBJECT_TYPES = (T_TRACKED, T_DERIVED, T_DET3D)
PREFERRED_ODOM = ("/localization/kinematic_state", "/odom", "/odometry")
PREFERRED_FIX = ("/sensing/gnss/ublox/nav_sat_fix", "/fix", "/gps/fix", "/gnss/fix")

# 3x3 sub-blocks (x, y, yaw) of a row-major 6x6 covariance and (vx, vy, wz) of a twist covariance
_SUB = np.array([0, 1, 5, 6, 7, 11, 30, 31, 35])


def _canon(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    parts = type_name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else type_name


class Ros2McapOptions(ImportOptions):
    object_topics: list[str] | None = None
    """Object topics to read (default: every topic of a supported object type)."""
    odometry_topic: str | None = None
    """nav_msgs/Odometry topic of the ego (default: the only one, or /localization/kinematic_state,
    /odom); "" = none."""
    navsatfix_topic: str | None = None
    """sensor_msgs/NavSatFix topic of the ego (default: the only one); "" = none."""
    tf_topics: list[str] = ["/tf", "/tf_static"]
    """tf2_msgs/TFMessage topics (the second-named and any /tf_static are static)."""
    map_frame: str = "map"
    """The fixed frame every pose is transformed into."""
    base_frame: str = "base_link"
    """The ego vehicle's frame."""
    frame_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose (x, y, yaw in rad) of map_frame in the OpenDRIVE map's local frame."""
    ego_length: float = 4.9
    """Recording vehicle length (m)."""
    ego_width: float = 1.9
    """Recording vehicle width (m)."""
    ego_height: float = 1.6
    """Recording vehicle height (m)."""
    ego_class: str = "car"
    """Class of the recording vehicle."""
    ego_center_offset: float = 0.0
    """Distance (m, forward) from base_frame to the ego's footprint centre."""
    relative_velocity: bool = False
    """Twists given in the header frame are relative to the moving ego (derived_object_msgs)."""
    class_map: dict[str, str] = {}
    """vision_msgs class_id -> class (one of the 13), for ids that are not class names."""
    min_existence_probability: float = 0.0
    """Drop Autoware objects below this existence probability."""
    object_sensor_kind: str = "lidar"
    """acquisition.sensors kind recorded for the object topics."""
    tf_tolerance_s: float = 0.2
    """How far (s) beyond a dynamic transform's samples a stamp may lie; objects further out are
    dropped with a warning."""


# --- reading ---------------------------------------------------------------------------------------

@dataclass
class _Objects:
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
    orient: list[int] = field(default_factory=list)      # Autoware orientation_availability
    where: list[tuple[int, int]] = field(default_factory=list)  # (message index, object index)


@dataclass
class _Edges:
    """Transform samples: child -> (parent, t_ns, translation, quaternion, static, source)."""

    data: dict[str, dict[str, Any]] = field(default_factory=dict)

    def add(self, parent: str, child: str, t_ns: int, tr: tuple, q: tuple, static: bool,
            source: str) -> None:
        e = self.data.setdefault(child, {"parent": parent, "t": [], "tr": [], "q": [],
                                         "static": static, "source": source})
        if e["parent"] != parent:
            return  # a frame has one parent; later conflicting edges are ignored
        e["t"].append(t_ns)
        e["tr"].append(tr)
        e["q"].append(q)


def _stamp(header, log_time: int) -> tuple[int, bool]:
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


def _read_tracked(msg, objs: _Objects, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
    frame = msg.header.frame_id
    for oi, o in enumerate(msg.objects):
        if o.existence_probability < opts.min_existence_probability:
            continue
        k = o.kinematics
        pmf = np.zeros(NCLS)
        for c in o.classification:
            pmf[CLS[AUTOWARE_LABELS.get(int(c.label), "other")]] += max(float(c.probability), 0.0)
        if pmf.sum() <= 0:
            pmf[CLS["other"]] = 1.0
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


def _read_derived(msg, objs: _Objects, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
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


def _read_det3d(msg, objs: _Objects, t_ns: int, ti: int, mi: int, opts: Ros2McapOptions) -> None:
    for oi, d in enumerate(msg.detections):
        frame = d.header.frame_id or msg.header.frame_id
        pmf = np.zeros(NCLS)
        best, best_score = None, -np.inf
        for h in d.results:
            s = float(h.hypothesis.score)
            pmf[CLS[class_of(h.hypothesis.class_id, opts.class_map)]] += max(s, 0.0)
            if s > best_score:
                best, best_score = h, s
        if pmf.sum() <= 0:
            pmf[CLS["other"]] = 1.0
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


_READERS = {T_TRACKED: _read_tracked, T_DERIVED: _read_derived, T_DET3D: _read_det3d}


def _mcap_errors() -> tuple[type[BaseException], ...]:
    """What a corrupt MCAP file raises from the reader: record-level errors, a damaged record
    length (OverflowError) and, from a damaged compressed chunk, the decompressors' own
    (zstandard.ZstdError; lz4 raises RuntimeError). Lengths beyond the file and oversized chunks
    are refused before the reader runs (``safeio.check_mcap``); MemoryError stays listed only as a
    last resort."""
    from mcap.exceptions import McapError

    errs: list[type[BaseException]] = [McapError, ValueError, EOFError, KeyError, OSError,
                                       struct.error, IndexError, RuntimeError, OverflowError,
                                       MemoryError]
    try:
        import zstandard

        errs.append(zstandard.ZstdError)
    except ImportError:  # pragma: no cover - mcap depends on it
        pass
    return tuple(errs)


def _why(e: BaseException) -> str:
    if isinstance(e, MemoryError) and not str(e):
        return "MemoryError: a record's length field is implausibly large"
    return f"{type(e).__name__}: {e}"


def _channels(path: Path) -> dict[str, str]:
    """topic -> canonical message type of an MCAP file (from its summary, else a scan)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None:
                return {ch.topic: _canon(summary.schemas[ch.schema_id].name)
                        for ch in summary.channels.values() if ch.schema_id in summary.schemas}
            out = {}
            for schema, ch, _ in reader.iter_messages(log_time_order=False):
                if schema is not None:
                    out.setdefault(ch.topic, _canon(schema.name))
            return out
    except _mcap_errors() as e:
        raise FormatError(f"not a readable MCAP file: {_why(e)}", path=path) from None


def _pick(types: dict[str, str], wanted: str, given: str | None, preferred: tuple[str, ...],
          path: Path, what: str) -> str | None:
    if given == "":
        return None
    if given is not None:
        if given not in types:
            raise FormatError(f"{what} topic {given!r} not in the file; topics: {sorted(types)}",
                              path=path)
        if types[given] != wanted:
            raise FormatError(f"topic {given!r} has type {types[given]}, expected {wanted}", path=path)
        return given
    cands = sorted(t for t, ty in types.items() if ty == wanted)
    if len(cands) == 1:
        return cands[0]
    for p in preferred:
        if p in cands:
            return p
    return cands[0] if cands else None


class _Decoders:
    """CDR decoding, one decoder per schema: rosbags' deserialisers, generated for each message
    type (3-4x faster than mcap_ros2's generic decoder on TrackedObjects), and mcap_ros2's decoder
    for schemas rosbags does not parse (e.g. ``ros2idl``). One type store per schema, so two files
    with different definitions of one type name do not clash."""

    def __init__(self) -> None:
        from mcap_ros2.decoder import DecoderFactory

        self._fallback = DecoderFactory()
        self._by_schema: dict[tuple[int, str], Any] = {}

    def decoder(self, schema, encoding: str):
        key = (schema.id, schema.name)
        fn = self._by_schema.get(key)
        if fn is None:
            fn = self._by_schema[key] = self._make(schema, encoding)
        return fn

    def _make(self, schema, encoding: str):
        if encoding != "cdr":
            raise ValueError(f"unsupported message encoding {encoding!r}")
        if schema.encoding == "ros2msg":
            try:
                return self._rosbags(schema)
            except Exception:  # noqa: BLE001 - rosbags cannot parse it: the generic decoder tries
                pass
        decode = self._fallback.decoder_for(encoding, schema)
        if decode is None:
            raise ValueError(f"unsupported schema encoding {schema.encoding!r}")
        return decode

    @staticmethod
    def _rosbags(schema):
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg

        text = schema.data.decode("utf-8")
        parts = re.split(r"^={10,}\s*$\n?", text, flags=re.MULTILINE)
        types = dict(get_types_from_msg(parts[0], schema.name))
        for part in parts[1:]:
            head, _, body = part.strip("\n").partition("\n")
            if not head.startswith("MSG:"):
                raise ValueError(f"schema part without a MSG: header: {head[:60]!r}")
            types.update(get_types_from_msg(body, head[4:].strip()))
        store = get_typestore(Stores.EMPTY)
        store.register(types)
        name = schema.name
        return lambda data: store.deserialize_cdr(data, name)


def _read(paths: list[Path], opts: Ros2McapOptions):
    from mcap.reader import make_reader

    types: dict[str, str] = {}
    for p in paths:
        if not p.is_file():
            raise RecordingIOError("input not found", path=p)
        check_mcap(p)  # bounded pre-scan: no record or chunk may claim more than the file holds
        types.update(_channels(p))
    first = paths[0]
    if opts.object_topics is not None:
        for t in opts.object_topics:
            if t not in types:
                raise FormatError(f"object topic {t!r} not in the file; topics: {sorted(types)}",
                                  path=first)
            if types[t] not in OBJECT_TYPES:
                raise FormatError(f"topic {t!r} has type {types[t]}; supported object types: "
                                  f"{', '.join(OBJECT_TYPES)}", path=first)
        obj_topics = list(opts.object_topics)
    else:
        obj_topics = sorted(t for t, ty in types.items() if ty in OBJECT_TYPES)
    odom = _pick(types, T_ODOM, opts.odometry_topic, PREFERRED_ODOM, first, "odometry")
    fix = _pick(types, T_FIX, opts.navsatfix_topic, PREFERRED_FIX, first, "NavSatFix")
    tf_topics = [t for t in opts.tf_topics if types.get(t) == T_TF]
    if not obj_topics and odom is None and fix is None:
        raise FormatError("no object, odometry or NavSatFix topics found; topics: "
                          f"{ {t: ty for t, ty in sorted(types.items())} }", path=first)
    topic_index = {t: i for i, t in enumerate(obj_topics)}
    wanted = set(obj_topics) | set(tf_topics) | {t for t in (odom, fix) if t}

    objs = _Objects()
    edges = _Edges()
    ego_odom: dict[str, list] = {"t": [], "pose": [], "pcov": [], "twist": [], "tcov": [],
                                 "frame": [], "child": []}
    ego_fix: dict[str, list] = {"t": [], "lonlat": [], "cov": []}
    counters: dict[str, int] = {}
    zero_stamps = 0
    for path in paths:
        factory = _Decoders()
        try:
            f = open(path, "rb")
        except OSError as e:
            raise RecordingIOError(f"cannot read: {e.strerror}", path=path) from None
        with f:
            reader = make_reader(f)
            it = reader.iter_messages(topics=sorted(wanted & set(_channels(path))))
            while True:
                try:
                    schema, ch, m = next(it)
                except StopIteration:
                    break
                except _mcap_errors() as e:
                    raise FormatError(f"corrupt MCAP after {sum(counters.values())} messages: "
                                      f"{_why(e)}", path=path) from None
                topic = ch.topic
                mi = counters.get(topic, 0)
                counters[topic] = mi + 1
                where = f"topic {topic} message {mi}"
                try:
                    msg = factory.decoder(schema, ch.message_encoding)(m.data)
                except Exception as e:  # noqa: BLE001 - the decoder raises many kinds
                    raise FormatError(f"{where}: cannot decode: {type(e).__name__}: {e}",
                                      path=path) from None
                ty = _canon(schema.name)
                try:
                    if ty in _READERS and topic in topic_index:
                        t_ns, ok = _stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        _READERS[ty](msg, objs, t_ns, topic_index[topic], mi, opts)
                    elif ty == T_TF:
                        static = topic.endswith("tf_static")
                        for tr in msg.transforms:
                            t_ns, ok = _stamp(tr.header, m.log_time)
                            q = tr.transform.rotation
                            edges.add(tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"),
                                      t_ns, _vec(tr.transform.translation), (q.x, q.y, q.z, q.w),
                                      static, topic)
                    elif ty == T_ODOM and topic == odom:
                        t_ns, ok = _stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        ego_odom["t"].append(t_ns)
                        ego_odom["pose"].append(_pose7(msg.pose.pose))
                        ego_odom["pcov"].append(_sub9(msg.pose.covariance))
                        tw = msg.twist.twist
                        ego_odom["twist"].append((tw.linear.x, tw.linear.y, tw.angular.z))
                        ego_odom["tcov"].append(_sub9(msg.twist.covariance))
                        ego_odom["frame"].append(msg.header.frame_id.lstrip("/"))
                        ego_odom["child"].append(msg.child_frame_id.lstrip("/"))
                    elif ty == T_FIX and topic == fix:
                        if int(msg.status.status) < 0:  # no fix
                            continue
                        t_ns, ok = _stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        ego_fix["t"].append(t_ns)
                        ego_fix["lonlat"].append((msg.longitude, msg.latitude))
                        c = list(msg.position_covariance)
                        known = int(msg.position_covariance_type) > 0 and len(c) == 9
                        ego_fix["cov"].append((c[0], c[1], c[3], c[4]) if known else (np.nan,) * 4)
                except (AttributeError, TypeError, ValueError, IndexError) as e:
                    raise FormatError(f"{where}: malformed {ty}: {e}", path=path) from None
    if zero_stamps:
        warnings.warn(f"{zero_stamps} messages have a zero header.stamp; their log time is used",
                      stacklevel=3)
    return types, obj_topics, odom, fix, objs, edges, ego_odom, ego_fix


# --- transform tree --------------------------------------------------------------------------------

class _Tree:
    def __init__(self, edges: _Edges, map_frame: str, tol_ns: int):
        self.map = map_frame
        self.tol = tol_ns
        self.e: dict[str, dict[str, Any]] = {}
        for child, d in edges.data.items():
            t = np.asarray(d["t"], np.int64)
            order = np.argsort(t, kind="stable")
            t = t[order]
            keep = np.r_[True, np.diff(t) > 0]
            self.e[child] = {"parent": d["parent"], "t": t[keep],
                             "tr": np.asarray(d["tr"], np.float64)[order][keep],
                             "q": np.asarray(d["q"], np.float64)[order][keep],
                             "static": d["static"] or keep.sum() == 1, "source": d["source"],
                             "cov": None}

    def add(self, parent: str, child: str, t: np.ndarray, tr: np.ndarray, q: np.ndarray,
            cov: np.ndarray | None, source: str) -> None:
        self.e[child] = {"parent": parent, "t": t, "tr": tr, "q": q, "static": False,
                         "source": source, "cov": cov}

    def reaches(self, frame: str, target: str) -> bool:
        for _ in range(64):
            if frame == target:
                return True
            if frame not in self.e:
                return False
            frame = self.e[frame]["parent"]
        return False

    def _edge_at(self, e: dict[str, Any], t: np.ndarray):
        from scipy.spatial.transform import Rotation, Slerp

        m = len(t)
        if e["static"] or len(e["t"]) == 1:
            r = np.repeat(quaternion_matrix(e["q"][-1:]), m, axis=0)
            return r, np.repeat(e["tr"][-1:], m, axis=0), np.ones(m, bool), None
        te = e["t"]
        ok = (t >= te[0] - self.tol) & (t <= te[-1] + self.tol)
        tc = np.clip(t, te[0], te[-1])
        base = te[0]
        tf = (tc - base).astype(np.float64)
        tef = (te - base).astype(np.float64)
        tr = np.stack([np.interp(tf, tef, e["tr"][:, k]) for k in range(3)], -1)
        # within the tolerance beyond the ends: extrapolate the translation linearly
        tq = (t - base).astype(np.float64)
        lo, hi = tq < tef[0], tq > tef[-1]
        if len(tef) > 1 and (lo.any() or hi.any()):
            s0 = (e["tr"][1] - e["tr"][0]) / (tef[1] - tef[0])
            s1 = (e["tr"][-1] - e["tr"][-2]) / (tef[-1] - tef[-2])
            tr[lo] += np.outer(tq[lo] - tef[0], s0)
            tr[hi] += np.outer(tq[hi] - tef[-1], s1)
        rot = Slerp(tef, Rotation.from_quat(e["q"]))(tf)
        cov = None
        if e["cov"] is not None:
            cov = np.stack([np.interp(tf, tef, e["cov"][:, k]) for k in range(9)], -1).reshape(m, 3, 3)
        return rot.as_matrix(), tr, ok, cov

    def lookup(self, frame: str, t: np.ndarray, want_cov: bool = True):
        """Pose of ``frame`` in the map frame at ``t``: R (m,3,3), p (m,3), ok (m,) (inside the
        dynamic transforms' time spans), and the (x, y, yaw) pose covariance (m,3,3) of the
        uncertain frame in the chain (the ego) with that frame's origin in map (m,3), or None."""
        m = len(t)
        r_acc = np.repeat(np.eye(3)[None], m, axis=0)
        p_acc = np.zeros((m, 3))
        ok = np.ones(m, bool)
        cov_acc = None
        cov_child = None
        cur = frame
        for _ in range(64):
            if cur == self.map:
                if cov_acc is None or not want_cov:
                    return r_acc, p_acc, ok, None
                origin = p_acc if cov_child == frame else self.lookup(cov_child, t, False)[1]
                return r_acc, p_acc, ok, (cov_acc, origin)
            e = self.e[cur]
            r, p, ok_e, cov = self._edge_at(e, t)
            ok &= ok_e
            if cov_acc is not None:  # expressed in cur: rotate into the parent
                r2 = rotation_2d(matrix_yaw(r))
                cov_acc = cov_acc.copy()
                cov_acc[:, :2, :2] = np.einsum("nij,njk,nlk->nil", r2, cov_acc[:, :2, :2], r2)
            if want_cov and cov is not None and cov_acc is None:
                cov_acc, cov_child = np.nan_to_num(cov), cur
            r_acc = np.einsum("nij,njk->nik", r, r_acc)
            p_acc = np.einsum("nij,nj->ni", r, p_acc) + p
            cur = e["parent"]
        raise FormatError(f"transform chain of frame {frame!r} is too deep or cyclic")


# --- math ------------------------------------------------------------------------------------------

def _cov3(flat: np.ndarray) -> np.ndarray:
    c = np.asarray(flat, np.float64).reshape(-1, 3, 3)
    unknown = np.all(c == 0, axis=(1, 2)) | (c[:, 0, 0] < 0)  # all zero / -1: unknown (ROS custom)
    c = c.copy()
    c[unknown] = np.nan
    return c


def _to_map(r_f: np.ndarray, p_f: np.ndarray, cov_f, pose: np.ndarray, pcov: np.ndarray):
    """Object poses in a frame -> map: position, heading, (x, y, yaw) covariance (n,3,3)."""
    pos = np.einsum("nij,nj->ni", r_f, pose[:, :3]) + p_f
    r_obj = np.einsum("nij,njk->nik", r_f, quaternion_matrix(pose[:, 3:]))
    heading = matrix_yaw(r_obj)
    th = matrix_yaw(r_f)
    c, s = np.cos(th), np.sin(th)
    n = len(th)
    j_obj = np.zeros((n, 3, 3))
    j_obj[:, 0, 0], j_obj[:, 0, 1], j_obj[:, 1, 0], j_obj[:, 1, 1] = c, -s, s, c
    j_obj[:, 2, 2] = 1.0
    cov = np.einsum("nij,njk,nlk->nil", j_obj, pcov, j_obj)
    if cov_f is not None:
        # the uncertain frame (the ego) at ``origin`` with pose covariance (x, y, yaw) in map:
        # d pos / d yaw = the lever arm from its origin rotated by 90 degrees
        fcov, origin = cov_f
        lever = pos[:, :2] - origin[:, :2]
        j_f = np.zeros((n, 3, 3))
        j_f[:, 0, 0] = j_f[:, 1, 1] = j_f[:, 2, 2] = 1.0
        j_f[:, 0, 2] = -lever[:, 1]
        j_f[:, 1, 2] = lever[:, 0]
        cov = cov + np.einsum("nij,njk,nlk->nil", j_f, fcov, j_f)
    return pos, heading, cov, th


def _twist_to_map(angle: np.ndarray, twist: np.ndarray, tcov: np.ndarray, var_angle: np.ndarray):
    """Rotate (vx, vy) by ``angle``; covariance R V R^T + g var(angle) g^T."""
    r = rotation_2d(angle)
    v = np.einsum("nij,nj->ni", r, twist[:, :2])
    cov = np.einsum("nij,njk,nlk->nil", r, tcov[:, :2, :2], r)
    g = np.stack([-v[:, 1], v[:, 0]], -1)  # d(R v)/d angle
    cov = cov + np.nan_to_num(var_angle)[:, None, None] * np.einsum("ni,nj->nij", g, g)
    return v, cov


def _apply_offset(offset, x, y, heading, cov_xy, vx, vy, cov_v):
    ox, oy, oyaw = offset
    if oyaw:
        c, s = np.cos(oyaw), np.sin(oyaw)
        x, y = c * x - s * y, s * x + c * y
        vx, vy = c * vx - s * vy, s * vx + c * vy
        r = rotation_2d(np.full(len(x), oyaw))
        cov_xy = np.einsum("nij,njk,nlk->nil", r, cov_xy, r)
        cov_v = np.einsum("nij,njk,nlk->nil", r, cov_v, r)
        heading = heading + oyaw
    return x + ox, y + oy, np.angle(np.exp(1j * heading)), cov_xy, vx, vy, cov_v


# --- the converter ---------------------------------------------------------------------------------

@converter("ros2-mcap", description="ROS 2 MCAP of a road vehicle: Autoware/derived_object_msgs/"
           "vision_msgs objects + Odometry/NavSatFix ego + /tf",
           patterns=("*.mcap",), method="road_vehicle", options=Ros2McapOptions)
def convert_ros2_mcap(inputs: list[Path], *, map_source, options: Ros2McapOptions):
    o = options
    if o.ego_class not in CLASSES:
        raise FormatError(f"ego_class {o.ego_class!r} is not one of {list(CLASSES)}")
    types, obj_topics, odom, fix, objs, edges, ego_odom, ego_fix = _read(inputs, o)
    map_bytes = load_map_bytes(map_source)
    tree = _Tree(edges, o.map_frame, int(o.tf_tolerance_s * 1e9))
    first = inputs[0]

    # --- ego track ---------------------------------------------------------------------------------
    ego = None
    if ego_odom["t"]:
        t = np.asarray(ego_odom["t"], np.int64)
        order = np.argsort(t, kind="stable")
        keep = np.r_[True, np.diff(t[order]) > 0]
        order = order[keep]
        t = t[order]
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
        ego = {"t": t, "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2], "heading": heading,
               "cov": cov, "v": v, "vcov": vcov, "yaw_rate": twist[:, 2],
               "yaw_rate_var": tcov[:, 2, 2], "source": odom, "frame": child}
    elif ego_fix["t"]:
        from aveas_format.mapref.crs import LocalFrame
        from aveas_format.opendrive import load_map

        net = load_map(map_bytes)
        if not net.header.geo_reference:
            raise FormatError("NavSatFix needs a map with a <geoReference> to project lon/lat")
        t = np.asarray(ego_fix["t"], np.int64)
        order = np.argsort(t, kind="stable")
        keep = np.r_[True, np.diff(t[order]) > 0]
        order = order[keep]
        t = t[order]
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
        vx, vy, vxs, vys = velocity_with_std(pid0, ts, mx, my, sx, sy)
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
        ego = {"t": t, "x": mx, "y": my, "z": None, "heading": heading, "cov": cov,
               "v": np.c_[vx, vy], "vcov": vcov, "yaw_rate": None, "yaw_rate_var": None,
               "source": fix, "frame": o.base_frame}

    # --- objects -----------------------------------------------------------------------------------
    n = len(objs.t_ns)
    rows: dict[str, np.ndarray] = {}
    if n:
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
                    tq = (t_ns[h] - ego["t"][0]).astype(np.float64)
                    te = (ego["t"] - ego["t"][0]).astype(np.float64)
                    evx = np.interp(tq, te, ego["v"][:, 0])
                    evy = np.interp(tq, te, ego["v"][:, 1])
                    w = np.interp(tq, te, ego["yaw_rate"]) if ego["yaw_rate"] is not None else 0.0
                    ex = np.interp(tq, te, ego["x"])
                    ey = np.interp(tq, te, ego["y"])
                    v = v + np.c_[evx - w * (y[h] - ey), evy + w * (x[h] - ex)]
                    vc = vc + np.nan_to_num(np.stack(
                        [np.interp(tq, te, ego["vcov"][:, a, b]) for a in range(2) for b in range(2)],
                        -1).reshape(-1, 2, 2))
                vel[h], vcov[h] = v, vc
        if not valid.all():
            warnings.warn(f"{int((~valid).sum())} object samples lie outside the transforms' time "
                          f"span (+- {o.tf_tolerance_s} s) and are dropped", stacklevel=2)
        keys = [f"{topic[i]}:{objs.oid[i]}" for i in range(n)] if len(obj_topics) > 1 else objs.oid
        rows = {"t_ns": t_ns, "key": np.asarray(keys, dtype=object), "x": x, "y": y, "z": z,
                "heading": heading, "cov": cov, "vel": vel, "vcov": vcov,
                "dims": np.asarray(objs.dims, np.float64), "pmf": np.asarray(objs.pmf),
                "orient": np.asarray(objs.orient), "valid": valid}
        rows = {k: v[valid] for k, v in rows.items()}
        if not len(rows["t_ns"]) and ego is None:
            raise FormatError("no object sample has a transform to the map frame", path=first)

    # --- time zero ---------------------------------------------------------------------------------
    stamps = [a for a in (rows.get("t_ns"), None if ego is None else ego["t"]) if a is not None and len(a)]
    if not stamps:
        raise FormatError("no samples: the object topics are empty and there is no ego pose",
                          path=first)
    t0 = int(min(int(a.min()) for a in stamps))

    # --- assemble states ---------------------------------------------------------------------------
    cols: dict[str, list[np.ndarray]] = {}

    def put(**kw):
        for k, v in kw.items():
            cols.setdefault(k, []).append(np.asarray(v))

    sources: list[str] = []
    n_ego = 0
    if ego is not None:
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
        put(participant_id=np.zeros(len(te), np.int64), t_ns=te, x=ex, y=ey, heading=eh, vx=evx,
            vy=evy, x_std=sx, y_std=sy, xy_corr=rho, heading_std=np.sqrt(ecov[:, 2, 2]),
            vx_std=vsx, vy_std=vsy, vxvy_corr=vrho)
        sources.append("ego")
        n_ego = 1
    p_extra: dict[str, np.ndarray] = {}
    if rows and len(rows["t_ns"]):
        codes, uniq = factorize(rows["key"])
        order = np.lexsort((rows["t_ns"], codes))
        r = {k: v[order] for k, v in rows.items()}
        codes = codes[order]
        dup = np.r_[False, (codes[1:] == codes[:-1]) & (r["t_ns"][1:] == r["t_ns"][:-1])]
        if dup.any():
            k = int(np.flatnonzero(dup)[0])
            warnings.warn(f"{first}: {int(dup.sum())} object sample(s) repeat a (track, stamp) and "
                          f"were dropped, the first kept (e.g. track {uniq[codes[k]]!r} at stamp "
                          f"{int(r['t_ns'][k])} ns)", stacklevel=2)
        r = {k: v[~dup] for k, v in r.items()}
        codes = codes[~dup]
        m = len(uniq)
        ts = (r["t_ns"] - t0) / 1e9
        # velocities where the source has none: from positions
        psx = np.sqrt(np.clip(r["cov"][:, 0, 0], 0, None))
        psy = np.sqrt(np.clip(r["cov"][:, 1, 1], 0, None))
        fvx, fvy, fvxs, fvys = velocity_with_std(codes, ts, r["x"], r["y"], psx, psy)
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
        put(participant_id=codes + n_ego, t_ns=r["t_ns"], x=x, y=y, heading=h, vx=vx, vy=vy,
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
        p_extra = {"source_id": list(uniq), "pmf": pmf, "sizes": sizes, "size_std": std_dims}
        sources.extend(uniq)

    states = {k: np.concatenate(v) for k, v in cols.items()}
    states["time"] = (states.pop("t_ns") - t0) / 1e9
    for k in ("x_std", "y_std", "xy_corr", "heading_std", "vx_std", "vy_std", "vxvy_corr"):
        states[k] = nullable(states[k])

    # --- participants ------------------------------------------------------------------------------
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
    sensors = []
    if ego is not None:
        sensors.append({"id": ego["source"], "kind": "gnss_imu",
                        "description": types.get(ego["source"], "")})
    for tp in obj_topics:
        sensors.append({"id": tp, "kind": o.object_sensor_kind, "description": types[tp],
                        "pose": {"frame": "platform"}})
    return wrap_recording(
        "ros2-mcap", inputs, options, map_bytes=map_bytes, participants=participants,
        states=states, method="road_vehicle", provenance="natural",
        start_time=utc_iso_from_ns(t0),
        acquisition={"platform": "road vehicle (ROS 2)", "sensors": sensors},
    )
