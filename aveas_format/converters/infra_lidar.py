"""Pole-mounted (infrastructure) LiDAR tracks -> recording.

Inputs (mixed freely; the kind is recognised per file):

- **OpenLABEL** JSON (``{"openlabel": ...}``), one file per frame or one per sequence, as the TUM
  Traffic (A9) datasets write them: ``frames.<n>.objects.<uid>.object_data.cuboid.val`` =
  ``[x, y, z, qx, qy, qz, qw, l, w, h]`` (the box centre, its orientation and size in a sensor
  coordinate system; the 9-value Euler form ``[x, y, z, rx, ry, rz, l, w, h]`` is read too). Both
  the ASAM-conformant form (``cuboid`` a list, the object's ``type`` in the top-level ``objects``)
  and the TUM deviations (a single ``cuboid`` object, ``type`` inside ``object_data``) are
  accepted. The object uid is the track id. ``frame_properties.timestamp`` (s since the epoch)
  gives the time, else the frame number / ``rate_hz``. ``num_points`` and ``score`` attributes
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
(OpenLABEL: the pose of a coordinate system in its parent, ``X_parent = P X_child``) up to the
root; ``frame_offset`` = (x, y, yaw) places that base frame in the OpenDRIVE map's local frame, whose
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
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common import (
    class_of,
    column,
    coverage_regions,
    unobserved_table,
    covariance_std_corr,
    factorize,
    group_mean,
    group_std,
    load_map_bytes,
    map_area,
    matrix_yaw,
    nullable,
    occlusion_shadows,
    quaternion_matrix,
    read_numeric_table,
    read_table,
    rotate_covariance_2d,
    sector_polygon,
    utc_iso_from_ns,
    velocity_with_std,
    wrap_recording,
)
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
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


def _chain(cs: dict[str, Any], name: str, path: Path) -> np.ndarray:
    out = np.eye(4)
    cur = name
    for _ in range(64):
        node = cs.get(cur)
        if node is None:
            raise FormatError(f"coordinate system {cur!r} is not in coordinate_systems "
                              f"({sorted(cs)})", path=path)
        if "pose_wrt_parent" in node and node["pose_wrt_parent"]:
            out = _transform(node["pose_wrt_parent"], f"coordinate_systems.{cur}.pose_wrt_parent",
                             path) @ out
        parent = node.get("parent", "")
        if not parent:
            return out
        cur = parent
    raise FormatError(f"coordinate system {name!r}: parent chain is cyclic", path=path)


# --- readers ---------------------------------------------------------------------------------------

_ROWS = ("time", "track", "type", "cx", "cy", "cz", "qx", "qy", "qz", "qw", "l", "w", "h",
         "points", "score", "cs", "src")


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
    ol = data["openlabel"]
    if not isinstance(ol, dict):
        raise FormatError("'openlabel' is not an object", path=path)
    cs = ol.get("coordinate_systems") or {}
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
        frame = frames[fkey]
        try:
            fnum = int(fkey)
        except ValueError:
            raise FormatError(f"frame key {fkey!r} is not an integer", path=path) from None
        ts = (frame.get("frame_properties") or {}).get("timestamp")
        try:
            t = float(ts) if ts is not None else fnum / opts.rate_hz
        except (TypeError, ValueError):
            raise FormatError(f"frame {fkey}: timestamp {ts!r} is not a number", path=path) from None
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
            if not np.isfinite(val).all():
                raise FormatError(f"{where} val is not finite", path=path)
            if length <= 0 or width <= 0:
                raise FormatError(f"{where} size {length} x {width} is not positive", path=path)
            cname = cub.get("coordinate_system") or default_cs
            key = f"{src}:{cname}"
            if key not in systems:
                if opts.sensor_pose is not None:
                    systems[key] = read_sensor_pose(opts.sensor_pose)
                elif cname:
                    systems[key] = _chain(cs, cname, path)
                else:
                    systems[key] = np.eye(4)
            typ = (top.get(uid) or {}).get("type") or od.get("type") or "other"
            pts = _attr(cub, "num_points")
            if pts is None:
                pts = _attr(od, "num_points")
            score = _attr(cub, "score")
            if score is None:
                score = _attr(od, "score")
            for k, v in zip(_ROWS, (t, str(uid), str(typ), x, y, z, qx, qy, qz, qw, length, width,
                                    height, np.nan if pts is None else pts,
                                    np.nan if score is None else score, key, src)):
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
    t = read_numeric_table(path, numeric=num)
    n = t.num_rows
    tv = column(t, tcol)
    time = tv / opts.rate_hz if tcol.startswith("frame") else tv
    vals = {c: column(t, c) for c in ("x", "y", "yaw")}
    z = column(t, "z") if "z" in names else np.zeros(n)
    length, width, height = column(t, lc), column(t, wc), column(t, hc)
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
            "points": column(t, "num_points") if "num_points" in names else np.full(n, np.nan),
            "score": column(t, "score") if "score" in names else np.full(n, np.nan),
            "cs": [key] * n, "src": [src] * n}
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


@converter("infra-lidar", description="Infrastructure LiDAR: OpenLABEL cuboids (TUM Traffic/A9 style) "
           "or a tracks table + sensor pose", patterns=("*.json", "*.csv", "*.parquet"),
           method="infrastructure_lidar", options=InfraLidarOptions, provides=("start_time",))
def convert_infra_lidar(inputs: list[Path], *, map_source, options: InfraLidarOptions):
    o = options
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

    map_bytes = load_map_bytes(map_source)
    n = len(rows["time"])
    t_abs = np.asarray(rows["time"], np.float64)
    cs_codes, cs_names = factorize(rows["cs"])
    c = np.c_[rows["cx"], rows["cy"], rows["cz"]].astype(np.float64)
    q = np.c_[rows["qx"], rows["qy"], rows["qz"], rows["qw"]].astype(np.float64)
    ox, oy, oyaw = o.frame_offset
    off = np.eye(4)
    off[:2, :2] = [[np.cos(oyaw), -np.sin(oyaw)], [np.sin(oyaw), np.cos(oyaw)]]
    off[:2, 3] = ox, oy
    mats = np.stack([off @ systems[str(k)] for k in cs_names])       # sensor -> local, per system
    m = mats[cs_codes]
    pos = np.einsum("nij,nj->ni", m[:, :3, :3], c) + m[:, :3, 3]
    rot = np.einsum("nij,njk->nik", m[:, :3, :3], quaternion_matrix(q))
    heading = matrix_yaw(rot)
    length = np.asarray(rows["l"], np.float64)
    width = np.asarray(rows["w"], np.float64)
    height = np.asarray(rows["h"], np.float64)
    ground = pos[:, 2] - np.nan_to_num(height) / 2
    sensor = m[:, :3, 3]                                             # sensor origin, local frame
    # uncertainty model
    d = pos[:, :2] - sensor[:, :2]
    r = np.hypot(d[:, 0], d[:, 1])
    bearing = np.arctan2(d[:, 1], d[:, 0])
    npts = np.asarray(rows["points"], np.float64)
    f = np.sqrt(np.maximum(1.0, o.reference_points / np.where(npts > 0, npts, o.reference_points)))
    sr = (o.sigma0_m + o.range_coeff * r) * f
    st = (o.sigma0_m + o.angular_std_rad * r) * f
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sr ** 2, st ** 2
    sx, sy, rho = covariance_std_corr(rotate_covariance_2d(cov, bearing))

    # participants and ordering
    pid, uniq = factorize(rows["track"])
    t0 = float(t_abs.min())
    # relative times at microsecond resolution (epoch seconds as float64 carry ~0.2 us of noise)
    t_rel = np.round(t_abs - t0, 6)
    order = np.lexsort((t_rel, pid))
    pid, t_rel = pid[order], t_rel[order]
    dup = np.r_[False, (pid[1:] == pid[:-1]) & (t_rel[1:] == t_rel[:-1])]
    if dup.any():
        warnings.warn(f"{int(dup.sum())} boxes repeat a track's timestamp (e.g. track "
                      f"{uniq[pid[np.flatnonzero(dup)[0]]]!r}); the first is kept", stacklevel=2)
    sel = order[~dup]
    pid, time = pid[~dup], t_rel[~dup]
    x, y = pos[sel, 0], pos[sel, 1]
    sx, sy, rho = sx[sel], sy[sel], rho[sel]
    vx, vy, vxs, vys = velocity_with_std(pid, time, x, y, sx, sy)
    mp = len(uniq)
    types = np.asarray(rows["type"], dtype=object)[sel]
    pmf = group_mean(pid, _class_pmf(types, np.asarray(rows["score"], np.float64)[sel], o.class_map), mp)
    pmf = (pmf / pmf.sum(axis=1, keepdims=True)).astype(np.float32)
    dims = np.c_[length, width, height][sel]
    mean_dims = group_mean(pid, dims, mp)
    std_dims = np.stack([np.fmax(np.nan_to_num(group_std(pid, dims[:, k], mp), nan=0.0),
                                 o.dimension_std_m) for k in range(3)], -1)
    std_dims[np.isnan(mean_dims)] = np.nan
    first = np.unique(pid, return_index=True)[1]
    states = {
        "participant_id": pid, "time": time, "x": x, "y": y, "z": ground[sel],
        "heading": heading[sel], "vx": vx, "vy": vy,
        "x_std": sx, "y_std": sy, "xy_corr": nullable(rho),
        "heading_std": o.heading_std_rad * f[sel], "vx_std": nullable(vxs), "vy_std": nullable(vys),
    }
    participants = {
        "participant_id": np.arange(mp, dtype=np.int64), "source_id": [str(u) for u in uniq],
        "class": np.asarray(CLASSES, dtype=object)[np.argmax(pmf, axis=1)], "class_pmf": pmf,
        "length": mean_dims[:, 0], "width": mean_dims[:, 1], "height": nullable(mean_dims[:, 2]),
        "length_std": std_dims[:, 0], "width_std": std_dims[:, 1],
        "height_std": nullable(std_dims[:, 2]),
        "attributes": [json.dumps({"source_class": str(types[i])}) for i in first],
    }

    # unobserved regions
    period = 1.0 / o.rate_hz
    frame_times = np.unique(time)
    nxt = np.r_[frame_times[1:], frame_times[-1] + period]
    duration = float(nxt[-1])
    s0 = mats[0][:3, 3]
    fov_yaw = matrix_yaw(mats[0][None, :3, :3])[0] + np.radians(o.fov_yaw_deg)
    area = map_area(map_bytes)
    unob = coverage_regions(o.sensor_id, (float(s0[0]), float(s0[1])), o.range_m, float(fov_yaw),
                            np.radians(o.fov_deg), area, 0.0, duration)
    import shapely

    view = shapely.intersection(sector_polygon(float(s0[0]), float(s0[1]), o.range_m, float(fov_yaw),
                                               np.radians(o.fov_deg)), area)
    coverage = shapely.to_wkt(view, rounding_precision=3) if not view.is_empty else None
    if o.occlusion:
        h_sensor = float(s0[2])
        shadows = occlusion_shadows((float(s0[0]), float(s0[1]), h_sensor), x, y, heading[sel],
                                    length[sel], width[sel],
                                    np.where(np.isfinite(height[sel]), height[sel], 1.5), o.range_m)
        keep = np.flatnonzero(np.asarray([g is not None for g in shadows]))
        ends = nxt[np.searchsorted(frame_times, time[keep])]
        for i, te in zip(keep, ends):
            unob.append({"time_start": float(time[i]), "time_end": float(te), "kind": "occlusion",
                         "geometry": shadows[i], "sensor_id": o.sensor_id, "occluder_id": int(pid[i])})
    unobserved = unobserved_table(unob)
    yaw_s = float(matrix_yaw(mats[0][None, :3, :3])[0])
    from scipy.spatial.transform import Rotation

    _, pitch, roll = Rotation.from_matrix(mats[0][:3, :3]).as_euler("ZYX")
    start = (utc_iso_from_ns(int(round(t0 * 1e9))) if t0 > 1e8 else "1970-01-01T00:00:00Z")
    return wrap_recording(
        "infra-lidar", inputs, options, map_bytes=map_bytes, participants=participants,
        states=states, method="infrastructure_lidar", provenance="natural", start_time=start,
        unobserved=unobserved, duration_s=duration,
        acquisition={
            "platform": "pole-mounted LiDAR",
            "sensors": [{"id": o.sensor_id, "kind": "lidar",
                         "pose": {"x": float(s0[0]), "y": float(s0[1]), "z": float(s0[2]),
                                  "yaw": yaw_s, "pitch": float(pitch), "roll": float(roll),
                                  "frame": "local"},
                         "description": f"range {o.range_m} m, FOV {o.fov_deg} deg"}],
            "not_observable": ["light_", "interior"],
        },
        coverage=coverage,
    )
