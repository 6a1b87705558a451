"""ASAM OpenLABEL 1.0 (AVEAS profile) <-> recording, both directions.

**Export** (``aveas-format export --to openlabel REC -o OUT.json``) writes one OpenLABEL 1.0 JSON
file that follows the AVEAS profile (PyPI ``aveas-openlabel`` 0.4.17) and the map next to it
(``OUT.xodr``, named in ``metadata.opendrive``). The file validates against the official ASAM
OpenLABEL 1.0 JSON schema and loads with ``aveas_openlabel.AveasOpenLabel.from_dict``:

- ``metadata``: ``acquisition_method`` (aerial / stationary / in-vehicle), ``acquisition_partner``,
  ``acquisition_date`` (= ``start_time``), ``right_of_use``, ``opendrive``, ``projection_string``
  (= ``crs``), ``threshold_gttc``/``threshold_pret``/``threshold_thw`` (= ``thresholds``).
- ``objects`` (one per participant, key = ``participant_id``): type ``vehicle/car``,
  ``human/pedestrian``, ... (the profile's 13 classes), name = ``source_id``, ``dimensions/size``
  (+``/ustddev``), ``classification/uncertainties`` (= ``class_pmf``), ``is_recorder``,
  ``attached_to`` and the ``summary/*`` speed and acceleration extremes.
- ``frames`` (one per distinct ``time``; ``frame_properties.timestamp`` = seconds since
  ``acquisition_date``): per participant a ``bounding_box`` cuboid (x, y, z of the box centre in the
  OpenDRIVE inertial frame, yaw = ``heading``, size), ``velocity`` and ``acceleration`` in the
  vehicle frame (x forward, y left, as the profile states; yaw rate as rz), ``/ustddev`` siblings,
  ``used_road_link`` (road id: the profile's attribute name), ``open_drive/lane_id``,
  ``open_drive/lane_position`` (lane offset / lane width), ``open_drive/local_road_coordinates``
  (s, t), ``road/classification`` and ``road/number_lanes/*`` from the map, lights, interior
  signals and ``impact/gttc|thw|pret`` from the derived tables below the thresholds.
- ``contexts``: a ``scenario_context`` and ``environment_context`` (static conditions and one per
  ``environment`` row with its frame interval); ``events`` for the profile's event types (lane
  change, parking, turning, overtaking, following).

What the profile cannot carry (occlusions, full covariance, exact probabilities of lights, PET,
provenance and roles, other event kinds, the exact metadata) goes into the namespaced extension
``aveas_format`` where the OpenLABEL schema allows additional properties: ``metadata.aveas_format``
(recording.json, the ``unobserved``/``events``/``environment``/``interior`` tables, column lists,
the derived tables -- kinematics, interactions, encroachments with PET, traffic -- as column lists
with their recording.json ``derived`` entries and provenance), the ``dimensions/size`` item of each
object and the ``bounding_box`` item of each object in a frame (with the exact value of a velocity,
acceleration or z where the rebuilt one would differ in the last bit). Other readers ignore it;
our own import uses it, so export -> import is lossless and leaves derived tables fresh.

**Import** (``aveas-format convert --from openlabel FILE.json``) reads AVEAS-profile files,
including those written by ``aveas-openlabel`` itself (``to_dict(exclude_none=True)``) with its
quirks: ``used_road_link`` as the road-id name, enum values written as
``"Road__ClassificationValue.STRAIGHT"``, and the lateral automated-control flag serialised under
the longitudinal name (the second ``interior/automated_control/longitudinal`` of a frame is read
as lateral). It also reads generic ASAM OpenLABEL with cuboids (9 values with Euler angles or 10
with a quaternion) in any coordinate system, chained through ``coordinate_systems``
``pose_wrt_parent`` and per-frame ``frame_properties.transforms`` to the root frame; a root of
type ``geo_utm`` named like ``utm-30t`` is read as that UTM zone (or pass ``world_crs``), any other
root is taken as the map frame. Per-frame timestamps in Unix seconds set ``start_time``.

The map comes from ``--map``, else from ``metadata.opendrive`` when that file lies next to the
input. Positions are the box centres at ground level; velocities without a ``velocity`` attribute
are computed from the positions; road coordinates are taken from the file where it has them, else
computed through the map.
"""

from __future__ import annotations

import base64
import json
import math
import re
import warnings
from collections import defaultdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.common import load_map_bytes, source_block
from aveas_format.converters.registry import ConverterOptions, ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.safeio import (MAX_BULK_JSON_BYTES, MAX_JSON_DEPTH, CountingReader, check_json_size,
                                 load_json, scan_json_member, stream_json_error)
from aveas_format.schema.taxonomy import CLASSES, LIGHTING, ROAD_SURFACE

#: the namespace of everything this library adds to an OpenLABEL file
EXT = "aveas_format"
EXT_VERSION = "1"

#: format class -> AVEAS OpenLABEL object type (same 13 classes, same order)
CLASS_TO_TYPE: dict[str, str] = {
    "animal": "animal", "bicycle": "vehicle/bicycle", "bus": "vehicle/bus", "car": "vehicle/car",
    "pedestrian": "human/pedestrian", "mobility_device": "vehicle/mobility_device",
    "motorcycle": "vehicle/motorcycle", "other": "other", "pushable_pullable": "pushable_pullable",
    "railvehicle": "vehicle/railvehicle", "trailer": "vehicle/trailer", "truck": "vehicle/truck",
    "van": "vehicle/van",
}
TYPE_TO_CLASS = {v: k for k, v in CLASS_TO_TYPE.items()}
#: generic OpenLABEL / dataset type names -> class (lower-case, after the AVEAS names)
GENERIC_TYPES: dict[str, str] = {
    "car": "car", "egocar": "car", "ego": "car", "ego_vehicle": "car", "vehicle": "car",
    "passenger_car": "car", "sedan": "car", "suv": "car", "taxi": "car", "emergency_vehicle": "car",
    "police_car": "car", "van": "van", "truck": "truck", "lorry": "truck", "trailer": "trailer",
    "bus": "bus", "pedestrian": "pedestrian", "person": "pedestrian", "human": "pedestrian",
    "adult": "pedestrian", "child": "pedestrian", "bicycle": "bicycle", "cyclist": "bicycle",
    "bike": "bicycle", "motorcycle": "motorcycle", "motorbike": "motorcycle",
    "motorcyclist": "motorcycle", "scooter": "mobility_device", "wheelchair": "mobility_device",
    "mobility_device": "mobility_device", "tram": "railvehicle", "train": "railvehicle",
    "railvehicle": "railvehicle", "animal": "animal", "dog": "animal", "stroller": "pushable_pullable",
    "pushable_pullable": "pushable_pullable", "other": "other",
}
#: classes without ``is_recorder`` in the profile
_NO_RECORDER = {"animal", "pushable_pullable", "trailer"}
#: classes whose frames carry the mandatory road attributes in the profile
_ROAD_CLASSES = {"bicycle", "bus", "car", "mobility_device", "motorcycle", "other", "railvehicle",
                 "trailer", "truck", "van"}
#: format event kinds <-> AVEAS event types
EVENT_TO_TYPE = {"lane_change": "lane change", "parking": "parking", "turning": "turning",
                 "overtaking": "overtaking", "following": "following"}
TYPE_TO_EVENT = {v: k for k, v in EVENT_TO_TYPE.items()}
#: acquisition methods (format -> profile); the exact method is kept in the extension
METHOD_TO_PROFILE = {
    "aerial": "aerial", "traffic_simulation": "aerial", "accident_reconstruction": "aerial",
    "infrastructure_lidar": "stationary", "infrastructure_lwir": "stationary",
    "infrastructure_camera": "stationary", "road_vehicle": "in-vehicle",
    "driving_simulator": "in-vehicle",
}
PROFILE_TO_METHOD = {"aerial": "aerial", "stationary": "infrastructure_camera",
                     "in-vehicle": "road_vehicle"}
#: lights: format column -> profile boolean attribute
LIGHTS = {
    "light_brake_p": "lights/brake", "light_indicator_left_p": "lights/indicator/left",
    "light_indicator_right_p": "lights/indicator/right", "light_front_p": "lights/front",
    "light_high_beam_p": "lights/high_beam",
}
_LONGITUDINAL = "interior/automated_control/longitudinal"
#: format lighting PMF <-> profile lighting_conditions (profile order: darkness, artificial,
#: civil_twilight, day)
LIGHTING_TO_PROFILE = {"day": "day", "twilight": "civil_twilight", "darkness_lit": "artificial",
                       "darkness_unlit": "darkness"}
PROFILE_LIGHTING = ("darkness", "artificial", "civil_twilight", "day")
PROFILE_ROAD = ("dry", "wet", "slippery")
_BEAUFORT = (0.5, 1.5, 3.3, 5.5, 7.9, 10.7, 13.8, 17.1, 20.7, 24.4, 28.4, 32.6)  # upper m/s bounds
_DEFAULT_THRESHOLDS = {"ttc_s": 3.0, "pet_s": 1.5, "thw_s": 1.0}

#: states columns the profile attributes carry (possibly as a placeholder where null)
_PROFILE_STATE_COLS = {"participant_id", "time", "x", "y", "z", "heading", "vx", "vy", "ax", "ay",
                       "yaw_rate", "lon", "lat", "road_id", "lane_id", "road_s", "road_t",
                       "x_std", "y_std", "z_std", "heading_std"}
_PROFILE_PART_COLS = {"participant_id", "source_id", "class", "class_pmf", "length", "width",
                      "height", "length_std", "width_std", "height_std", "attached_to"}


# ================================================================================================
# helpers
# ================================================================================================

def _f(v: Any) -> float:
    return float(v)


def _finite(v: Any) -> bool:
    return v is not None and not (isinstance(v, float) and math.isnan(v))


def _clean(v: Any) -> Any:
    """JSON-safe: NaN -> None, numpy scalars -> Python."""
    if isinstance(v, (np.floating, float)):
        v = float(v)
        return None if math.isnan(v) or math.isinf(v) else v
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, (bytes, bytearray)):
        return {"base64": base64.b64encode(bytes(v)).decode()}
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    return v


#: schema-metadata key of a derived table (aveas_format.derive.registry.DERIVED_KEY)
_DERIVED_KEY = b"aveas_derived"
_NONFINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def table_to_json(table: pa.Table | None) -> dict[str, Any] | None:
    """A table as ``{"columns": {name: [values]}, "rows": n}`` (binary as base64, dictionary as
    plain). JSON has no NaN or infinity: the row indices of such float values go to
    ``"nonfinite": {name: {"NaN"|"Infinity"|"-Infinity": [rows]}}`` (the list holds null there), and
    the table's ``aveas_derived`` schema metadata (how a derived table was made) to
    ``"derived_info"``."""
    if table is None:
        return None
    cols = {}
    nonfinite: dict[str, dict[str, list[int]]] = {}
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_dictionary(col.type):
            col = col.cast(col.type.value_type)
        if pa.types.is_floating(col.type) and table.num_rows:
            x = col.to_numpy(zero_copy_only=False).astype(np.float64)
            valid = ~np.asarray(col.is_null().to_numpy(zero_copy_only=False), bool)
            bad = {key: np.flatnonzero(valid & m).tolist()
                   for key, m in (("NaN", np.isnan(x)), ("Infinity", np.isposinf(x)),
                                  ("-Infinity", np.isneginf(x)))}
            bad = {k: v for k, v in bad.items() if v}
            if bad:
                nonfinite[name] = bad
        cols[name] = _clean(col.to_pylist())
    out: dict[str, Any] = {"columns": cols, "rows": table.num_rows}
    if nonfinite:
        out["nonfinite"] = nonfinite
    info = (table.schema.metadata or {}).get(_DERIVED_KEY)
    if info is not None:
        out["derived_info"] = info.decode("utf-8", "replace")
    return out


def table_from_json(obj: dict[str, Any] | None, name: str) -> pa.Table | None:
    """Inverse of :func:`table_to_json`, conformed to the format's declared types."""
    if not obj:
        return None
    from aveas_format.io.arrow import conform
    from aveas_format.schema.tables import TABLES

    spec = TABLES[name]
    nonfinite = obj.get("nonfinite") or {}
    arrays = {}
    for cname, vals in (obj.get("columns") or {}).items():
        fix = nonfinite.get(cname)
        if fix:
            vals = list(vals)
            for key, rows in fix.items():
                for i in rows:
                    if 0 <= int(i) < len(vals):
                        vals[int(i)] = _NONFINITE.get(key, math.nan)
        if any(isinstance(v, dict) and set(v) == {"base64"} for v in vals if v is not None):
            arrays[cname] = pa.array([None if v is None else base64.b64decode(v["base64"])
                                      for v in vals], pa.binary())
        else:
            try:
                arrays[cname] = pa.array(vals)
            except (pa.ArrowInvalid, pa.ArrowTypeError):
                arrays[cname] = pa.array([None if v is None else json.dumps(v) for v in vals])
    if not arrays:
        return None
    n = int(obj.get("rows", len(next(iter(arrays.values())))))
    arrays = {k: (v if len(v) == n else pa.nulls(n)) for k, v in arrays.items()}
    table = conform(pa.table(arrays), spec)
    info = obj.get("derived_info")
    if isinstance(info, str):
        md = dict(table.schema.metadata or {})
        md[_DERIVED_KEY] = info.encode()
        table = table.replace_schema_metadata(md)
    return table


def _iso_ms(ts: str) -> str:
    """recording start_time -> the profile's yyyy-MM-ddTHH:mm:ss.FFFZ."""
    m = re.match(r"^(\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2})(?:\.(\d+))?Z$", ts)
    if not m:
        return ts
    return f"{m[1]}.{(m[2] or '').ljust(3, '0')[:3]}Z"


def _to_utc(ts: str) -> str:
    """Any ISO 8601 timestamp (with offset) -> UTC ``...Z`` keeping the fraction digits."""
    s = ts.strip()
    m = re.match(r"^(\d{4}-\d{2}-\d{2})[T ](\d{2}:\d{2}:\d{2})(?:\.(\d{1,9}))?(Z|[+-]\d{2}(?::?\d{2})?)?$", s)
    if not m:
        raise FormatError(f"acquisition_date {ts!r} is not an ISO 8601 timestamp")
    date, hms, frac, tz = m.groups()
    tz = tz or "Z"
    if tz in ("Z", "+00", "+0000", "+00:00", "-00:00"):
        return f"{date}T{hms}{'.' + frac if frac else ''}Z"
    if len(tz) == 3:
        tz += ":00"
    elif ":" not in tz:
        tz = tz[:3] + ":" + tz[3:]
    dt = datetime.fromisoformat(f"{date}T{hms}{tz}").astimezone(timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + (f".{frac}" if frac else "") + "Z"


def _enum_value(v: Any) -> Any:
    """aveas-openlabel writes str enums as ``"Road__ClassificationValue.STRAIGHT"``: -> "straight"."""
    if isinstance(v, str) and "." in v:
        head, tail = v.split(".", 1)
        if head.endswith("Value") and re.fullmatch(r"[A-Z0-9_]+", tail):
            return tail.lower()
    return v


def _beaufort(speed: float) -> int:
    return int(np.searchsorted(np.asarray(_BEAUFORT), speed, side="right"))


def _beaufort_speed(force: float) -> float:
    edges = (0.0,) + _BEAUFORT + (36.0,)
    k = int(min(max(round(force), 0), 12))
    return round(0.5 * (edges[k] + edges[k + 1]), 2)


def _rot_body(vx: np.ndarray, vy: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World -> vehicle frame (x forward, y left)."""
    c, s = np.cos(h), np.sin(h)
    return c * vx + s * vy, -s * vx + c * vy


def _rot_world(u: np.ndarray, v: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(h), np.sin(h)
    return c * u - s * v, s * u + c * v


def _body_std(sx: np.ndarray, sy: np.ndarray, corr: np.ndarray | None, h: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """1-sigma of the vehicle-frame components of a world-frame Gaussian vector."""
    r = np.zeros_like(sx) if corr is None else np.nan_to_num(corr)
    c, s = np.cos(h), np.sin(h)
    cxy = r * sx * sy
    vu = c * c * sx * sx + s * s * sy * sy + 2 * c * s * cxy
    vv = s * s * sx * sx + c * c * sy * sy - 2 * c * s * cxy
    return np.sqrt(np.maximum(vu, 0)), np.sqrt(np.maximum(vv, 0))


def _col(table: pa.Table, name: str, dtype=np.float64) -> np.ndarray | None:
    if table is None or name not in table.column_names:
        return None
    from aveas_format.io.arrow import column_numpy

    return column_numpy(table, name, dtype)


def _pylist(table: pa.Table, name: str) -> list | None:
    if table is None or name not in table.column_names:
        return None
    col = table.column(name)
    if pa.types.is_dictionary(col.type):
        col = col.cast(col.type.value_type)
    return col.to_pylist()


def _intervals(frames: np.ndarray) -> list[dict[str, int]]:
    """Sorted frame numbers -> contiguous frame intervals."""
    if len(frames) == 0:
        return []
    f = np.unique(frames)
    breaks = np.flatnonzero(np.diff(f) != 1)
    starts = np.r_[f[0], f[breaks + 1]]
    ends = np.r_[f[breaks], f[-1]]
    return [{"frame_start": int(a), "frame_end": int(b)} for a, b in zip(starts, ends)]


# ================================================================================================
# map facts for the profile's road attributes
# ================================================================================================

def _road_facts(net, road_id: list, s: np.ndarray, lane_id: np.ndarray, lane_offset: np.ndarray
                ) -> dict[str, np.ndarray] | None:
    """Per sample: lane_position, lanes left/right (physical, legal), classification.

    Best effort: None where the map engine cannot answer (never fails the export)."""
    try:
        n = len(s)
        lanes = net.lanes
        rid = np.asarray(road_id, dtype=object)
        out = {"lane_position": np.full(n, np.nan), "left_phys": np.zeros(n, int),
               "left_legal": np.zeros(n, int), "right_phys": np.zeros(n, int),
               "right_legal": np.zeros(n, int), "classification": np.full(n, "straight", object)}
        for r in set(rid.tolist()):
            m = np.flatnonzero(rid == r)
            ss = s[m]
            inner, outer = net.lane_borders(r, ss, lane_id[m])
            width = np.abs(outer - inner)
            with np.errstate(invalid="ignore", divide="ignore"):
                out["lane_position"][m] = np.clip(lane_offset[m] / width, -0.5, 0.5)
            ri = net._road_index_of(r)
            ri = np.broadcast_to(np.asarray(ri), ss.shape)
            sc = np.clip(ss, 0.0, net._road_length[ri])
            piece = lanes.find_piece(ri, sc)
            b = lanes.borders(piece, sc)
            for side, outers, ids, types in (("left", b.left, lanes.lid[piece], lanes.ltype[piece]),
                                             ("right", b.right, lanes.rid[piece], lanes.rtype[piece])):
                inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
                present = (ids != 0) & (np.abs(outers - inners) > 0.01)
                drivable = present & (types >= 0) & net._drivable_code[np.where(types >= 0, types, 0)]
                out[f"{side}_phys"][m] = present.sum(1)
                out[f"{side}_legal"][m] = drivable.sum(1)
            _, _, _, kappa = net.reference_line(r, sc)
            road = net.roads.get(r) if hasattr(net.roads, "get") else None
            junction = str(getattr(road, "junction", "-1")) if road is not None else "-1"
            if junction not in ("-1", "", "None"):
                out["classification"][m] = "x_intersection"
            else:
                out["classification"][m] = np.where(np.abs(kappa) > 1e-3, "curve", "straight")
        return out
    except Exception:  # noqa: BLE001 — optional attributes; the map engine may not support them
        return None


# ================================================================================================
# export
# ================================================================================================

class OpenLabelExportOptions(ConverterOptions):
    map_file: str | None = None
    """File name of the map written next to the output and named in ``metadata.opendrive``
    (default: the output's name with ``.xodr``)."""
    write_map: bool = True
    """Write the map next to the output."""
    extension: bool = True
    """Write the ``aveas_format`` extension (needed for a lossless import; turn off for a
    profile-only file)."""
    road_attributes: bool = True
    """Compute ``road/classification`` and ``road/number_lanes/*`` from the map."""
    indent: int | None = None
    """JSON indentation (default: compact)."""


def recording_to_openlabel(rec, *, opendrive: str = "map.xodr", extension: bool = True,
                           road_attributes: bool = True) -> dict[str, Any]:
    """The OpenLABEL document (a dict with the root key ``openlabel``) of a recording."""
    with _no_gc():
        return _recording_to_openlabel(rec, opendrive, extension, road_attributes)


class _no_gc:
    """Pause the cyclic garbage collector while building or walking millions of small dicts
    (it otherwise runs again and again over the growing, acyclic document)."""

    def __enter__(self):
        import gc

        self._was = gc.isenabled()
        gc.disable()

    def __exit__(self, *exc):
        import gc

        if self._was:
            gc.enable()


def _recording_to_openlabel(rec, opendrive: str, extension: bool, road_attributes: bool) -> dict[str, Any]:
    meta = rec.meta
    p = rec.participants
    s = rec.states
    thr = meta.thresholds.model_dump() if meta.thresholds else {}
    thr_out = {k: (thr.get(k) or v) for k, v in _DEFAULT_THRESHOLDS.items()}
    metadata: dict[str, Any] = {
        "schema_version": "1.0.0",
        "name": meta.title or meta.recording_id,
        "annotator": meta.acquisition.partner,
        "comment": f"written by aveas-format from recording {meta.recording_id}",
        "aveas_schema_version": "0.4.17",
        "right_of_use": meta.rights.right_of_use.value,
        "acquisition_method": METHOD_TO_PROFILE[meta.acquisition.method.value],
        "acquisition_partner": meta.acquisition.partner,
        "acquisition_date": _iso_ms(meta.start_time),
        "opendrive": opendrive,
        "projection_string": meta.crs,
        "threshold_gttc": float(thr_out["ttc_s"]),
        "threshold_pret": float(thr_out["pet_s"]),
        "threshold_thw": float(thr_out["thw_s"]),
    }
    doc: dict[str, Any] = {"metadata": metadata}

    # ---- frames: one per distinct time --------------------------------------------------------
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    times, frame_of_row = np.unique(t, return_inverse=True)
    n = s.num_rows
    part_ids = p.column("participant_id").to_numpy()
    classes = _pylist(p, "class")
    cls_of = dict(zip(part_ids.tolist(), classes))
    length = dict(zip(part_ids.tolist(), _col(p, "length").tolist()))
    width = dict(zip(part_ids.tolist(), _col(p, "width").tolist()))
    hcol = _col(p, "height")
    height = dict(zip(part_ids.tolist(), (hcol if hcol is not None else np.full(len(part_ids), np.nan)).tolist()))

    x = _col(s, "x")
    y = _col(s, "y")
    h = _col(s, "heading")
    z = _col(s, "z")
    vx, vy = _col(s, "vx"), _col(s, "vy")
    vu, vv = _rot_body(vx, vy, h)
    ax, ay = _col(s, "ax"), _col(s, "ay")
    if ax is None or ay is None:
        kin = rec.derived.get("kinematics") if rec.derived else None
        a_est = None
        if kin is not None and kin.num_rows == n:
            a_est = (_col(kin, "ax"), _col(kin, "ay"))
        if a_est is None:
            from aveas_format.mapref.build import velocity_from_positions

            a_est = velocity_from_positions(pid, t, vx, vy)
        ax_w = np.nan_to_num(a_est[0]) if ax is None else ax
        ay_w = np.nan_to_num(a_est[1]) if ay is None else ay
    else:
        ax_w, ay_w = ax, ay
    au, av = _rot_body(np.nan_to_num(ax_w), np.nan_to_num(ay_w), h)
    yaw_rate = _col(s, "yaw_rate")
    stds = {c: _col(s, c) for c in ("x_std", "y_std", "z_std", "heading_std", "vx_std", "vy_std",
                                     "ax_std", "ay_std", "yaw_rate_std")}
    vxvy = _col(s, "vxvy_corr")
    axay = _col(s, "axay_corr")
    road_id = _pylist(s, "road_id") or [None] * n
    lane_id = _col(s, "lane_id")
    road_s = _col(s, "road_s")
    road_t = _col(s, "road_t")
    lane_offset = _col(s, "lane_offset")
    lights = {c: _col(s, c) for c in LIGHTS if c in s.column_names}

    on = np.array([r is not None for r in road_id], dtype=bool) & np.isfinite(
        road_s if road_s is not None else np.full(n, np.nan))
    facts = None
    if road_attributes and on.any():
        idx = np.flatnonzero(on)
        lid = np.nan_to_num(lane_id[idx]).astype(int) if lane_id is not None else np.zeros(len(idx), int)
        lo = lane_offset[idx] if lane_offset is not None else np.full(len(idx), np.nan)
        f = _road_facts(rec.map, [road_id[i] for i in idx], road_s[idx], lid, lo)
        if f is not None:
            facts = {k: np.empty(n, dtype=v.dtype) for k, v in f.items()}
            for k, v in f.items():
                facts[k][idx] = v

    # interior signals by row
    interior_rows: dict[tuple[int, float], dict[str, Any]] = {}
    if rec.interior is not None and rec.interior.num_rows:
        it = rec.interior
        ipid = it.column("participant_id").to_pylist()
        itime = it.column("time").to_pylist()
        icols = {c: _pylist(it, c) for c in ("steering_angle", "steering_angle_std", "brake_pedal",
                                              "accelerator_pedal", "gear", "automation_longitudinal_p",
                                              "automation_lateral_p") if c in it.column_names}
        for k in range(it.num_rows):
            interior_rows[(ipid[k], itime[k])] = {c: v[k] for c, v in icols.items()}

    # impact attributes from derived tables
    impact: dict[tuple[int, float], dict[str, list]] = defaultdict(lambda: defaultdict(list))
    inter = rec.derived.get("interactions") if rec.derived else None
    if inter is not None and inter.num_rows:
        ip, it_, io = (inter.column(c).to_pylist() for c in ("participant_id", "time", "other_id"))
        for metric, thr_key in (("ttc", "ttc_s"), ("thw", "thw_s")):
            if metric not in inter.column_names:
                continue
            vals = inter.column(metric).to_pylist()
            for k, v in enumerate(vals):
                if v is not None and v < thr_out[thr_key]:
                    key = "gttc" if metric == "ttc" else "thw"
                    impact[(ip[k], it_[k])][f"{key}/object_ids"].append(str(io[k]))
                    impact[(ip[k], it_[k])][f"{key}/values"].append(float(v))
    enc = rec.derived.get("encroachments") if rec.derived else None
    if enc is not None and enc.num_rows:
        for r in enc.select(["first_id", "second_id", "time_second_enter", "pet"]).to_pylist():
            if r["pet"] is None or r["pet"] >= thr_out["pet_s"] or r["time_second_enter"] is None:
                continue
            k = int(np.clip(np.searchsorted(times, r["time_second_enter"]), 0, len(times) - 1))
            key = (r["second_id"], float(times[k]))
            impact[key]["pret/object_ids"].append(str(r["first_id"]))
            impact[key]["pret/values"].append(float(r["pet"]))

    # extension columns of states
    ext_cols = [c for c in s.column_names if c not in _PROFILE_STATE_COLS]
    ext_vals = {c: _pylist(s, c) for c in ext_cols}
    nullable = [c for c in ("z", "z_std", "x_std", "y_std", "heading_std", "ax", "ay", "yaw_rate")
                if c in s.column_names]
    null_of = {c: s.column(c).is_null().to_numpy(zero_copy_only=False) for c in nullable}
    null_ofl = {c: v.tolist() for c, v in null_of.items()}
    # values the importer rebuilds with rounding (vehicle -> world frame, box centre -> ground):
    # the exact value goes into the extension where the rebuilt one would differ in any bit, so
    # that an unchanged round trip hashes the same (and derived tables stay fresh)
    exact: dict[str, list] = {}
    if extension and n:
        from aveas_format.numeric import wrap_angle

        hw = wrap_angle(h)
        back = dict(zip(("vx", "vy"), _rot_world(vu, vv, hw)))
        if ax is not None and ay is not None:
            back.update(zip(("ax", "ay"), _rot_world(au, av, hw)))
        if z is not None:
            hv = np.asarray([height[q] for q in pid.tolist()], float)
            hv = np.where(np.isfinite(hv), hv, 0.0)
            back["z"] = (np.where(np.isfinite(z), z, 0.0) + hv / 2) - hv / 2
        for c, b in back.items():
            orig = _col(s, c)
            off = np.isfinite(orig) & (b != orig)
            if off.any():
                exact[c] = np.where(off, orig, np.nan).tolist()

    # uncertainty attributes, vectorised (lists of Python floats per row)
    def _z(a):
        return np.zeros(n) if a is None else np.nan_to_num(a)

    box_std = vel_std = acc_std = None
    if any(stds[c] is not None for c in ("x_std", "y_std", "heading_std")):
        zero = np.zeros(n)
        box_std = np.column_stack([_z(stds["x_std"]), _z(stds["y_std"]), _z(stds["z_std"]), zero, zero,
                                   _z(stds["heading_std"])]).tolist()
    size_std = {}
    for j, q in enumerate(part_ids.tolist()):
        size_std[q] = [float(v) if v is not None else 0.0 for v in (
            (p.column(c)[j].as_py() if c in p.column_names else None)
            for c in ("length_std", "width_std", "height_std"))]
    vel_ok = acc_ok = np.zeros(n, bool)
    if stds["vx_std"] is not None and stds["vy_std"] is not None:
        vel_ok = np.isfinite(stds["vx_std"]) & np.isfinite(stds["vy_std"])
        su, sv = _body_std(_z(stds["vx_std"]), _z(stds["vy_std"]), vxvy, h)
        zero = np.zeros(n)
        vel_std = np.column_stack([su, sv, zero, zero, zero, _z(stds["yaw_rate_std"])]).tolist()
    if stds["ax_std"] is not None and stds["ay_std"] is not None:
        acc_ok = np.isfinite(stds["ax_std"]) & np.isfinite(stds["ay_std"])
        su, sv = _body_std(_z(stds["ax_std"]), _z(stds["ay_std"]), axay, h)
        zero = np.zeros(n)
        acc_std = np.column_stack([su, sv, zero, zero, zero, zero]).tolist()
    xl, yl, hl = x.tolist(), y.tolist(), h.tolist()
    onl = on.tolist()
    lane_idl = lane_id.tolist() if lane_id is not None else None
    road_sl = road_s.tolist() if road_s is not None else None
    road_tl = road_t.tolist() if road_t is not None else None
    lightl = {c: a.tolist() for c, a in lights.items()}
    zl = z.tolist() if z is not None else None
    vul, vvl, aul, avl = vu.tolist(), vv.tolist(), au.tolist(), av.tolist()
    yrl = yaw_rate.tolist() if yaw_rate is not None else None
    pidl, tl, fl = pid.tolist(), t.tolist(), frame_of_row.tolist()

    frames: dict[str, dict[str, Any]] = {}
    for k, tv in enumerate(times):
        frames[str(k)] = {"frame_properties": {"timestamp": float(tv)}, "objects": {}}
    for i in range(n):
        q = pidl[i]
        cls = cls_of[q]
        hh = height[q]
        zc = (0.0 if zl is None or not _finite(zl[i]) else zl[i]) + (0.0 if not _finite(hh) else hh / 2)
        cuboid: dict[str, Any] = {"name": "bounding_box", "val": [
            xl[i], yl[i], zc, 0.0, 0.0, hl[i], length[q], width[q], hh if _finite(hh) else 0.0]}
        yr = yrl[i] if yrl is not None and _finite(yrl[i]) else 0.0
        vec: list[dict[str, Any]] = [
            {"name": "velocity", "val": [vul[i], vvl[i], 0.0, 0.0, 0.0, yr]},
            {"name": "acceleration", "val": [aul[i], avl[i], 0.0, 0.0, 0.0, 0.0]},
        ]
        num: list[dict[str, Any]] = []
        text: list[dict[str, Any]] = []
        boolean: list[dict[str, Any]] = []
        if box_std is not None:
            vec.append({"name": "bounding_box/ustddev", "val": box_std[i] + size_std[q]})
        if vel_std is not None and vel_ok[i]:
            vec.append({"name": "velocity/ustddev", "val": vel_std[i]})
        if acc_std is not None and acc_ok[i]:
            vec.append({"name": "acceleration/ustddev", "val": acc_std[i]})
        if onl[i]:
            text.append({"name": "used_road_link", "val": str(road_id[i])})
            if lane_idl is not None and _finite(lane_idl[i]):
                text.append({"name": "open_drive/lane_id", "val": str(int(lane_idl[i]))})
            vec.append({"name": "open_drive/local_road_coordinates",
                        "val": [road_sl[i], road_tl[i]]})
            if facts is not None:
                lp = facts["lane_position"][i]
                if _finite(lp):
                    num.append({"name": "open_drive/lane_position", "val": _f(lp)})
                if cls in _ROAD_CLASSES:
                    text.append({"name": "road/classification", "val": str(facts["classification"][i])})
                    for side in ("left", "right"):
                        num.append({"name": f"road/number_lanes/{side}/legal",
                                    "val": int(facts[f"{side}_legal"][i])})
                        num.append({"name": f"road/number_lanes/{side}/physical",
                                    "val": int(facts[f"{side}_phys"][i])})
        for c, name in LIGHTS.items():
            a = lightl.get(c)
            if a is not None and _finite(a[i]):
                boolean.append({"name": name, "val": bool(a[i] >= 0.5)})
        irow = interior_rows.get((q, tl[i])) if interior_rows else None
        if irow:
            for c, name in (("automation_longitudinal_p", _LONGITUDINAL),
                            # the profile's lateral flag carries the longitudinal name (quirk)
                            ("automation_lateral_p", _LONGITUDINAL)):
                if irow.get(c) is not None:
                    boolean.append({"name": name, "val": bool(irow[c] >= 0.5)})
            for c, name in (("steering_angle", "interior/steering_angle"),
                            ("steering_angle_std", "interior/steering_angle/ustddev"),
                            ("brake_pedal", "interior/brake_pedal"),
                            ("accelerator_pedal", "interior/accelerator_pedal"),
                            ("gear", "interior/gear")):
                if irow.get(c) is not None:
                    num.append({"name": name, "val": irow[c] if c == "gear" else float(irow[c])})
        imp = impact.get((q, tl[i])) if impact else None
        if imp:
            for key in ("gttc", "pret", "thw"):
                if imp.get(f"{key}/values"):
                    vec.append({"name": f"impact/{key}/object_ids", "val": imp[f"{key}/object_ids"]})
                    vec.append({"name": f"impact/{key}/values", "val": imp[f"{key}/values"]})
        if extension:
            ext = {c: ext_vals[c][i] for c in ext_cols if ext_vals[c][i] is not None}
            for c in nullable:
                if null_ofl[c][i]:
                    ext[c] = None
            for c, vals in exact.items():
                if not math.isnan(vals[i]):
                    ext[c] = vals[i]
            if ext:
                cuboid[EXT] = _clean(ext)
        od: dict[str, Any] = {"cuboid": [cuboid], "vec": vec}
        od["boolean"] = boolean
        od["num"] = num
        od["text"] = text
        frames[str(fl[i])]["objects"][str(q)] = {"object_data": od}
    doc["frames"] = frames
    doc["frame_intervals"] = [{"frame_start": 0, "frame_end": int(len(times) - 1)}] if len(times) else []

    # ---- objects ---------------------------------------------------------------------------------
    speed = np.hypot(vx, vy)
    acc = np.hypot(np.nan_to_num(ax_w), np.nan_to_num(ay_w)) * np.sign(
        np.nan_to_num(ax_w) * np.cos(h) + np.nan_to_num(ay_w) * np.sin(h))
    order = np.argsort(pid, kind="stable")
    bounds = np.searchsorted(pid[order], part_ids), np.searchsorted(pid[order], part_ids, side="right")
    pmf = None
    if "class_pmf" in p.column_names:
        from aveas_format.io.arrow import pmf_matrix

        pmf = pmf_matrix(p.column("class_pmf"), "class")
    source_ids = _pylist(p, "source_id")
    roles = _pylist(p, "role") or ["observed"] * p.num_rows
    attached = _pylist(p, "attached_to")
    p_ext_cols = [c for c in p.column_names if c not in _PROFILE_PART_COLS]
    p_ext_vals = {c: _pylist(p, c) for c in p_ext_cols}
    objects: dict[str, Any] = {}
    for j, q in enumerate(part_ids.tolist()):
        cls = classes[j]
        rows = order[bounds[0][j]:bounds[1][j]]
        hh = height[q]
        size = {"name": "dimensions/size", "val": [_f(length[q]), _f(width[q]), _f(hh) if _finite(hh) else 0.0]}
        vec = [size]
        if any(c in p.column_names for c in ("length_std", "width_std")):
            vec.append({"name": "dimensions/size/ustddev",
                        "val": [_part_std(p, q, c) for c in ("length_std", "width_std", "height_std")]})
        if pmf is not None and np.isfinite(pmf[j]).all():
            w = pmf[j].astype(np.float64)
            w = w / w.sum()
            vec.append({"name": "classification/uncertainties", "val": [float(v) for v in w]})
        num = []
        if len(rows):
            num += [{"name": "summary/speed/max", "val": _f(speed[rows].max())},
                    {"name": "summary/speed/min", "val": _f(speed[rows].min())},
                    {"name": "summary/accel/max", "val": _f(acc[rows].max()), "type": "value"},
                    {"name": "summary/accel/min", "val": _f(acc[rows].min()), "type": "value"}]
        obj_data: dict[str, Any] = {"vec": vec, "num": num, "text": [], "boolean": []}
        if cls not in _NO_RECORDER:
            obj_data["boolean"].append({"name": "is_recorder", "val": roles[j] == "recording_vehicle"})
        if attached is not None and attached[j] is not None:
            obj_data["text"].append({"name": "attached_to", "val": str(attached[j])})
        if extension:
            ext = {"participant_id": q, "class": cls}
            for c in p_ext_cols:
                if p_ext_vals[c][j] is not None:
                    ext[c] = p_ext_vals[c][j]
            for c in ("height", "length_std", "width_std", "height_std", "class_pmf"):
                if c in p.column_names and p.column(c)[j].as_py() is None:
                    ext[c] = None
            if pmf is not None and np.isfinite(pmf[j]).all():
                ext["class_pmf"] = [float(v) for v in pmf[j]]
            size[EXT] = _clean(ext)
        objects[str(q)] = {
            "name": str(source_ids[j]) if source_ids else str(q),
            "type": CLASS_TO_TYPE[cls],
            "frame_intervals": _intervals(frame_of_row[rows]),
            "object_data": obj_data,
        }
    doc["objects"] = objects

    # ---- contexts ---------------------------------------------------------------------------------
    doc["contexts"] = _contexts(rec, times, speed)

    # ---- events ---------------------------------------------------------------------------------
    events = {}
    if rec.events is not None and rec.events.num_rows:
        for r in rec.events.to_pylist():
            etype = EVENT_TO_TYPE.get(str(r["kind"]))
            ids = r["participant_ids"] or []
            if etype is None or not ids:
                continue
            fs = int(np.clip(np.searchsorted(times, r["time_start"] - 1e-9), 0, max(len(times) - 1, 0)))
            fe = int(np.clip(np.searchsorted(times, r["time_end"] + 1e-9) - 1, fs, max(len(times) - 1, 0)))
            events[str(r["event_id"])] = {
                "name": f"{etype}{r['event_id']}", "type": etype,
                "frame_intervals": [{"frame_start": fs, "frame_end": fe}],
                "event_data": {
                    "text": [{"name": "event_participant/role_a_id", "val": str(ids[0]), "type": "value"}],
                    "vec": [{"name": "event_participants/role_b_ids", "val": [str(v) for v in ids[1:]],
                             "type": "values"}],
                },
            }
    if events:
        doc["events"] = events

    if extension:
        md = meta.model_dump(mode="json", exclude_none=True)
        for k in ("tables", "derived", "map", "source"):
            md.pop(k, None)
        metadata[EXT] = _clean({
            "version": EXT_VERSION,
            "frame_timestamps": "seconds since acquisition_date",
            "start_time": meta.start_time,
            "recording": md,
            "map": meta.map.model_dump(mode="json"),
            "thresholds_given": sorted(k for k, v in thr.items() if v is not None),
            "states_columns": s.column_names,
            "participants_columns": p.column_names,
            "tables": {name: table_to_json(getattr(rec, name)) for name in
                       ("unobserved", "events", "environment", "interior")
                       if getattr(rec, name) is not None},
            # derived tables (columnar) and their recording.json ``derived`` entries
            "derived": {name: table_to_json(t) for name, t in sorted((rec.derived or {}).items())
                        if t is not None},
            "derived_entries": [e.model_dump(mode="json", exclude_none=True) for e in meta.derived],
        })
    return {"openlabel": doc}


def _part_std(p: pa.Table, q: int, c: str) -> float:
    if c not in p.column_names:
        return 0.0
    ids = p.column("participant_id").to_numpy()
    j = int(np.flatnonzero(ids == q)[0])
    v = p.column(c)[j].as_py()
    return float(v) if v is not None else 0.0


def _pmf_vector(pmf: dict | None, cats: tuple[str, ...], mapping: dict[str, str],
                out_cats: tuple[str, ...]) -> list[float] | None:
    if not pmf:
        return None
    vals = dict.fromkeys(out_cats, 0.0)
    for c in cats:
        vals[mapping[c]] += float(pmf.get(c, 0.0) or 0.0)
    tot = sum(vals.values())
    return [v / tot for v in vals.values()] if tot > 0 else None


def _environment_data(cond: dict[str, Any]) -> dict[str, list]:
    data: dict[str, list] = {"num": [], "text": [], "vec": []}
    lighting = _pmf_vector(cond.get("lighting"), LIGHTING, LIGHTING_TO_PROFILE, PROFILE_LIGHTING)
    if lighting:
        data["text"].append({"name": "lighting_conditions",
                             "val": PROFILE_LIGHTING[int(np.argmax(lighting))]})
        data["vec"].append({"name": "environment/lighting_conditions/uncertainties", "val": lighting})
    road = _pmf_vector(cond.get("road_surface"), ROAD_SURFACE,
                       {"dry": "dry", "wet": "wet", "slippery": "slippery", "snow_ice": "slippery"},
                       PROFILE_ROAD)
    if road:
        data["text"].append({"name": "road_condition", "val": PROFILE_ROAD[int(np.argmax(road))]})
        data["vec"].append({"name": "environment/road_condition/uncertainties", "val": road})
    if cond.get("temperature_c") is not None:
        data["num"].append({"name": "environment/temperature_celsius", "val": int(round(cond["temperature_c"]))})
    if cond.get("temperature_c_std") is not None:
        data["num"].append({"name": "environment/temperature/ustddev", "val": float(cond["temperature_c_std"])})
    if cond.get("precipitation_mm_h") is not None:
        data["num"].append({"name": "environment/precipitation_intensity",
                            "val": int(round(cond["precipitation_mm_h"]))})
    if cond.get("visibility_m") is not None:
        data["num"].append({"name": "environment/visibility_range", "val": int(round(cond["visibility_m"]))})
    if cond.get("cloud_cover_okta") is not None:
        data["num"].append({"name": "environment/cloud_cover", "val": int(cond["cloud_cover_okta"])})
    if cond.get("wind_speed_m_s") is not None:
        data["num"].append({"name": "environment/wind/beaufort_force", "val": _beaufort(cond["wind_speed_m_s"])})
    return data


def _contexts(rec, times: np.ndarray, speed: np.ndarray) -> dict[str, Any]:
    meta = rec.meta
    out: dict[str, Any] = {}
    site = meta.acquisition.site
    rt = site.road_type.value if site and site.road_type else None
    prov = meta.provenance.value
    staged = prov == "staged" or (prov == "mixed" and "staged" in (_pylist(rec.participants, "provenance") or []))
    boolean = [{"name": "scenario/is_staged", "val": bool(staged)}]
    if rt:
        boolean += [{"name": "scenario/contains_highway", "val": rt in ("motorway", "mixed")},
                    {"name": "scenario/contains_urban", "val": rt in ("urban", "parking", "mixed")},
                    {"name": "scenario/contains_rural", "val": rt in ("rural", "mixed")}]
    num = []
    if len(speed):
        moving = speed[speed > 0]
        num.append({"name": "scenario/maximum_vehicle_speed", "val": float(speed.max())})
        if len(moving):
            num.append({"name": "scenario/minimum_vehicle_speed", "val": float(moving.min())})
    from aveas_format.schema.metadata import timestamp_ns

    wd = datetime.fromtimestamp(timestamp_ns(meta.start_time) / 1e9, tz=timezone.utc).isoweekday()
    num.append({"name": "scenario/weekday_number", "val": int(wd)})
    vec = [{"name": "scenario/course", "val": [site.name]}] if site else []
    out["0"] = {"name": "scenario_context", "type": "ScenarioContext",
                       "context_data": {"boolean": boolean, "num": num, "text": [], "vec": vec}}
    if meta.conditions is not None:
        out["1"] = {"name": "environment_context", "type": "EnvironmentContext",
                              "context_data": _environment_data(meta.conditions.model_dump())}
    env = rec.environment
    if env is not None and env.num_rows and len(times):
        for k, r in enumerate(env.to_pylist()):
            fs = int(np.clip(np.searchsorted(times, r["time_start"] - 1e-9), 0, len(times) - 1))
            fe = int(np.clip(np.searchsorted(times, r["time_end"] + 1e-9) - 1, fs, len(times) - 1))
            out[str(k + 2)] = {
                "name": "environment_context", "type": "EnvironmentContext",
                "frame_intervals": [{"frame_start": fs, "frame_end": fe}],
                "context_data": _environment_data(r)}
    return out


@converter("openlabel", direction="export", options=OpenLabelExportOptions,
           description="ASAM OpenLABEL 1.0 JSON, AVEAS profile (+ the map as .xodr next to it)")
def export_openlabel(rec, output: Path, *, options: OpenLabelExportOptions) -> list[Path]:
    from aveas_format.safeio import write_bytes_atomic

    output = Path(output)
    stem = output.name[:-5] if output.name.endswith(".json") else output.stem
    map_name = options.map_file or f"{stem}.xodr"
    doc = recording_to_openlabel(rec, opendrive=map_name, extension=options.extension,
                                 road_attributes=options.road_attributes)
    data = json.dumps(doc, indent=options.indent, allow_nan=False, separators=None if options.indent
                      else (",", ":")).encode()
    written = [write_bytes_atomic(output, data)]
    if options.write_map and rec.map_source is not None:
        written.append(write_bytes_atomic(output.parent / map_name, rec.map_source))
    return written


# ================================================================================================
# import
# ================================================================================================

class OpenLabelImportOptions(ImportOptions):
    world_crs: str | None = None
    """CRS (PROJ/EPSG) of the root coordinate system of generic files, e.g. EPSG:32630; default:
    read from a ``geo_utm`` root named like ``utm-30t``, else the root is the map frame."""
    method: str | None = None
    """Acquisition method (default: from ``acquisition_method``; ``road_vehicle`` where a generic
    file has an ego object, else ``infrastructure_camera``)."""
    rate_hz: float = 10.0
    """Frame rate of files without frame timestamps."""
    road_coordinates: str = "auto"
    """``file`` (take the file's road coordinates), ``map`` (compute them through the map) or
    ``auto`` (the file's where it has them, else the map's)."""
    provenance: str | None = None
    """natural / staged / simulated (default: from the file; ``staged`` where the scenario
    context says so, else natural)."""


def _load_doc(path: Path) -> dict[str, Any]:
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    doc = load_json(raw, path=path, max_bytes=MAX_BULK_JSON_BYTES)
    if not isinstance(doc, dict) or not isinstance(doc.get("openlabel"), dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    return doc["openlabel"]


class _NotStrictJSON(Exception):
    """The file uses Python's JSON extensions (NaN, Infinity), which ``json.loads`` reads and the
    streaming parser refuses: read it whole instead (as before the import streamed)."""


def _stream_error(e: Exception, path: Path, consumed: int) -> Exception:
    arg = e.args[0] if e.args else ""
    msg = arg.decode("utf-8", "replace") if isinstance(arg, bytes) else str(arg)
    if "invalid char" in msg and re.search(r"NaN|Infinity", msg):
        return _NotStrictJSON()
    return stream_json_error(e, path=path, consumed=consumed)


def _check_stream(path: Path) -> None:
    """Parse the whole file without building anything: the file's JSON error, if it has one."""
    import ijson

    with open(path, "rb") as f:
        r = CountingReader(f)
        try:
            for _ in ijson.basic_parse(r, use_float=True):
                pass
        except ijson.JSONError as e:
            raise _stream_error(e, path, r.pos) from None


def _stream_doc(path: Path):
    """Open an OpenLABEL file for a streamed import: ``(ol, frames)`` with ``ol`` the object under
    ``openlabel`` without its frames (read whole: metadata, objects, coordinate systems, ...) and
    ``frames`` a function that yields ``(frame key, frame)`` one at a time in file order (ijson);
    ``frames`` is None where the file was read whole (no frames object, or a file the structural
    pre-scan does not take: then :func:`_load_doc`, the same limits and errors).

    The size limit is checked before reading; the nesting limit on the structural pre-scan
    (:func:`aveas_format.safeio.scan_json_member`, which also finds the byte range of the frames).
    Broken JSON and non-UTF-8 text give a :class:`FormatError` naming the file."""
    import ijson

    check_json_size(path, max_bytes=MAX_BULK_JSON_BYTES)
    try:
        f = open(path, "rb")  # noqa: SIM115 - closed below
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e.strerror or e}", path=path) from None
    with f:
        head = f.read(4096).lstrip(b" \t\r\n")
        if not head.startswith(b"{"):  # empty, a BOM, UTF-16/32, not an object: read it whole
            return _load_doc(path), None
        depth, span, ok = scan_json_member(f, "openlabel", "frames")
    if not ok:  # broken (e.g. truncated: refused here in bounded memory) or a member repeats
        _check_stream(path)
    if not ok or depth == MAX_JSON_DEPTH:  # (at the limit: the exact check of load_json decides)
        return _load_doc(path), None
    if depth > MAX_JSON_DEPTH:
        raise FormatError(f"JSON nested deeper than {MAX_JSON_DEPTH} levels", path=path)
    with open(path, "rb") as f:
        r = CountingReader(f, (span[0], span[1], b"{}") if span else None)
        try:
            doc = dict(ijson.kvitems(r, "", use_float=True))
        except ijson.JSONError as e:
            raise _stream_error(e, path, r.pos) from None
    if not isinstance(doc.get("openlabel"), dict):
        raise FormatError("not an OpenLABEL file: no top-level 'openlabel' object", path=path)
    ol = doc["openlabel"]
    if span is None:
        return ol, None

    def frames():
        with open(path, "rb") as fr:
            rd = CountingReader(fr, start=span[0], stop=span[1])
            try:
                yield from ijson.kvitems(rd, "", use_float=True)
            except ijson.JSONError as e:
                raise _stream_error(e, path, rd.pos) from None

    return ol, frames


def _attrs(od: dict[str, Any] | None) -> dict[str, list[dict[str, Any]]]:
    """name -> list of items (all types), in file order."""
    out: dict[str, list] = defaultdict(list)
    for kind in ("boolean", "num", "text", "vec"):
        items = (od or {}).get(kind) or []
        if isinstance(items, dict):
            items = [items]
        for it in items:
            if isinstance(it, dict) and "name" in it:
                out[it["name"]].append(it)
    return out


def _first(attrs, name, default=None):
    items = attrs.get(name)
    return items[0].get("val", default) if items else default


# -- geometry of generic files -------------------------------------------------------------------

def _quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) or 1.0
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def _euler_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """ZYX (yaw, pitch, roll) — OpenLABEL's default sequence."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


def _axis_rotation(axis: str, angle: float) -> np.ndarray:
    c, s_ = math.cos(angle), math.sin(angle)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s_], [0, s_, c]])
    if axis == "Y":
        return np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
    return np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])


def _pose(tf: dict[str, Any] | list | None) -> np.ndarray | None:
    """A 4x4 matrix of an OpenLABEL pose/transform: ``matrix4x4`` (row-major), or ``quaternion``
    (x, y, z, w) / ``euler_angles`` (values in the order of ``sequence``, default ZYX, i.e.
    (rz, ry, rx)) with ``translation``."""
    if tf is None:
        return None
    if isinstance(tf, list):
        tf = {"matrix4x4": tf}
    m = np.eye(4)
    if tf.get("matrix4x4") is not None:
        return np.asarray(tf["matrix4x4"], float).reshape(4, 4)
    if tf.get("quaternion") is not None:
        m[:3, :3] = _quat_matrix(*tf["quaternion"])
    elif tf.get("euler_angles") is not None:
        seq = str(tf.get("sequence") or "ZYX").upper()
        R = np.eye(3)
        for axis, angle in zip(seq, tf["euler_angles"]):
            R = R @ _axis_rotation(axis, float(angle))
        m[:3, :3] = R
    if tf.get("translation") is not None:
        m[:3, 3] = np.asarray(tf["translation"], float)[:3]
    return m


class _Frames:
    """Chains coordinate systems to the root (static poses + per-frame transforms)."""

    def __init__(self, cs: dict[str, Any] | None) -> None:
        self.cs = cs or {}
        self.parent = {k: (v or {}).get("parent") or None for k, v in self.cs.items()}
        self.static = {k: _pose((v or {}).get("pose_wrt_parent")) for k, v in self.cs.items()}

    def root_of(self, name: str | None) -> str | None:
        seen = set()
        while name and self.parent.get(name) and name not in seen:
            seen.add(name)
            name = self.parent[name]
        return name

    def to_root(self, name: str | None, transforms: dict[str, Any] | None) -> np.ndarray:
        m = np.eye(4)
        if not name:
            return m
        tfs = {}
        for tf in (transforms or {}).values():
            if isinstance(tf, dict) and tf.get("src") and tf.get("dst"):
                tfs[(tf["src"], tf["dst"])] = _pose(tf.get("transform_src_to_dst"))
        seen = set()
        while name in self.parent and self.parent[name] and name not in seen:
            seen.add(name)
            par = self.parent[name]
            step = tfs.get((name, par))
            if step is None and (par, name) in tfs and tfs[(par, name)] is not None:
                step = np.linalg.inv(tfs[(par, name)])
            if step is None:
                step = self.static.get(name)
            if step is None:
                step = np.eye(4)
            m = step @ m
            name = par
        return m


def _utm_crs(name: str, cs_type: str | None) -> str | None:
    """EPSG code of a UTM coordinate system named like ``utm-30t`` / ``UTM32N`` (band letters C-M
    are southern, N-X northern; no letter = northern)."""
    mt = re.search(r"utm[-_ ]?(\d{1,2})\s*([c-xC-X])?(?![a-zA-Z])", name or "", re.I)
    if not mt:
        return None
    zone = int(mt[1])
    south = bool(mt[2]) and mt[2].upper() < "N"
    return f"EPSG:{32700 + zone if south else 32600 + zone}"


# -- the frames: one at a time into column chunks ------------------------------------------------

#: boxes per chunk of the column buffers (Python lists -> numpy arrays)
_CHUNK = 4096
_FLOAT_COLS = ("cub_ts", "px", "py", "pz", "yaw", "vu", "vv", "yr", "au", "av", "x_std", "y_std",
               "z_std", "heading_std", "vu_std", "vv_std", "yr_std", "au_std", "av_std", "road_s",
               "road_t", "lane_position", *LIGHTS)
_OBJ_COLS = ("csroot", "road_id", "lane_id")


def _as_obj(lst: list) -> np.ndarray:
    a = np.empty(len(lst), object)
    for i, v in enumerate(lst):
        a[i] = v
    return a


def _as_float(lst: list) -> np.ndarray:
    """float64 where every value converts (as ``np.asarray(values, float)`` would), else the values
    as an object array (converted, or refused with the same error, where the column is used)."""
    try:
        a = np.asarray(lst, float)
        if a.ndim == 1:
            return a
    except (TypeError, ValueError, OverflowError):
        pass
    return _as_obj(lst)


def _ext_rep(vals: list) -> tuple:
    """One extension column (values or ``_MISSING``): ``("f", values, present, null)`` where all
    present values are floats or null, else ``("o", object array)``."""
    n = len(vals)
    if all(v is _MISSING or v is None or type(v) is float for v in vals):
        return ("f", np.fromiter((v if type(v) is float else np.nan for v in vals), float, n),
                np.fromiter((v is not _MISSING for v in vals), bool, n),
                np.fromiter((v is None for v in vals), bool, n))
    return ("o", _as_obj(vals))


def _rep_list(rep: tuple) -> list:
    if rep[0] == "o":
        return rep[1].tolist()
    _, fv, pr, nl = rep
    return [(None if b else v) if p else _MISSING for v, p, b in zip(fv.tolist(), pr, nl)]


def _rep_take(rep: tuple, idx: np.ndarray) -> tuple:
    return (rep[0], *(a[idx] for a in rep[1:]))


def _rep_concat(reps: list[tuple]) -> tuple:
    if all(r[0] == "f" for r in reps):
        return ("f", *(np.concatenate([r[i] for r in reps]) for i in (1, 2, 3)))
    return ("o", np.concatenate([r[1] if r[0] == "o" else _as_obj(_rep_list(r)) for r in reps]))


class _FrameData:
    """What :class:`_FrameRows` collected, in sorted frame order."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


class _FrameRows:
    """The frames of an OpenLABEL file, one ``(key, frame)`` at a time in any order: per box the
    values of one state in column chunks (numpy), per frame its key, timestamp and object ids.
    :meth:`finish` sorts the rows by frame key (numerically where digits, as the dict path always
    did) and, where a key repeats, keeps the last frame of that key (as ``json.loads`` does)."""

    def __init__(self, objects: Any, cs: _Frames, path: Path | None) -> None:
        self.objects, self.cs, self.path = objects, cs, path
        self.keys: list = []  # per frame occurrence (file order)
        self.stamps: list = []
        self.frame_uids: list[np.ndarray] = []
        self.uid_index: dict[str, int] = {}
        self.buf: dict[str, list] = {c: [] for c in (*_FLOAT_COLS, *_OBJ_COLS, "uidx", "occ",
                                                     "hv", "hr")}
        self.ext_buf: list = []
        self.chunks: list[dict[str, np.ndarray]] = []
        self.ext_chunks: list[tuple[int, dict[str, tuple]]] = []
        self.sizes: list[tuple[int, str, list]] = []
        self.interior: list[tuple[int, str, dict]] = []
        self._need_size: dict[str, bool] = {}

    def _needs_size(self, u: str) -> bool:
        need = self._need_size.get(u)
        if need is None:
            try:
                obj = self.objects.get(u) or {}
                need = _first(_attrs(obj.get("object_data")), "dimensions/size") is None
            except Exception:  # noqa: BLE001 - a damaged object: keep the sizes (they are unused)
                need = True
            self._need_size[u] = need
        return need

    def _flush(self) -> None:
        b = self.buf
        if not b["occ"]:
            return
        ch = {c: _as_float(b[c]) for c in _FLOAT_COLS}
        ch.update({c: _as_obj(b[c]) for c in _OBJ_COLS})
        ch["uidx"] = np.asarray(b["uidx"], np.int64)
        ch["occ"] = np.asarray(b["occ"], np.int64)
        ch["hv"] = np.asarray(b["hv"], bool)
        ch["hr"] = np.asarray(b["hr"], bool)
        self.chunks.append(ch)
        es = self.ext_buf
        keys = dict.fromkeys(c for e in es if e for c in e)
        self.ext_chunks.append((len(es), {c: _ext_rep([e.get(c, _MISSING) if e else _MISSING
                                                       for e in es]) for c in keys}))
        for v in b.values():
            v.clear()
        self.ext_buf = []

    def add(self, k: Any, fr: Any) -> None:
        j = len(self.keys)
        fr = fr or {}
        ts = (fr.get("frame_properties") or {}).get("timestamp")
        if isinstance(ts, str):
            try:
                ts = float(ts)
            except ValueError:
                try:
                    from aveas_format.schema.metadata import timestamp_ns

                    ts = timestamp_ns(_to_utc(ts)) / 1e9
                except (ValueError, FormatError):
                    ts = None
        self.keys.append(k)
        self.stamps.append(ts)
        ui = self.uid_index
        fobjs = fr.get("objects") or {}
        self.frame_uids.append(np.fromiter((ui.setdefault(u, len(ui)) for u in fobjs), np.int64))
        cs, path, b = self.cs, self.path, self.buf
        transforms = (fr.get("frame_properties") or {}).get("transforms")
        for u, oif in fobjs.items():
            od = (oif or {}).get("object_data") or {}
            cubs = od.get("cuboid") or []
            if isinstance(cubs, dict):
                cubs = [cubs]
            cub = next((c for c in cubs if c.get("name") == "bounding_box"), cubs[0] if cubs else None)
            if cub is None or cub.get("val") is None:
                continue
            v = [float(a) for a in cub["val"]]
            csname = cub.get("coordinate_system")
            if len(v) == 9 and v[3] == 0.0 and v[4] == 0.0 and not csname:
                # the common case (the AVEAS profile): a level box in the root frame
                pw, yaw, dims = v[:3], v[5], v[6:9]
            elif len(v) == 10:
                R = _quat_matrix(v[3], v[4], v[5], v[6])
                dims = v[7:10]
            elif len(v) == 9:
                R = _euler_matrix(v[3], v[4], v[5])
                dims = v[6:9]
            else:
                raise FormatError(f"frame {k} object {u}: cuboid with {len(v)} values", path=path)
            if len(v) == 10 or not (v[3] == 0.0 and v[4] == 0.0 and not csname):
                M = cs.to_root(csname, transforms)
                Rw = M[:3, :3] @ R
                pw = M[:3, :3] @ np.asarray(v[:3]) + M[:3, 3]
                yaw = math.atan2(Rw[1, 0], Rw[0, 0])
            attrs = _attrs(od)
            b["uidx"].append(ui[u])
            b["occ"].append(j)
            cub_ts = _first(_attrs(cub.get("attributes")), "timestamp")
            b["cub_ts"].append(float(cub_ts) if isinstance(cub_ts, (int, float)) else np.nan)
            b["px"].append(pw[0])
            b["py"].append(pw[1])
            b["pz"].append(pw[2] - dims[2] / 2.0)
            b["yaw"].append(yaw)
            b["csroot"].append(cs.root_of(csname))
            if self._needs_size(u):
                self.sizes.append((j, u, dims))
            vel = _first(attrs, "velocity")
            acc = _first(attrs, "acceleration")
            b["vu"].append(vel[0] if vel else np.nan)
            b["vv"].append(vel[1] if vel else np.nan)
            b["yr"].append(vel[5] if vel and len(vel) > 5 else np.nan)
            b["hv"].append(vel is not None)
            b["au"].append(acc[0] if acc else np.nan)
            b["av"].append(acc[1] if acc else np.nan)
            bsd = _first(attrs, "bounding_box/ustddev")
            b["x_std"].append(bsd[0] if bsd else np.nan)
            b["y_std"].append(bsd[1] if bsd else np.nan)
            b["z_std"].append(bsd[2] if bsd else np.nan)
            b["heading_std"].append(bsd[5] if bsd else np.nan)
            vsd = _first(attrs, "velocity/ustddev")
            b["vu_std"].append(vsd[0] if vsd else np.nan)
            b["vv_std"].append(vsd[1] if vsd else np.nan)
            b["yr_std"].append(vsd[5] if vsd and len(vsd) > 5 else np.nan)
            asd = _first(attrs, "acceleration/ustddev")
            b["au_std"].append(asd[0] if asd else np.nan)
            b["av_std"].append(asd[1] if asd else np.nan)
            road = _first(attrs, "used_road_link", _first(attrs, "open_drive/road_id"))
            lrc = _first(attrs, "open_drive/local_road_coordinates")
            lane = _first(attrs, "open_drive/lane_id")
            b["hr"].append(road is not None and lrc is not None)
            b["road_id"].append(str(road) if road is not None and lrc is not None else None)
            b["road_s"].append(lrc[0] if road is not None and lrc else np.nan)
            b["road_t"].append(lrc[1] if road is not None and lrc else np.nan)
            try:
                b["lane_id"].append(int(str(_enum_value(lane))) if lane is not None and road is not None else None)
            except ValueError:
                b["lane_id"].append(None)
            b["lane_position"].append(_first(attrs, "open_drive/lane_position", np.nan))
            for c, name in LIGHTS.items():
                bl = _first(attrs, name)
                b[c].append(np.nan if bl is None else float(bool(bl)))
            # interior (the lateral flag carries the longitudinal name: the second one is lateral)
            lon_items = attrs.get(_LONGITUDINAL) or []
            lat_items = attrs.get("interior/automated_control/lateral") or []
            irow = {}
            if lon_items:
                irow["automation_longitudinal_p"] = float(bool(lon_items[0].get("val")))
            if lat_items:
                irow["automation_lateral_p"] = float(bool(lat_items[0].get("val")))
            elif len(lon_items) > 1:
                irow["automation_lateral_p"] = float(bool(lon_items[1].get("val")))
            for c, name in (("steering_angle", "interior/steering_angle"),
                            ("steering_angle_std", "interior/steering_angle/ustddev"),
                            ("brake_pedal", "interior/brake_pedal"),
                            ("accelerator_pedal", "interior/accelerator_pedal"),
                            ("gear", "interior/gear")):
                val = _first(attrs, name)
                if val is not None:
                    irow[c] = val
            if irow:
                self.interior.append((j, u, irow))
            any(n.startswith("impact/") for n in attrs)  # (as before: attribute names are text)
            e = cub.get(EXT)
            self.ext_buf.append(e if isinstance(e, dict) else None)
            if len(b["occ"]) >= _CHUNK:
                self._flush()

    def finish(self) -> _FrameData:
        self._flush()
        last: dict = {}
        for j, k in enumerate(self.keys):
            last[k] = j
        fkeys = sorted(last, key=lambda k: (int(k) if str(k).lstrip("-").isdigit() else 0, str(k)))
        rank_of = np.full(len(self.keys), -1, np.int64)
        for r, k in enumerate(fkeys):
            rank_of[last[k]] = r
        names = list(self.uid_index)
        seen: dict[str, None] = {}
        objects = self.objects
        for k in fkeys:
            for i in self.frame_uids[last[k]].tolist():
                u = names[i]
                if u not in objects and u not in seen:
                    seen[u] = None
        rows: dict[str, np.ndarray] = {}
        ext: dict[str, tuple] = {}
        has_vel, has_road = True, False
        if self.chunks:
            rank = rank_of[np.concatenate([ch.pop("occ") for ch in self.chunks])]
            sel = np.flatnonzero(rank >= 0)
            sel = sel[np.argsort(rank[sel], kind="stable")]
            ident = len(sel) == len(rank) and bool((sel == np.arange(len(sel))).all())
            for c in list(self.chunks[0]):  # one column at a time, freeing its chunks
                a = np.concatenate([ch.pop(c) for ch in self.chunks])
                rows[c] = a if ident else a[sel]
            self.chunks = []
            rows["rank"] = rank if ident else rank[sel]
            hv, hr = rows.pop("hv"), rows.pop("hr")
            has_vel, has_road = bool(hv.all()), bool(hr.any())
            keys = dict.fromkeys(c for _, reps in self.ext_chunks for c in reps)
            for c in keys:
                parts = [reps.get(c) or ("f", np.full(m, np.nan), np.zeros(m, bool), np.zeros(m, bool))
                         for m, reps in self.ext_chunks]
                ext[c] = _rep_concat(parts) if ident else _rep_take(_rep_concat(parts), sel)
        else:
            rows = {c: np.asarray([]) for c in (*_FLOAT_COLS, *_OBJ_COLS)}
            rows["uidx"] = rows["rank"] = np.asarray([], np.int64)
        sizes: dict[str, list] = defaultdict(list)
        for j, u, dims in self.sizes:
            if rank_of[j] >= 0:
                sizes[u].append(dims)

        def interior(pid_of: dict, time_of: dict) -> dict[str, list]:
            out: dict[str, list] = defaultdict(list)
            keep = sorted((int(rank_of[j]), i) for i, (j, _, _) in enumerate(self.interior)
                          if rank_of[j] >= 0)
            for r, i in keep:
                _, u, irow = self.interior[i]
                out["participant_id"].append(pid_of[u])
                out["time"].append(time_of[fkeys[r]])
                for c in ("automation_longitudinal_p", "automation_lateral_p", "steering_angle",
                          "steering_angle_std", "brake_pedal", "accelerator_pedal", "gear"):
                    out[c].append(irow.get(c))
            return out

        return _FrameData(fkeys=fkeys, stamps={k: self.stamps[last[k]] for k in fkeys},
                          seen_in_frames=list(seen), uid_names=names, rows=rows, ext=ext,
                          sizes=sizes, interior=interior, has_vel=has_vel, has_road=has_road)


# -- the import ----------------------------------------------------------------------------------

def _find_map(path: Path, ol: dict[str, Any], map_source, options) -> bytes:
    if map_source is not None:
        return load_map_bytes(map_source)
    name = (ol.get("metadata") or {}).get("opendrive")
    if name:
        cand = (path.parent / str(name))
        if cand.is_file():
            return cand.read_bytes()
        # case-insensitive match next to the file
        for q in path.parent.iterdir():
            if q.name.lower() == str(name).lower():
                return q.read_bytes()
    raise FormatError("no map: pass --map MAP.xodr (metadata.opendrive "
                      + (f"{name!r} is not next to the file)" if name else "is absent)"), path=path)


@converter("openlabel", description="ASAM OpenLABEL 1.0 JSON (AVEAS profile and generic cuboids)",
           patterns=("*.json",), method=None, options=OpenLabelImportOptions, needs_map=False)
def import_openlabel(inputs: list[Path], *, map_source, options: OpenLabelImportOptions):
    if len(inputs) != 1:
        raise FormatError(f"openlabel: expected one input file, got {len(inputs)}")
    path = Path(inputs[0])
    import importlib.util

    if importlib.util.find_spec("ijson") is None:  # a dependency; without it: read whole, as before
        warnings.warn("ijson is not installed: the OpenLABEL file is read whole (pip install ijson)",
                      stacklevel=2)
    else:
        with _no_gc():
            try:
                try:
                    ol, frames = _stream_doc(path)
                    map_bytes = _find_map(path, ol, map_source, options)
                    return _openlabel_to_recording(ol, map_bytes, options=options, path=path,
                                                   frames=frames)
                except (_NotStrictJSON, FormatError) as e:
                    if isinstance(e, _NotStrictJSON) or str(e.message).startswith(
                            ("broken JSON", "not UTF-8", "JSON ")):
                        raise
                    _check_stream(path)
                    raise
                except Exception:
                    # as when the file was parsed whole: a JSON error anywhere in the file comes
                    # before what the frames read so far made of it (checked only on failure)
                    _check_stream(path)
                    raise
            except _NotStrictJSON:
                pass
    with _no_gc():
        ol = _load_doc(path)
    map_bytes = _find_map(path, ol, map_source, options)
    return openlabel_to_recording(ol, map_bytes, options=options, path=path)


def openlabel_to_recording(ol: dict[str, Any], map_bytes: bytes, *, options=None, path: Path | None = None):
    """A recording from a parsed OpenLABEL document (the object under ``openlabel``)."""
    with _no_gc():
        return _openlabel_to_recording(ol, map_bytes, options=options, path=path)


def _openlabel_to_recording(ol: dict[str, Any], map_bytes: bytes, *, options=None,
                            path: Path | None = None, frames=None):
    """``frames``: a function yielding ``(key, frame)`` in file order (the streamed import); else
    the frames are ``ol["frames"]``. Both go through :class:`_FrameRows`."""
    from aveas_format.mapref.crs import LocalFrame, parse_crs
    from aveas_format.mapref.build import build_recording
    from aveas_format.numeric import wrap_angle
    from aveas_format.opendrive import load_map

    options = options or OpenLabelImportOptions()
    if "openlabel" in ol and isinstance(ol["openlabel"], dict):
        ol = ol["openlabel"]
    md = ol.get("metadata") or {}
    ext = md.get(EXT) if isinstance(md.get(EXT), dict) else None
    rmeta = dict((ext or {}).get("recording") or {})
    net = load_map(map_bytes)

    # ---- CRS ---------------------------------------------------------------------------------
    crs = net.header.geo_reference or rmeta.get("crs")
    if not crs:
        ps = md.get("projection_string")
        if ps:
            try:
                parse_crs(ps)
                crs = ps
            except FormatError:
                warnings.warn(f"projection_string {ps!r} is not a usable CRS", stacklevel=2)
    if not crs:
        raise FormatError("neither the map (<geoReference>) nor metadata.projection_string gives "
                          "a usable CRS", path=path)
    local = LocalFrame(crs, offset=net.header.offset, warn=False)

    # ---- frames (streamed one at a time, or from the dict) and time ---------------------------
    objects = ol.get("objects") or {}
    cs = _Frames(ol.get("coordinate_systems"))
    acc = _FrameRows(objects, cs, path)
    for k, fr in (frames() if frames is not None else (ol.get("frames") or {}).items()):
        acc.add(k, fr)
    fd = acc.finish()
    fkeys = fd.fkeys
    fnum = {k: (int(k) if str(k).lstrip("-").isdigit() else i) for i, k in enumerate(fkeys)}
    stamps = fd.stamps
    start_time = None
    if ext and ext.get("start_time"):
        start_time = ext["start_time"]
        time_of = {k: float(stamps[k]) if stamps[k] is not None else 0.0 for k in fkeys}
    else:
        have = [v for v in stamps.values() if v is not None]
        if fkeys and len(have) == len(fkeys):
            t0 = min(have)
            time_of = {k: float(stamps[k] - t0) for k in fkeys}
            if t0 > 1e8:  # Unix seconds
                dt = datetime.fromtimestamp(t0, tz=timezone.utc)
                start_time = dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        else:
            f0 = min(fnum.values()) if fnum else 0
            time_of = {k: (fnum[k] - f0) / options.rate_hz for k in fkeys}
        if start_time is None and md.get("acquisition_date"):
            start_time = _to_utc(str(md["acquisition_date"]))
    start_time = options.start_time or start_time or "1970-01-01T00:00:00Z"

    # ---- objects -----------------------------------------------------------------------------
    uids = list(objects)
    uids += fd.seen_in_frames
    obj_ext = {}
    for u in uids:
        size_items = _attrs((objects.get(u) or {}).get("object_data")).get("dimensions/size") or []
        e = size_items[0].get(EXT) if size_items and isinstance(size_items[0].get(EXT), dict) else None
        obj_ext[u] = e
    if all(e is not None and "participant_id" in e for e in obj_ext.values()) and uids:
        pid_of = {u: int(obj_ext[u]["participant_id"]) for u in uids}
    elif all(str(u).isdigit() for u in uids):
        pid_of = {u: int(u) for u in uids}
    else:
        pid_of = {u: i for i, u in enumerate(uids)}

    # ---- per object and frame ---------------------------------------------------------------
    root_crs = options.world_crs
    rows = fd.rows
    uidx, rank = rows.pop("uidx"), rows.pop("rank")
    rows["participant_id"] = np.asarray([pid_of.get(u, 0) for u in fd.uid_names])[uidx] \
        if fd.uid_names else np.asarray([])
    rows["time"] = np.asarray([time_of[k] for k in fkeys], float)[rank] if fkeys else np.asarray([])
    state_ext = fd.ext
    sizes = fd.sizes
    interior = fd.interior(pid_of, time_of)
    has_vel, has_road = fd.has_vel, fd.has_road
    n = len(rows["time"])
    if n == 0 and uids:
        static = sum(1 for o in objects.values()
                     if isinstance(o, dict) and isinstance(o.get("object_data"), dict)
                     and "cuboid" in o["object_data"])
        hint = (f" ({static} object(s) carry a static cuboid in object_data, which has no time: "
                "a trajectory needs frames)" if static else "")
        raise FormatError(f"no frame has a cuboid for any object{hint}", path=path)

    # per-box measurement timestamps (cuboid attribute "timestamp", Unix seconds) beat the
    # frame's: the ASAM example repeats frame timestamps while its boxes' differ
    cts = np.asarray(rows["cub_ts"], float)
    if ext is None and n and np.isfinite(cts).all() and cts.min() > 1e8:
        t0 = float(cts.min())
        rows["time"] = cts - t0
        if not options.start_time:
            start_time = datetime.fromtimestamp(t0, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    # one state per participant and time: later duplicates are dropped, with a warning
    if n:
        key = np.rec.fromarrays([np.asarray(rows["participant_id"]), np.asarray(rows["time"], float)])
        _, first_idx = np.unique(key, return_index=True)
        if len(first_idx) < n:
            keep = np.sort(first_idx)
            warnings.warn(f"OpenLABEL: {n - len(keep)} boxes repeat a (participant, time) and were "
                          "dropped", stacklevel=2)
            for c in list(rows):
                rows[c] = rows[c][keep]
            state_ext = {c: _rep_take(r, keep) for c, r in state_ext.items()}
            n = len(keep)

    # ---- world -> local frame -----------------------------------------------------------------
    px, py = np.asarray(rows["px"], float), np.asarray(rows["py"], float)
    yaw = np.asarray(rows["yaw"], float)
    roots = {r for r in rows["csroot"] if r}
    wcrs = root_crs
    if wcrs is None and len(roots) == 1:
        r = next(iter(roots))
        wcrs = _utm_crs(r, ((ol.get("coordinate_systems") or {}).get(r) or {}).get("type"))
    if wcrs is not None and n:
        import pyproj

        tr = pyproj.Transformer.from_crs(parse_crs(wcrs).crs, "EPSG:4326", always_xy=True)
        lon, lat = tr.transform(px, py)
        lon2, lat2 = tr.transform(px + np.cos(yaw), py + np.sin(yaw))
        x, y = local.from_wgs84(np.asarray(lon), np.asarray(lat))
        x2, y2 = local.from_wgs84(np.asarray(lon2), np.asarray(lat2))
        heading = np.arctan2(y2 - y, x2 - x)
    else:
        x, y, heading = px, py, yaw
    heading = wrap_angle(heading)

    pid = np.asarray(rows["participant_id"], np.int64)
    t = np.asarray(rows["time"], float)
    states: dict[str, Any] = {"participant_id": pid, "time": t, "x": x, "y": y, "heading": heading,
                              "z": np.asarray(rows["pz"], float)}
    if has_vel and n:
        vx, vy = _rot_world(np.asarray(rows["vu"], float), np.asarray(rows["vv"], float), heading)
        states["vx"], states["vy"] = vx, vy
        yr = np.asarray(rows["yr"], float)
        if np.isfinite(yr).any():
            states["yaw_rate"] = yr
        au, av = np.asarray(rows["au"], float), np.asarray(rows["av"], float)
        if np.isfinite(au).all() and np.isfinite(av).all():
            states["ax"], states["ay"] = _rot_world(au, av, heading)
        for c in ("x_std", "y_std", "z_std", "heading_std"):
            a = np.asarray(rows[c], float)
            if np.isfinite(a).any():
                states[c] = a
        su, sv = np.asarray(rows["vu_std"], float), np.asarray(rows["vv_std"], float)
        if np.isfinite(su).any():
            sx, sy = _body_std(su, sv, None, -heading)  # vehicle -> world (independent components)
            states["vx_std"], states["vy_std"] = sx, sy
        ysd = np.asarray(rows["yr_std"], float)
        if np.isfinite(ysd).any():
            states["yaw_rate_std"] = ysd
        su, sv = np.asarray(rows["au_std"], float), np.asarray(rows["av_std"], float)
        if np.isfinite(su).any() and "ax" in states:
            states["ax_std"], states["ay_std"] = _body_std(su, sv, None, -heading)
    for c in LIGHTS:
        a = np.asarray(rows[c], float)
        if not np.isnan(a).all():
            states[c] = pa.array(a, mask=np.isnan(a), type=pa.float32())
    use_file = options.road_coordinates == "file" or (options.road_coordinates == "auto" and has_road)
    if use_file and n:
        states["road_id"] = pa.array(rows["road_id"].tolist(), pa.string())
        states["lane_id"] = pa.array(rows["lane_id"].tolist(), pa.int16())
        states["road_s"] = np.asarray(rows["road_s"], float)
        states["road_t"] = np.asarray(rows["road_t"], float)
        lp = np.asarray(rows["lane_position"], float)
        if np.isfinite(lp).any():
            ok = np.isfinite(lp) & np.array([r is not None for r in rows["road_id"]])
            lo = np.full(n, np.nan)
            idx = np.flatnonzero(ok)
            for r in {rows["road_id"][i] for i in idx}:
                m = idx[[rows["road_id"][i] == r for i in idx]]
                try:
                    inner, outer = net.lane_borders(r, states["road_s"][m],
                                                    np.asarray([rows["lane_id"][i] or 0 for i in m]))
                    lo[m] = lp[m] * np.abs(outer - inner)
                except Exception:  # noqa: BLE001 — a road the map lacks
                    pass
            states["lane_offset"] = lo

    # extension: exact values of this library's own export
    if state_ext:
        for c in sorted(state_ext):
            base = states.get(c)
            rep = state_ext[c]
            if rep[0] == "f":  # floats (the common case): vectorised, same result as below
                _, fv, pr, nl = rep
                if base is None and (pr & ~nl).any():
                    states[c] = pa.array(fv, mask=~(pr & ~nl), type=pa.float64())
                    continue
                if (isinstance(base, np.ndarray) and base.dtype == np.float64 and base.ndim == 1
                        and len(base) == len(fv)):
                    null = np.where(pr, nl, np.isnan(base))
                    if not null.all():
                        states[c] = pa.array(np.where(pr, fv, base), mask=null, type=pa.float64())
                        continue
            vals = _rep_list(rep)
            if base is None:
                states[c] = pa.array([None if v is _MISSING else v for v in vals])
            else:
                cur = base.to_pylist() if isinstance(base, (pa.Array, pa.ChunkedArray)) else [
                    None if (isinstance(b, float) and math.isnan(b)) else b for b in np.asarray(base).tolist()]
                states[c] = pa.array([cur[i] if v is _MISSING else v for i, v in enumerate(vals)])
    del rows, state_ext  # the per-box columns are in ``states`` now
    fd.rows = fd.ext = None
    cols_keep = (ext or {}).get("states_columns")
    if cols_keep:
        for c in list(states):
            if c not in cols_keep:
                del states[c]
    states = {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(
        np.asarray(v), from_pandas=True)) for c, v in states.items()}

    # ---- participants -----------------------------------------------------------------------
    part: dict[str, list] = defaultdict(list)
    p_ext_rows = []
    ego_seen = False
    for u in uids:
        obj = objects.get(u) or {}
        attrs = _attrs(obj.get("object_data"))
        otype = str(obj.get("type") or "other")
        cls = TYPE_TO_CLASS.get(otype)
        if cls is None:
            key = otype.lower().split("/")[-1].replace(" ", "_").replace("-", "_")
            cls = GENERIC_TYPES.get(key, "other")
        is_ego = otype.lower() in ("egocar", "ego", "ego_vehicle") or bool(_first(attrs, "is_recorder", False))
        ego_seen |= is_ego
        size = _first(attrs, "dimensions/size")
        if size is None:
            arr = np.asarray(sizes.get(u) or [[1.0, 1.0, 1.0]], float)
            size = np.median(arr, axis=0).tolist()
        ssd = _first(attrs, "dimensions/size/ustddev")
        pmf = _first(attrs, "classification/uncertainties")
        part["participant_id"].append(pid_of[u])
        part["source_id"].append(str(obj.get("name") or u))
        part["class"].append(cls)
        part["length"].append(float(size[0]))
        part["width"].append(float(size[1]))
        part["height"].append(float(size[2]) if len(size) > 2 and size[2] else None)
        part["length_std"].append(float(ssd[0]) if ssd else None)
        part["width_std"].append(float(ssd[1]) if ssd else None)
        part["height_std"].append(float(ssd[2]) if ssd and len(ssd) > 2 else None)
        part["class_pmf"].append([float(v) for v in pmf] if pmf and len(pmf) == len(CLASSES) else None)
        att = _first(attrs, "attached_to")
        part["attached_to"].append(pid_of.get(str(att)) if att is not None else None)
        part["role"].append("recording_vehicle" if is_ego else "observed")
        p_ext_rows.append(obj_ext.get(u))
    if all(v is None for v in part["class_pmf"]):
        del part["class_pmf"]
    else:
        from aveas_format.schema.pmf import one_hot

        part["class_pmf"] = [v if v is not None else one_hot([c], "class")[0].tolist()
                             for v, c in zip(part["class_pmf"], part["class"])]
        m = np.asarray(part["class_pmf"], np.float32)
        part["class_pmf"] = pa.array(list(m), pa.list_(pa.float32()))
        # the class is the PMF's argmax (a foreign file may disagree; the PMF wins)
        part["class"] = [CLASSES[int(np.argmax(r))] if not obj_ext.get(u) else c
                         for r, c, u in zip(m, part["class"], uids)]
    for c in ("attached_to", "height", "length_std", "width_std", "height_std"):
        if c in part and all(v is None for v in part[c]):
            del part[c]
    if any(e for e in p_ext_rows):
        keys = sorted({c for e in p_ext_rows if e for c in e} - {"participant_id"})
        for c in keys:
            vals = [e.get(c, _MISSING) if e else _MISSING for e in p_ext_rows]
            cur = part.get(c)
            if c == "class_pmf":
                mats = [None if v is _MISSING else v for v in vals]
                if cur is not None:
                    curl = cur.to_pylist()
                    mats = [curl[i] if v is _MISSING else v for i, v in enumerate(vals)]
                part[c] = pa.array(mats, pa.list_(pa.float32()))
                continue
            if cur is None:
                part[c] = [None if v is _MISSING else v for v in vals]
            else:
                part[c] = [cur[i] if v is _MISSING else v for i, v in enumerate(vals)]
    pcols = (ext or {}).get("participants_columns")
    if pcols:
        for c in list(part):
            if c not in pcols:
                del part[c]
    participants = {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(v))
                    for c, v in part.items()}
    if not uids:  # a file without objects (e.g. the profile's minimum example)
        participants = {"participant_id": pa.array([], pa.int64()), "class": pa.array([], pa.string()),
                        "length": pa.array([], pa.float64()), "width": pa.array([], pa.float64())}
    if n == 0:
        states = {c: pa.array([], pa.int64() if c == "participant_id" else pa.float64())
                  for c in ("participant_id", "time", "x", "y", "heading", "vx", "vy")}

    # ---- tables from the extension, else from the profile -----------------------------------
    tables_ext = (ext or {}).get("tables") or {}
    events = table_from_json(tables_ext.get("events"), "events")
    unobserved = table_from_json(tables_ext.get("unobserved"), "unobserved")
    environment = table_from_json(tables_ext.get("environment"), "environment")
    interior_t = table_from_json(tables_ext.get("interior"), "interior")
    frame_time = {fnum[k]: time_of[k] for k in fkeys}
    if ext is None:
        events = _profile_events(ol, frame_time, pid_of)
        if interior:
            interior_t = pa.table({c: pa.array(v) for c, v in interior.items()
                                   if c in ("participant_id", "time") or any(x is not None for x in v)})
    conditions, environment_rows, staged = _profile_contexts(ol, frame_time)
    if ext is None and environment_rows:
        environment = pa.table({k: [r.get(k) for r in environment_rows]
                                for k in sorted({k for r in environment_rows for k in r})})

    # ---- metadata ---------------------------------------------------------------------------
    method = options.method or ((rmeta.get("acquisition") or {}).get("method")) or \
        PROFILE_TO_METHOD.get(str(_enum_value(md.get("acquisition_method"))), None) or \
        ("road_vehicle" if ego_seen else "infrastructure_camera")
    partner = options.partner or (rmeta.get("acquisition") or {}).get("partner") or \
        md.get("acquisition_partner") or md.get("annotator") or "unknown"
    provenance = options.provenance or rmeta.get("provenance") or ("staged" if staged else "natural")
    acq = dict(rmeta.get("acquisition") or {})
    acq.pop("method", None)
    acq.pop("partner", None)
    if not acq and path is not None:
        acq = {"platform": f"imported from OpenLABEL {path.name}"}
    rights = rmeta.get("rights") or {
        "right_of_use": str(_enum_value(md.get("right_of_use") or options.right_of_use)),
        "license": options.license, "owner": options.owner or partner}
    if options.owner or options.license != "unspecified":
        rights = {**rights, "license": options.license if options.license != "unspecified"
                  else rights.get("license", "unspecified"), "owner": options.owner or rights.get("owner") or partner}
    kw: dict[str, Any] = {}
    for key in ("title", "description", "coverage", "conditions", "thresholds", "extras", "location",
                "duration_s", "nominal_rate_hz"):
        if rmeta.get(key) is not None:
            kw[key] = rmeta[key]
    if "thresholds" not in kw and ext is None and any(
            md.get(k) is not None for k in ("threshold_gttc", "threshold_pret", "threshold_thw")):
        kw["thresholds"] = {"ttc_s": md.get("threshold_gttc"), "pet_s": md.get("threshold_pret"),
                            "thw_s": md.get("threshold_thw")}
        kw["thresholds"] = {k: float(v) for k, v in kw["thresholds"].items() if v and v > 0}
    if ext is not None:
        given = set(ext.get("thresholds_given") or [])
        if "thresholds" in kw:
            kw["thresholds"] = {k: v for k, v in kw["thresholds"].items() if k in given}
            if not kw["thresholds"]:
                del kw["thresholds"]
    if "conditions" not in kw and conditions:
        kw["conditions"] = conditions
    if "title" not in kw and ext is None and md.get("name"):  # ours: recording.json has it (or none)
        kw["title"] = str(md["name"])
    if options.title:
        kw["title"] = options.title
    if not n:
        kw.setdefault("duration_s", 0.0)
        kw.setdefault("nominal_rate_hz", options.rate_hz)
    opts_src = options
    rec = build_recording(
        map_source=map_bytes, participants=participants, states=states, unobserved=unobserved,
        events=events, environment=environment, interior=interior_t, crs=crs, method=method,
        partner=partner, provenance=provenance, start_time=start_time,
        recording_id=options.recording_id or rmeta.get("recording_id"),
        rights=rights, reference=not use_file, acquisition=acq,
        source=source_block("openlabel", [path] if path is not None else [], opts_src),
        **kw)
    if ext is not None:
        _restore_derived(rec, ext)
    return rec


def _restore_derived(rec, ext: dict[str, Any]) -> None:
    """The derived tables and recording.json ``derived`` entries of this library's own export."""
    from aveas_format.schema.metadata import DerivedEntry
    from aveas_format.schema.tables import TABLES

    for name, obj in sorted((ext.get("derived") or {}).items()):
        spec = TABLES.get(f"derived/{name}")
        if spec is None or not isinstance(obj, dict):
            warnings.warn(f"OpenLABEL extension: unknown derived table {name!r} skipped", stacklevel=3)
            continue
        table = table_from_json(obj, spec.name)
        if table is not None:
            # types as declared, columns and rows in the order they had (as exported)
            rec.derived[name] = table.select([c for c in obj.get("columns") or {}
                                              if c in table.column_names])
    entries = []
    for e in ext.get("derived_entries") or []:
        try:
            entries.append(DerivedEntry.model_validate(e))
        except Exception as err:  # noqa: BLE001 — a damaged entry: the table is then reported stale
            warnings.warn(f"OpenLABEL extension: derived entry skipped ({err})", stacklevel=3)
    if entries:
        rec.meta.derived = entries


_MISSING = object()


def _profile_events(ol: dict[str, Any], frame_time: dict[int, float], pid_of: dict[str, int]):
    evs = ol.get("events") or {}
    rows = []
    for k, ev in evs.items():
        etype = str(_enum_value((ev or {}).get("type") or ""))
        kind = TYPE_TO_EVENT.get(etype) or TYPE_TO_EVENT.get(etype.replace("_", " "))
        if kind is None and etype.replace(" ", "_") in {"near_miss", "accident", "lane_change", "cut_in",
                                                        "overtaking", "following", "turning", "parking",
                                                        "hard_braking", "handover_to_driver",
                                                        "driver_intervention"}:
            kind = etype.replace(" ", "_")
        if kind is None:
            continue
        attrs = _attrs(ev.get("event_data"))
        a = _first(attrs, "event_participant/role_a_id")
        b = _first(attrs, "event_participants/role_b_ids") or []
        ids = [pid_of[str(v)] for v in ([a] if a is not None else []) + list(b) if str(v) in pid_of]
        fi = (ev.get("frame_intervals") or [{}])[0]
        fs, fe = fi.get("frame_start"), fi.get("frame_end")
        if fs is None or fs not in frame_time:
            continue
        rows.append({"event_id": int(k) if str(k).isdigit() else len(rows), "kind": kind,
                     "time_start": frame_time[fs], "time_end": frame_time.get(fe, frame_time[fs]),
                     "participant_ids": ids,
                     "roles": (["role_a"] if a is not None else []) + ["role_b"] * (len(ids) - (a is not None)),
                     "origin": "annotated"})
    if not rows:
        return None
    return pa.table({k: [r[k] for r in rows] for k in rows[0]})


def _conditions_from(cd: dict[str, Any]) -> dict[str, Any]:
    a = _attrs(cd)
    out: dict[str, Any] = {}
    lu = _first(a, "environment/lighting_conditions/uncertainties")
    lv = _enum_value(_first(a, "lighting_conditions"))
    inv = {v: k for k, v in LIGHTING_TO_PROFILE.items()}
    if lu and len(lu) == 4:
        out["lighting"] = {inv[c]: float(v) for c, v in zip(PROFILE_LIGHTING, lu)}
    elif lv in inv:
        out["lighting"] = {inv[lv]: 1.0}
    ru = _first(a, "environment/road_condition/uncertainties")
    rv = _enum_value(_first(a, "road_condition"))
    if ru and len(ru) == 3:
        out["road_surface"] = {c: float(v) for c, v in zip(PROFILE_ROAD, ru)}
    elif rv in PROFILE_ROAD:
        out["road_surface"] = {rv: 1.0}
    for name, key in (("environment/temperature_celsius", "temperature_c"),
                      ("environment/temperature/ustddev", "temperature_c_std"),
                      ("environment/precipitation_intensity", "precipitation_mm_h"),
                      ("environment/visibility_range", "visibility_m")):
        v = _first(a, name)
        if v is not None:
            out[key] = float(v)
    cc = _first(a, "environment/cloud_cover")
    if cc is not None and 0 <= int(cc) <= 8:
        out["cloud_cover_okta"] = int(cc)
    bf = _first(a, "environment/wind/beaufort_force")
    if bf is not None:
        out["wind_speed_m_s"] = _beaufort_speed(float(bf))
    return out


def _profile_contexts(ol: dict[str, Any], frame_time: dict[int, float]):
    conditions: dict[str, Any] = {}
    env_rows: list[dict[str, Any]] = []
    staged = False
    for ctx in (ol.get("contexts") or {}).values():
        ctx = ctx or {}
        name, typ = str(ctx.get("name", "")), str(ctx.get("type", ""))
        cd = ctx.get("context_data") or {}
        if "scenario" in name.lower() or typ == "ScenarioContext":
            staged |= bool(_first(_attrs(cd), "scenario/is_staged", False))
        elif "environment" in name.lower() or typ == "EnvironmentContext":
            c = _conditions_from(cd)
            fis = ctx.get("frame_intervals")
            if fis:
                for fi in fis:
                    fs, fe = fi.get("frame_start"), fi.get("frame_end")
                    if fs in frame_time:
                        env_rows.append({"time_start": frame_time[fs],
                                         "time_end": frame_time.get(fe, frame_time[fs]), **c})
            else:
                conditions.update(c)
    return conditions or None, env_rows, staged


__all__ = ["export_openlabel", "import_openlabel", "openlabel_to_recording", "recording_to_openlabel",
           "table_from_json", "table_to_json"]
