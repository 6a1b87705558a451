"""Pole-mounted (infrastructure) LiDAR tracks -> recording.

Inputs (mixed freely; the kind is recognised per file):

- **OpenLABEL** JSON (``{"openlabel": ...}``), one file per frame or one per sequence, as the TUM
  Traffic (A9) datasets write them: ``frames.<n>.objects.<uid>.object_data.cuboid.val`` =
  ``[x, y, z, qx, qy, qz, qw, l, w, h]`` (the box centre, its orientation and size in a sensor
  coordinate system; the 9-value Euler form ``[x, y, z, rx, ry, rz, l, w, h]`` is read too). Both
  the ASAM-conformant form (``cuboid`` a list, the object's ``type`` in the top-level ``objects``)
  and the TUM deviations (a single ``cuboid`` object, ``type`` inside ``object_data``) are
  accepted. The object uid is the track id. ``frame_properties.timestamp`` gives the time (its
  unit inferred as in the ``openlabel`` importer: seconds, ms, us or ns since the epoch, or since
  the start; ``timestamp_unit`` fixes it; recorded in the ``source`` block), else the frame
  number / ``rate_hz``. Tracks whose ``type`` is no road user (see "Labels that are not road
  users") are skipped with a count unless ``keep_non_road_users``; ignore types (DontCare) and
  boxes with sentinel sizes (<= 0, > 400 m) always, with a note. ``num_points`` and ``score`` attributes
  (``attributes.num`` of the cuboid or of object_data) feed the uncertainty and the class PMF.
- A plain **tracks table** (CSV/Parquet) of an in-house tracker: ``time`` (s) or ``frame``,
  ``track_id`` (or ``id``), ``class`` (or ``type``), ``x, y, z, yaw, length, width, height`` (or
  ``l, w, h``) in the sensor frame, optional ``num_points``, ``score``. ``z`` is the box centre
  (``z_reference="bottom"``: its bottom).
- A **sensor pose** JSON (any JSON without an ``openlabel`` key, or option ``sensor_pose``): a 4x4
  sensor-to-base matrix under any key (the TUM calibration files'
  ``transformation_matrix_<lidar>_to_<base>``), ``{"matrix4x4": [16 values]}``,
  ``{"translation": [x,y,z], "quaternion": [qx,qy,qz,qw]}`` or ``{"x","y","z","yaw","pitch","roll"}``.

Frames: a cuboid's coordinate system is its ``coordinate_system``, else option
``coordinate_system``, else the one sensor coordinate system with a ``pose_wrt_parent``. The
sensor-to-base transform is the sensor pose file if given, else the chain of ``pose_wrt_parent``
(OpenLABEL: the pose of a coordinate system in its parent, ``X_parent = P X_child``) and of each
frame's ``frame_properties.transforms`` up to the root. Where a frame's transforms move the
cuboids' coordinate system, the sensor moves: each frame's boxes go through that frame's
transform, and the unobserved regions (range, field of view, shadows) follow the sensor frame by
frame; a chain that ends in a ``geo_*`` root (a sensor on a vehicle in world coordinates, as in
the ASAM cuboid example) is refused with a message naming ``--from openlabel``; a sensor pose
file together with moving frames is refused too (it would fix the pose the frames move); ``frame_offset`` = (x, y, yaw) places that base frame in the OpenDRIVE map's local frame, whose
ground is at base z = 0. Reference point: the cuboid's centre projected to the ground
(``z = centre - h/2``); heading = yaw of the cuboid's x axis in the map.

Uncertainty model (documented; parameters are options). With r the horizontal distance from the
sensor and n the LiDAR points on the object (unknown: n = ``reference_points``),
``f = sqrt(max(1, reference_points / n))``:
the position error along the line of sight is ``sigma_r = (sigma0_m + range_coeff * r) f``, across
it ``sigma_t = (sigma0_m + angular_std_rad * r) f`` (beam divergence / angular resolution), rotated
into x/y by the bearing (-> ``x_std``, ``y_std``, ``xy_corr``); ``heading_std = heading_std_rad f``.
Velocity by central differences within a track, its std propagated from the position stds.
Dimensions: the mean over the track, std = the spread over the track, at least ``dimension_std_m``.
Class PMF: ``score`` (default 1) on the labelled class, the rest spread evenly over the 13
classes; TUM classes CAR, TRUCK, TRAILER, VAN, MOTORCYCLE, BUS, PEDESTRIAN, BICYCLE map to those
classes, EMERGENCY_VEHICLE to car, OTHER to other (``class_map`` adds names).

Unobserved regions: the map's extent outside the sensor's range (``sensor_range``) and, for
``fov_deg`` < 360, outside its horizontal field of view (``field_of_view``), for the whole
recording; per frame, the ground shadow of every box seen from the sensor (``occlusion``, with
``occluder_id``; a box of height h at ground distance d hides the ground to d H / (H - h) for a
sensor H above the ground), valid from its frame to the next.

Tested on: the TUM Traffic dev-kit's calibration ``../shared/data/tum_traffic_calib/
s110_lidar_ouster_south.json`` (the real LiDAR-to-base pose) with label files in TUM's layout
written here from an analytic truth (tests/converters/test_infra_lidar.py: static and moving
sensor, epoch-microsecond timestamps, DontCare and barriers), and the ASAM spec's
``asam_spec__openlabel100_example_cuboids.json`` (refused: a moving vehicle in UTM).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import is_moving, to_recording
from aveas_format.converters.common.boxes import Boxes, Range, Rows, Sensor, Sizes
from aveas_format.converters.common.geometry import (covariance_std_corr, matrix_yaw, quaternion_matrix,
                                                     rotate_covariance_2d)
from aveas_format.converters.common.tables import factorize, header_names, read_table
from aveas_format.converters.common.timestamps import (TIMESTAMP_UNITS, resolve_timestamps,
                                                       timestamp_value, utc_iso_from_ns)
from aveas_format.converters.labels import LabelFilter, class_of, implausible_size
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes
from aveas_format.safeio import MAX_BULK_JSON_BYTES, load_json
from aveas_format.schema.taxonomy import CLASSES

CLS = {c: i for i, c in enumerate(CLASSES)}


class InfraLidarOptions(ImportOptions):
    sensor_pose: Path | None = None
    """Sensor pose JSON (sensor -> base transform); overrides the OpenLABEL pose_wrt_parent chain."""
    frame_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose (x, y, yaw in rad) of the base frame in the OpenDRIVE map's local frame."""
    coordinate_system: str | None = None
    """OpenLABEL coordinate system of cuboids that name none."""
    rate_hz: float = 10.0
    """Frame rate where frames carry no timestamp (time = frame / rate_hz)."""
    sensor_id: str = "lidar"
    """Sensor id (acquisition.sensors, unobserved.sensor_id)."""
    range_m: float = 120.0
    """Sensor range (m) for the sensor_range region and the shadows' extent."""
    fov_deg: float = 360.0
    """Horizontal field of view (deg)."""
    fov_yaw_deg: float = 0.0
    """Direction of the field of view's centre in the sensor frame (deg, CCW from the sensor x axis)."""
    sigma0_m: float = 0.05
    """Position error floor (m)."""
    range_coeff: float = 0.002
    """Growth of the line-of-sight position error with range (m per m)."""
    angular_std_rad: float = 0.0015
    """Angular error (rad): the position error across the line of sight grows as r * this."""
    reference_points: float = 50.0
    """Point count at which the errors are nominal; fewer points inflate them by sqrt(ref / n)."""
    heading_std_rad: float = 0.03
    """Nominal heading error (rad)."""
    dimension_std_m: float = 0.1
    """Floor of the length/width/height std (m)."""
    occlusion: bool = True
    """Write the occlusion shadows of the tracked boxes."""
    class_map: dict[str, str] = {}
    """Source class name -> one of the 13 classes."""
    z_reference: Literal["center", "bottom"] = "center"
    """Tracks table: z is the box centre or its bottom."""
    timestamp_unit: Literal[TIMESTAMP_UNITS] = "auto"
    """Unit of OpenLABEL ``frame_properties.timestamp``: s, ms, us or ns; ``auto`` infers it from
    the values' magnitude and spacing (recorded in the ``source`` block)."""
    keep_non_road_users: bool = False
    """Import tracks whose type is no road user (see docs/converters.md "Labels that are not road
    users"); ignore-type labels are never imported."""


# --- transforms ------------------------------------------------------------------------------------

def _transform(td: Any, where: str, path: Path) -> np.ndarray:
    """4x4 of an OpenLABEL transform_data / a sensor pose object."""
    try:
        if isinstance(td, list):
            m = np.asarray(td, np.float64)
            return m.reshape(4, 4)
        if "matrix4x4" in td:
            return np.asarray(td["matrix4x4"], np.float64).reshape(4, 4)
        out = np.eye(4)
        if "quaternion" in td:
            out[:3, :3] = quaternion_matrix(np.asarray(td["quaternion"], np.float64))[0]
            out[:3, 3] = np.asarray(td.get("translation", [0, 0, 0]), np.float64)
            return out
        if "euler_angles" in td:
            seq = td.get("sequence", "ZYX").upper()
            if seq != "ZYX":
                raise ValueError(f"euler sequence {seq!r} (only ZYX is read)")
            from scipy.spatial.transform import Rotation

            out[:3, :3] = Rotation.from_euler("ZYX", td["euler_angles"]).as_matrix()
            out[:3, 3] = np.asarray(td.get("translation", [0, 0, 0]), np.float64)
            return out
        if "yaw" in td or "x" in td:
            from scipy.spatial.transform import Rotation

            out[:3, :3] = Rotation.from_euler(
                "ZYX", [td.get("yaw", 0.0), td.get("pitch", 0.0), td.get("roll", 0.0)]).as_matrix()
            out[:3, 3] = [td.get("x", 0.0), td.get("y", 0.0), td.get("z", 0.0)]
            return out
        raise ValueError("no matrix4x4, quaternion/translation, euler_angles or x/y/z/yaw")
    except (ValueError, TypeError, KeyError) as e:
        raise FormatError(f"{where}: not a transform: {e}", path=path) from None


def read_sensor_pose(path: Path) -> np.ndarray:
    """The sensor -> base 4x4 of a sensor pose JSON (see the module doc)."""
    data = _load_json(path)
    if isinstance(data, dict):
        if any(k in data for k in ("matrix4x4", "quaternion", "euler_angles", "yaw", "x")):
            return _transform(data, "sensor pose", path)
        cands = []
        for k, v in data.items():
            try:
                a = np.asarray(v, np.float64)
            except (ValueError, TypeError):
                continue
            if a.shape in ((4, 4), (16,)):
                cands.append((("_to_" in k) + ("lidar" in k.lower()), k, a.reshape(4, 4)))
        if cands:
            cands.sort(key=lambda c: -c[0])
            return cands[0][2]
    elif isinstance(data, list):
        return _transform(data, "sensor pose", path)
    raise FormatError("no 4x4 transform found (expected e.g. transformation_matrix_<sensor>_to_<base>, "
                      "matrix4x4, translation + quaternion)", path=path)


def _load_json(path: Path) -> Any:
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror}", path=path) from None
    return load_json(raw, path=path, max_bytes=MAX_BULK_JSON_BYTES)


# --- readers ---------------------------------------------------------------------------------------

_ROWS = ("time", "track", "type", "cx", "cy", "cz", "qx", "qy", "qz", "qw", "l", "w", "h",
         "points", "score", "cs", "src", "frame")


def _attr(block: dict[str, Any], name: str) -> float | None:
    for a in (block.get("attributes") or {}).get("num", []) or []:
        if isinstance(a, dict) and a.get("name") == name:
            try:
                return float(a["val"])
            except (TypeError, ValueError, KeyError):
                return None
    return None


def _read_openlabel(path: Path, data: dict[str, Any], opts: InfraLidarOptions, rows: dict[str, list],
                    systems: dict[str, np.ndarray], src: int) -> None:
    """The cuboids of one OpenLABEL file into ``rows``; their coordinate systems' transforms to the
    base frame into ``systems`` (per frame where ``frame_properties.transforms`` move them)."""
    from aveas_format.converters.common.coordinate_systems import CoordinateSystems as _Frames

    ol = data["openlabel"]
    if not isinstance(ol, dict):
        raise FormatError("'openlabel' is not an object", path=path)
    cs = ol.get("coordinate_systems") or {}
    if not isinstance(cs, dict):
        raise FormatError("'openlabel.coordinate_systems' is not an object", path=path)
    tree = _Frames(cs)
    top = ol.get("objects") or {}
    frames = ol.get("frames") or {}
    if not isinstance(frames, dict):
        raise FormatError("'openlabel.frames' is not an object", path=path)
    default_cs = opts.coordinate_system
    if default_cs is None:
        posed = [k for k, v in cs.items() if isinstance(v, dict) and v.get("pose_wrt_parent")
                 and v.get("type", "") not in ("scene_cs", "geo_utm", "geo_wgs84", "local_cs")]
        default_cs = posed[0] if len(posed) == 1 else None
    for fkey in sorted(frames, key=lambda k: int(k) if str(k).lstrip("-").isdigit() else 0):
        frame = frames[fkey] if isinstance(frames[fkey], dict) else {}
        try:
            fnum = int(fkey)
        except ValueError:
            raise FormatError(f"frame key {fkey!r} is not an integer", path=path) from None
        fp = frame.get("frame_properties") if isinstance(frame.get("frame_properties"), dict) else {}
        ts = fp.get("timestamp")
        if ts is not None and timestamp_value(ts) is None:
            raise FormatError(f"frame {fkey}: timestamp {ts!r} is not a number or an ISO 8601 time",
                              path=path)
        edges = tree.frame_edges(fp.get("transforms"))
        for uid, obj in (frame.get("objects") or {}).items():
            od = (obj or {}).get("object_data") or {}
            cub = od.get("cuboid")
            if cub is None:
                continue
            if isinstance(cub, list):
                if not cub:
                    continue
                cub = cub[0]
            where = f"frame {fkey}: object {uid!r}: cuboid"
            if not isinstance(cub, dict) or "val" not in cub:
                raise FormatError(f"{where} has no 'val'", path=path)
            try:
                val = [float(v) for v in cub["val"]]
            except (TypeError, ValueError):
                raise FormatError(f"{where} val holds non-numbers: {cub['val']!r}"[:200], path=path) from None
            if len(val) == 10:
                x, y, z, qx, qy, qz, qw, length, width, height = val
            elif len(val) == 9:
                x, y, z, rx, ry, rz, length, width, height = val
                from scipy.spatial.transform import Rotation

                qx, qy, qz, qw = Rotation.from_euler("ZYX", [rz, ry, rx]).as_quat()
            else:
                raise FormatError(f"{where} val has {len(val)} values, expected 10 "
                                  "[x,y,z,qx,qy,qz,qw,l,w,h] or 9 [x,y,z,rx,ry,rz,l,w,h]", path=path)
            if not np.isfinite(val[:7]).all():
                raise FormatError(f"{where} val is not finite", path=path)
            cname = cub.get("coordinate_system") or default_cs
            moving = bool(cname) and cname in edges
            key = f"{src}:{cname}@{fkey}" if moving else f"{src}:{cname}"
            if key not in systems:
                if opts.sensor_pose is not None:
                    if moving:
                        raise FormatError(
                            f"frame {fkey}: frame_properties.transforms move coordinate system "
                            f"{cname!r} (a moving sensor), but option sensor_pose fixes its pose: "
                            "drop sensor_pose to apply the frame's transforms", path=path)
                    systems[key] = read_sensor_pose(opts.sensor_pose)
                elif cname:
                    if cname not in cs and cname not in edges:
                        raise FormatError(f"coordinate system {cname!r} is not in coordinate_systems "
                                          f"({sorted(cs)})", path=path)
                    m, root, via_frame = tree.resolve(cname, edges)
                    if via_frame and tree.kind.get(root, "").startswith("geo"):
                        raise FormatError(
                            f"frame {fkey}: frame_properties.transforms carry coordinate system "
                            f"{cname!r} into {root!r} ({tree.kind[root]}): the sensor rides on a "
                            "vehicle in world coordinates, not on a pole; convert with --from "
                            "openlabel, which applies the transforms and reads the UTM zone",
                            path=path)
                    systems[key] = m
                else:
                    systems[key] = np.eye(4)
            typ = (top.get(uid) or {}).get("type") or od.get("type") or "other"
            pts = _attr(cub, "num_points")
            if pts is None:
                pts = _attr(od, "num_points")
            score = _attr(cub, "score")
            if score is None:
                score = _attr(od, "score")
            for k, v in zip(_ROWS, (ts if ts is not None else None, str(uid), str(typ), x, y, z, qx,
                                    qy, qz, qw, length, width, height,
                                    np.nan if pts is None else pts,
                                    np.nan if score is None else score, key, src, fnum)):
                rows[k].append(v)


def _read_tracks(path: Path, opts: InfraLidarOptions, rows: dict[str, list],
                 systems: dict[str, np.ndarray], src: int) -> None:
    t = read_table(path)
    names = set(t.column_names)

    def pick(*cands: str, required: bool = True) -> str | None:
        for c in cands:
            if c in names:
                return c
        if required:
            raise FormatError(f"tracks table needs a column {' or '.join(repr(c) for c in cands)}; "
                              f"found {t.column_names}", path=path)
        return None

    tcol = pick("time", "timestamp", "frame", "frame_id")
    idc = pick("track_id", "id", "object_id")
    clc = pick("class", "type", "category", required=False)
    lc, wc, hc = pick("length", "l"), pick("width", "w"), pick("height", "h")
    num = [c for c in (tcol, "x", "y", "z", "yaw", lc, wc, hc, "num_points", "score") if c]
    for c in ("x", "y", "yaw"):
        pick(c)
    t = read_table(path, numeric=num)
    n = t.num_rows
    tv = column_numpy(t, tcol)
    time = tv / opts.rate_hz if tcol.startswith("frame") else tv
    vals = {c: column_numpy(t, c) for c in ("x", "y", "yaw")}
    z = column_numpy(t, "z", missing=0.0)
    length, width, height = column_numpy(t, lc), column_numpy(t, wc), column_numpy(t, hc)
    for c, arr in (("x", vals["x"]), ("y", vals["y"]), ("yaw", vals["yaw"]), (tcol, tv), (lc, length),
                   (wc, width)):
        bad = ~np.isfinite(arr) | ((arr <= 0) if c in (lc, wc) else False)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = "is missing" if np.isnan(arr[i]) else "must be positive" if c in (lc, wc) else "is not finite"
            line = i + 2 if path.suffix.lower() != ".parquet" else None
            raise FormatError(f"column {c!r}: value {what}", path=path, line=line,
                              row=None if line else i)
    height = np.where(np.isfinite(height), height, np.nan)
    if opts.z_reference == "bottom":
        z = z + np.nan_to_num(height) / 2
    ids = t.column(idc).cast(pa.string()).to_pylist()
    cls = t.column(clc).cast(pa.string()).to_pylist() if clc else ["other"] * n
    half = vals["yaw"] / 2
    key = f"{src}:table"
    if key not in systems:
        if opts.sensor_pose is None:
            raise FormatError("a tracks table needs a sensor pose: pass a sensor pose JSON as an "
                              "input or option sensor_pose", path=path)
        systems[key] = read_sensor_pose(opts.sensor_pose)
    cols = {"time": time, "track": ids, "type": cls, "cx": vals["x"], "cy": vals["y"], "cz": z,
            "qx": np.zeros(n), "qy": np.zeros(n), "qz": np.sin(half), "qw": np.cos(half),
            "l": length, "w": width, "h": height,
            "points": column_numpy(t, "num_points", missing=np.nan),
            "score": column_numpy(t, "score", missing=np.nan),
            "cs": [key] * n, "src": [src] * n, "frame": [np.nan] * n}
    for k in _ROWS:
        rows[k].extend(list(cols[k]))


# --- the converter ---------------------------------------------------------------------------------

def _class_pmf(types: np.ndarray, score: np.ndarray, class_map: dict[str, str]) -> np.ndarray:
    lut = {u: CLS[class_of(u, class_map)] for u in set(types)}
    idx = np.fromiter((lut[v] for v in types), np.int64, len(types))
    p = np.clip(np.where(np.isfinite(score), score, 1.0), 0.0, 1.0)
    out = np.repeat(((1.0 - p) / len(CLASSES))[:, None], len(CLASSES), axis=1)
    out[np.arange(len(idx)), idx] += p
    return out


def _is_lidar_input(path: Path, head: bytes) -> bool:
    """A sensor pose JSON, or a tracks table of 3D boxes with a yaw (an OpenLABEL file is the
    ``openlabel`` importer's by default: pass ``--from infra-lidar``)."""
    if path.suffix.lower() == ".json":
        return b'"openlabel"' not in head and (b"transformation_matrix" in head
                                                or b'"matrix4x4"' in head)
    names = header_names(path, head)
    return ({"x", "y", "yaw"} <= names and bool(names & {"track_id", "id", "object_id"})
            and ({"length", "width", "height"} <= names or {"l", "w", "h"} <= names))


@converter("infra-lidar", description="Infrastructure LiDAR: OpenLABEL cuboids (TUM Traffic/A9 style) "
           "or a tracks table + sensor pose", patterns=("*.json", "*.csv", "*.parquet"),
           method="infrastructure_lidar", options=InfraLidarOptions, provides=("start_time",),
           sniff=_is_lidar_input)
def convert_infra_lidar(inputs: list[Path], *, map_source, options: InfraLidarOptions):
    o = options
    rows, systems, labels, tables, o = _read_inputs(inputs, o)
    t_abs, resolved, start_ns = _times(rows, labels, o)
    notes = _keep_road_users(rows, o, t_abs)
    if not rows["time"]:
        raise FormatError("no road user among the cuboids: " + "; ".join(notes), path=inputs[0])
    for note in notes:
        warnings.warn(f"infra-lidar: {note}", stacklevel=2)
    map_bytes = load_map_bytes(map_source)
    t0 = float(np.min(rows["time"]))
    boxes, mats = _boxes_in_map(rows, systems, o, t0, [p for p, _ in labels] + tables)
    pose = boxes["sensor_pose"]
    moving = is_moving(pose)
    rot0 = mats[boxes.order[0], :3, :3]  # the sensor's pose in the first frame
    from scipy.spatial.transform import Rotation

    _, pitch, roll = Rotation.from_matrix(rot0).as_euler("ZYX")
    if start_ns is not None:  # exact: the first timestamp's digits, moved to the first kept box
        start = utc_iso_from_ns(start_ns + int(round((t0 - start_ns / 1e9) * 1e9)))
    else:
        start = utc_iso_from_ns(int(round(t0 * 1e9))) if t0 > 1e8 else "1970-01-01T00:00:00Z"
    types = np.asarray(rows["type"], dtype=object)[boxes.order]
    sensor = Sensor(
        method="infrastructure_lidar", start_time=start,
        platform="pole-mounted LiDAR" if not moving else "LiDAR on a moving platform",
        sensors=[{"id": o.sensor_id, "kind": "lidar",
                  "pose": {"x": float(pose[0, 0]), "y": float(pose[0, 1]), "z": float(pose[0, 2]),
                           "yaw": float(matrix_yaw(rot0[None])[0]), "pitch": float(pitch),
                           "roll": float(roll), "frame": "local"},
                  "description": f"range {o.range_m} m, FOV {o.fov_deg} deg"
                                 + ("; moving: pose of the first frame, unobserved regions "
                                    "per frame" if moving else "")}],
        not_observable=["light_", "interior"],
        coverage=Range(o.sensor_id, o.range_m, 1.0 / o.rate_hz, fov=np.radians(o.fov_deg),
                       occlusion=o.occlusion),
        sizes=Sizes(floor=o.dimension_std_m))
    return to_recording(boxes, sensor, converter="infra-lidar", inputs=inputs, options=options,
                        map_bytes=map_bytes, resolved=resolved, participants={
                            "attributes": [json.dumps({"source_class": str(types[i])})
                                           for i in boxes.first_rows()]})


def _read_inputs(inputs: list[Path], o: InfraLidarOptions
                 ) -> tuple[dict[str, list], dict[str, np.ndarray], list, list[Path], InfraLidarOptions]:
    """The rows of every OpenLABEL file and tracks table (``_ROWS``), the sensor -> base
    transform of each coordinate system (``rows["cs"]``), the OpenLABEL inputs (path, document),
    the tracks tables, and the options with a sensor pose input as ``sensor_pose``."""
    rows: dict[str, list] = {k: [] for k in _ROWS}
    systems: dict[str, np.ndarray] = {}
    labels, tables, poses = [], [], []
    for p in inputs:
        if p.suffix.lower() in (".csv", ".parquet"):
            tables.append(p)
        else:
            data = _load_json(p)
            (labels if isinstance(data, dict) and "openlabel" in data else poses).append((p, data))
    if poses:
        if len(poses) > 1 or o.sensor_pose is not None:
            raise FormatError("more than one sensor pose given (inputs without 'openlabel' and option "
                              f"sensor_pose): {[str(p) for p, _ in poses]}")
        o = o.model_copy(update={"sensor_pose": poses[0][0]})
    for i, (p, data) in enumerate(labels):
        _read_openlabel(p, data, o, rows, systems, i)
    for j, p in enumerate(tables):
        _read_tracks(p, o, rows, systems, len(labels) + j)
    if not rows["time"]:
        raise FormatError("no cuboids or track rows found", path=inputs[0])
    return rows, systems, labels, tables, o


def _boxes_in_map(rows: dict[str, list], systems: dict[str, np.ndarray], o: InfraLidarOptions,
                  t0: float, files: list[Path]) -> tuple[Boxes, np.ndarray]:
    """The boxes (sorted, repeated timestamps of a track dropped) in the map's frame with the
    uncertainty model of the module doc, and each row's sensor -> map transform (4x4): the
    cuboid's centre projected to the ground, its heading the yaw of its x axis. ``files``: the
    inputs in the order of ``rows["src"]``."""
    ox, oy, oyaw = o.frame_offset
    off = np.eye(4)
    off[:2, :2] = [[np.cos(oyaw), -np.sin(oyaw)], [np.sin(oyaw), np.cos(oyaw)]]
    off[:2, 3] = ox, oy
    cs_codes, cs_names = factorize(rows["cs"])
    m = np.stack([off @ systems[str(k)] for k in cs_names])[cs_codes]  # sensor -> local, per row
    c = np.c_[rows["cx"], rows["cy"], rows["cz"]].astype(np.float64)
    q = np.c_[rows["qx"], rows["qy"], rows["qz"], rows["qw"]].astype(np.float64)
    pos = np.einsum("nij,nj->ni", m[:, :3, :3], c) + m[:, :3, 3]
    heading = matrix_yaw(np.einsum("nij,njk->nik", m[:, :3, :3], quaternion_matrix(q)))
    height = np.asarray(rows["h"], np.float64)
    sensor = m[:, :3, 3]                                             # sensor origin, local frame
    d = pos[:, :2] - sensor[:, :2]
    r = np.hypot(d[:, 0], d[:, 1])
    npts = np.asarray(rows["points"], np.float64)
    f = np.sqrt(np.maximum(1.0, o.reference_points / np.where(npts > 0, npts, o.reference_points)))
    cov = np.zeros((len(r), 2, 2))
    cov[:, 0, 0] = ((o.sigma0_m + o.range_coeff * r) * f) ** 2        # along the line of sight
    cov[:, 1, 1] = ((o.sigma0_m + o.angular_std_rad * r) * f) ** 2     # across it
    sx, sy, rho = covariance_std_corr(rotate_covariance_2d(cov, np.arctan2(d[:, 1], d[:, 0])))
    pid, uniq = factorize(rows["track"])
    yaw = matrix_yaw(m[:, :3, :3]) + np.radians(o.fov_yaw_deg)
    # relative times at microsecond resolution (epoch seconds as float64 carry ~0.2 us of noise)
    boxes = Boxes(
        pid, np.round(np.asarray(rows["time"], np.float64) - t0, 6), pos[:, 0], pos[:, 1],
        source_ids=[str(u) for u in uniq], rows=Rows(files, file=np.asarray(rows["src"])),
        duplicates="first", z=pos[:, 2] - np.nan_to_num(height) / 2, heading=heading,
        x_std=sx, y_std=sy, xy_corr=rho, heading_std=o.heading_std_rad * f,
        length=np.asarray(rows["l"], np.float64), width=np.asarray(rows["w"], np.float64),
        height=height, class_pmf=_class_pmf(np.asarray(rows["type"], dtype=object),
                                            np.asarray(rows["score"], np.float64), o.class_map),
        sensor_pose=np.c_[sensor, yaw])
    return boxes.sort(), m


def _times(rows: dict[str, list], labels: list, o: InfraLidarOptions
           ) -> tuple[np.ndarray, dict, int | None]:
    """Seconds (Unix seconds where absolute) of every row into ``rows["time"]``: OpenLABEL frame
    timestamps with their unit inferred (or ``timestamp_unit``), else frame numbers at
    ``rate_hz``; tracks tables' time as given. Returns ``(times, resolved, Unix ns of the first
    OpenLABEL timestamp or None)``."""
    n = len(rows["time"])
    src = np.asarray(rows["src"])
    is_ol = src < len(labels)
    t = np.full(n, np.nan)
    resolved: dict[str, str] = {}
    start_ns = None
    if is_ol.any():
        idx = np.flatnonzero(is_ol)
        raw = [rows["time"][i] for i in idx]
        present = np.asarray([v is not None for v in raw])
        if present.all():
            ts = resolve_timestamps(raw, o.timestamp_unit, what="frame_properties.timestamp")
            t[idx] = (ts.start_ns / 1e9 if ts.epoch else 0.0) + ts.seconds
            resolved, start_ns = ts.resolved(), ts.start_ns
        elif not present.any():
            t[idx] = np.asarray(rows["frame"], np.float64)[idx] / o.rate_hz
            resolved = {"timestamps": f"no frame has a timestamp: frame numbers at rate_hz {o.rate_hz:g}"}
        else:
            i = idx[int(np.flatnonzero(~present)[0])]
            raise FormatError(f"frame {rows['frame'][i]} has no frame_properties.timestamp while other "
                              "frames have one", path=labels[int(src[i])][0])
    if (~is_ol).any():
        t[~is_ol] = np.asarray([rows["time"][i] for i in np.flatnonzero(~is_ol)], np.float64)
    rows["time"] = t.tolist()
    return t, resolved, start_ns


def _keep_road_users(rows: dict[str, list], o: InfraLidarOptions, t_abs: np.ndarray) -> list[str]:
    """Drop (in place) the rows of tracks whose type is no road user (``keep_non_road_users``
    keeps them) or an ignore type, and boxes with a sentinel or impossible size; the notes."""
    labels = LabelFilter(o.keep_non_road_users, o.class_map)
    first_type: dict[str, str] = {}
    for tr, ty in zip(rows["track"], rows["type"]):
        first_type.setdefault(tr, ty)
    keep_track = {tr: labels(ty) is not None for tr, ty in first_type.items()}
    keep = np.asarray([keep_track[tr] for tr in rows["track"]], bool)
    bad = implausible_size(np.c_[rows["l"], rows["w"], rows["h"]]) & keep
    notes = [labels.note("tracks")] if labels.note("tracks") else []
    if bad.any():
        notes.append(f"dropped {int(bad.sum())} boxes with a sentinel or impossible size (<= 0, "
                     "not finite or > 400 m)")
    keep &= ~bad
    if not keep.all():
        idx = np.flatnonzero(keep)
        for k in rows:
            rows[k] = [rows[k][i] for i in idx]
    return notes
