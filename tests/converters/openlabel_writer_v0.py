"""The OpenLABEL writer as it was before issue 22 (one dict per state, then ``json.dumps``), kept
only as the reference of tests/converters/test_openlabel_encode.py; not part of the package.

:func:`recording_to_openlabel` builds the document in steps, columns in and JSON out:
:class:`_Columns` reads the states and participants as numpy columns (velocity and acceleration
turned into the profile's vehicle frame); the per-row inputs of the frames are prepared vectorised
(road facts from the map, interior signals, ``impact`` attributes from the derived tables,
uncertainty vectors, the extension's columns and exact values); :func:`_frames` writes one object
per state row, :func:`_objects` the static data per participant, :func:`_contexts` the scenario and
environment contexts, :func:`_events` the profile's events and :func:`_extension` the
``aveas_format`` metadata block. :func:`export_openlabel` is the registered exporter
(``openlabel:export``), which writes the JSON and the map next to it.
"""

from __future__ import annotations

import math
from collections import defaultdict
from datetime import datetime, timezone
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.openlabel.profile import (
    DEFAULT_THRESHOLDS,
    LONGITUDINAL,
    NO_RECORDER,
    PROFILE_PART_COLS,
    PROFILE_STATE_COLS,
    ROAD_CLASSES,
    CLASS_TO_TYPE,
    EVENT_TO_TYPE,
    EXT,
    EXT_VERSION,
    LIGHTS,
    METHOD_TO_PROFILE,
    environment_data,
    iso_ms,
)
from aveas_format.converters.registry import ConverterOptions
from aveas_format.converters.common.geometry import rotate, rotated_std
from aveas_format.numeric import no_gc
from aveas_format.io.arrow import column_numpy


def to_vehicle(vx, vy, h):
    return rotate(vx, vy, -h)


to_world = rotate
from aveas_format.io.tablejson import json_safe, table_to_json

# ================================================================================================
# helpers
# ================================================================================================

def _f(v: Any) -> float:
    return float(v)


def _finite(v: Any) -> bool:
    return v is not None and not (isinstance(v, float) and math.isnan(v))


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
    with no_gc():
        return _recording_to_openlabel(rec, opendrive, extension, road_attributes)


def _recording_to_openlabel(rec, opendrive: str, extension: bool, road_attributes: bool) -> dict[str, Any]:
    """The steps of :func:`recording_to_openlabel` (the keys of the document in this order)."""
    meta = rec.meta
    thr = meta.thresholds.model_dump() if meta.thresholds else {}
    thr_out = {k: (thr.get(k) or v) for k, v in DEFAULT_THRESHOLDS.items()}
    metadata = _profile_metadata(meta, opendrive, thr_out)
    doc: dict[str, Any] = {"metadata": metadata}
    cols = _Columns(rec)
    doc["frames"] = _frames(rec, cols, thr_out, extension, road_attributes)
    times = cols.times
    doc["frame_intervals"] = [{"frame_start": 0, "frame_end": int(len(times) - 1)}] if len(times) else []
    speed = np.hypot(cols.vx, cols.vy)
    doc["objects"] = _objects(rec.participants, cols, speed, extension)
    doc["contexts"] = _contexts(rec, times, speed)
    events = _events(rec.events, times)
    if events:
        doc["events"] = events
    if extension:
        metadata[EXT] = _extension(rec, thr)
    return {"openlabel": doc}


def _profile_metadata(meta, opendrive: str, thr_out: dict[str, float]) -> dict[str, Any]:
    """The profile's ``metadata`` (without the extension)."""
    return {
        "schema_version": "1.0.0",
        "name": meta.title or meta.recording_id,
        "annotator": meta.acquisition.partner,
        "comment": f"written by aveas-format from recording {meta.recording_id}",
        "aveas_schema_version": "0.4.17",
        "right_of_use": meta.rights.right_of_use.value,
        "acquisition_method": METHOD_TO_PROFILE[meta.acquisition.method.value],
        "acquisition_partner": meta.acquisition.partner,
        "acquisition_date": iso_ms(meta.start_time),
        "opendrive": opendrive,
        "projection_string": meta.crs,
        "threshold_gttc": float(thr_out["ttc_s"]),
        "threshold_pret": float(thr_out["pet_s"]),
        "threshold_thw": float(thr_out["thw_s"]),
    }


# ================================================================================================
# the states and participants as columns
# ================================================================================================

class _Columns:
    """The states (one row per state) and participants as numpy columns: frame numbers (one frame
    per distinct ``time``), the participants' sizes by id, and velocity and acceleration in the
    profile's vehicle frame (``vu, vv``, ``au, av``; the world-frame acceleration ``ax_w, ay_w`` is
    estimated where the states have none)."""

    def __init__(self, rec) -> None:
        p, s = rec.participants, rec.states
        self.pid = pid = s.column("participant_id").to_numpy()
        self.t = t = s.column("time").to_numpy()
        self.times, self.frame_of_row = np.unique(t, return_inverse=True)
        self.n = n = s.num_rows
        self.part_ids = part_ids = p.column("participant_id").to_numpy()
        self.classes = _pylist(p, "class")
        self.cls_of = dict(zip(part_ids.tolist(), self.classes))
        self.length = dict(zip(part_ids.tolist(), column_numpy(p, "length", missing=None).tolist()))
        self.width = dict(zip(part_ids.tolist(), column_numpy(p, "width", missing=None).tolist()))
        hcol = column_numpy(p, "height", missing=np.nan)
        self.height = dict(zip(part_ids.tolist(), hcol.tolist()))
        self.x = column_numpy(s, "x", missing=None)
        self.y = column_numpy(s, "y", missing=None)
        self.h = h = column_numpy(s, "heading", missing=None)
        self.z = column_numpy(s, "z", missing=None)
        self.vx, self.vy = vx, vy = tuple(column_numpy(s, c, missing=None) for c in ("vx", "vy"))
        self.vu, self.vv = to_vehicle(vx, vy, h)
        self.ax, self.ay = ax, ay = tuple(column_numpy(s, c, missing=None) for c in ("ax", "ay"))
        self.ax_w, self.ay_w = _world_acceleration(rec, pid, t, vx, vy, ax, ay)
        self.au, self.av = to_vehicle(np.nan_to_num(self.ax_w), np.nan_to_num(self.ay_w), h)
        self.yaw_rate = column_numpy(s, "yaw_rate", missing=None)
        self.stds = {c: column_numpy(s, c, missing=None) for c in
                     ("x_std", "y_std", "z_std", "heading_std", "vx_std", "vy_std", "ax_std",
                      "ay_std", "yaw_rate_std")}
        self.vxvy = column_numpy(s, "vxvy_corr", missing=None)
        self.axay = column_numpy(s, "axay_corr", missing=None)
        self.road_id = road_id = _pylist(s, "road_id") or [None] * n
        self.lane_id = column_numpy(s, "lane_id", missing=None)
        self.road_s = road_s = column_numpy(s, "road_s", missing=None)
        self.road_t = column_numpy(s, "road_t", missing=None)
        self.lane_offset = column_numpy(s, "lane_offset", missing=None)
        self.lights = {c: column_numpy(s, c, missing=None) for c in LIGHTS if c in s.column_names}
        #: rows on a road (road id and s known)
        self.on = np.array([r is not None for r in road_id], dtype=bool) & np.isfinite(
            road_s if road_s is not None else np.full(n, np.nan))


def _world_acceleration(rec, pid: np.ndarray, t: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                        ax: np.ndarray | None, ay: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The states' acceleration, else the derived kinematics', else estimated from the velocities."""
    if ax is None or ay is None:
        kin = rec.derived.get("kinematics") if rec.derived else None
        a_est = None
        if kin is not None and kin.num_rows == len(t):
            a_est = tuple(column_numpy(kin, c, missing=None) for c in ("ax", "ay"))
        if a_est is None:
            from aveas_format.mapref.build import velocity_from_positions

            a_est = velocity_from_positions(pid, t, vx, vy)
        ax_w = np.nan_to_num(a_est[0]) if ax is None else ax
        ay_w = np.nan_to_num(a_est[1]) if ay is None else ay
    else:
        ax_w, ay_w = ax, ay
    return ax_w, ay_w


# ================================================================================================
# per-row inputs of the frames, prepared vectorised
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
            ri = net.road_index_of(r)
            ri = np.broadcast_to(np.asarray(ri), ss.shape)
            sc = np.clip(ss, 0.0, net.road_length[ri])
            piece = lanes.find_piece(ri, sc)
            b = lanes.borders(piece, sc)
            for side, outers, ids, types in (("left", b.left, lanes.lid[piece], lanes.ltype[piece]),
                                             ("right", b.right, lanes.rid[piece], lanes.rtype[piece])):
                inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
                present = (ids != 0) & (np.abs(outers - inners) > 0.01)
                drivable = present & (types >= 0) & net.drivable_code[np.where(types >= 0, types, 0)]
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


def _row_road_facts(rec, cols: _Columns) -> dict[str, np.ndarray] | None:
    """:func:`_road_facts` for the rows on a road, spread to all rows (None where the map cannot
    answer)."""
    n, on, lane_id, lane_offset = cols.n, cols.on, cols.lane_id, cols.lane_offset
    idx = np.flatnonzero(on)
    lid = np.nan_to_num(lane_id[idx]).astype(int) if lane_id is not None else np.zeros(len(idx), int)
    lo = lane_offset[idx] if lane_offset is not None else np.full(len(idx), np.nan)
    f = _road_facts(rec.map, [cols.road_id[i] for i in idx], cols.road_s[idx], lid, lo)
    if f is None:
        return None
    facts = {k: np.empty(n, dtype=v.dtype) for k, v in f.items()}
    for k, v in f.items():
        facts[k][idx] = v
    return facts


def _interior_rows(it: pa.Table | None) -> dict[tuple[int, float], dict[str, Any]]:
    """Interior signals by (participant, time)."""
    interior_rows: dict[tuple[int, float], dict[str, Any]] = {}
    if it is not None and it.num_rows:
        ipid = it.column("participant_id").to_pylist()
        itime = it.column("time").to_pylist()
        icols = {c: _pylist(it, c) for c in ("steering_angle", "steering_angle_std", "brake_pedal",
                                              "accelerator_pedal", "gear", "automation_longitudinal_p",
                                              "automation_lateral_p") if c in it.column_names}
        for k in range(it.num_rows):
            interior_rows[(ipid[k], itime[k])] = {c: v[k] for c, v in icols.items()}
    return interior_rows


def _impact(derived: dict[str, pa.Table] | None, times: np.ndarray, thr_out: dict[str, float]
            ) -> dict[tuple[int, float], dict[str, list]]:
    """The profile's ``impact/gttc|thw|pret`` attributes by (participant, time): the derived
    interactions and encroachments below the thresholds."""
    impact: dict[tuple[int, float], dict[str, list]] = defaultdict(lambda: defaultdict(list))
    inter = derived.get("interactions") if derived else None
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
    enc = derived.get("encroachments") if derived else None
    if enc is not None and enc.num_rows:
        for r in enc.select(["first_id", "second_id", "time_second_enter", "pet"]).to_pylist():
            if r["pet"] is None or r["pet"] >= thr_out["pet_s"] or r["time_second_enter"] is None:
                continue
            k = int(np.clip(np.searchsorted(times, r["time_second_enter"]), 0, len(times) - 1))
            key = (r["second_id"], float(times[k]))
            impact[key]["pret/object_ids"].append(str(r["first_id"]))
            impact[key]["pret/values"].append(float(r["pet"]))
    return impact


def _exact_values(s: pa.Table, cols: _Columns) -> dict[str, list]:
    """Values the importer rebuilds with rounding (vehicle -> world frame, box centre -> ground):
    the exact value (NaN elsewhere) of each column where the rebuilt one would differ in any bit,
    so that an unchanged round trip hashes the same (and derived tables stay fresh)."""
    from aveas_format.numeric import wrap_angle

    exact: dict[str, list] = {}
    hw = wrap_angle(cols.h)
    back = dict(zip(("vx", "vy"), to_world(cols.vu, cols.vv, hw)))
    if cols.ax is not None and cols.ay is not None:
        back.update(zip(("ax", "ay"), to_world(cols.au, cols.av, hw)))
    z = cols.z
    if z is not None:
        hv = np.asarray([cols.height[q] for q in cols.pid.tolist()], float)
        hv = np.where(np.isfinite(hv), hv, 0.0)
        back["z"] = (np.where(np.isfinite(z), z, 0.0) + hv / 2) - hv / 2
    for c, b in back.items():
        orig = column_numpy(s, c, missing=None)
        off = np.isfinite(orig) & (b != orig)
        if off.any():
            exact[c] = np.where(off, orig, np.nan).tolist()
    return exact


def _uncertainty(p: pa.Table, cols: _Columns) -> tuple:
    """The ``/ustddev`` vectors, as lists of Python floats per row (``box_std``, ``vel_std``,
    ``acc_std``; velocity and acceleration only in rows where ``vel_ok``/``acc_ok``) and per
    participant (``size_std``): ``(box_std, size_std, vel_std, vel_ok, acc_std, acc_ok)``."""
    n, stds, h = cols.n, cols.stds, cols.h

    def _z(a):
        return np.zeros(n) if a is None else np.nan_to_num(a)

    box_std = vel_std = acc_std = None
    if any(stds[c] is not None for c in ("x_std", "y_std", "heading_std")):
        zero = np.zeros(n)
        box_std = np.column_stack([_z(stds["x_std"]), _z(stds["y_std"]), _z(stds["z_std"]), zero, zero,
                                   _z(stds["heading_std"])]).tolist()
    size_std = {}
    for j, q in enumerate(cols.part_ids.tolist()):
        size_std[q] = [float(v) if v is not None else 0.0 for v in (
            (p.column(c)[j].as_py() if c in p.column_names else None)
            for c in ("length_std", "width_std", "height_std"))]
    vel_ok = acc_ok = np.zeros(n, bool)
    if stds["vx_std"] is not None and stds["vy_std"] is not None:
        vel_ok = np.isfinite(stds["vx_std"]) & np.isfinite(stds["vy_std"])
        su, sv = rotated_std(_z(stds["vx_std"]), _z(stds["vy_std"]), cols.vxvy, h)
        zero = np.zeros(n)
        vel_std = np.column_stack([su, sv, zero, zero, zero, _z(stds["yaw_rate_std"])]).tolist()
    if stds["ax_std"] is not None and stds["ay_std"] is not None:
        acc_ok = np.isfinite(stds["ax_std"]) & np.isfinite(stds["ay_std"])
        su, sv = rotated_std(_z(stds["ax_std"]), _z(stds["ay_std"]), cols.axay, h)
        zero = np.zeros(n)
        acc_std = np.column_stack([su, sv, zero, zero, zero, zero]).tolist()
    return box_std, size_std, vel_std, vel_ok, acc_std, acc_ok


# ================================================================================================
# frames: one object per state row
# ================================================================================================

def _frames(rec, cols: _Columns, thr_out: dict[str, float], extension: bool, road_attributes: bool
            ) -> dict[str, dict[str, Any]]:
    """``frames``: per distinct time its timestamp and, per state row, the object's data."""
    s, n = rec.states, cols.n
    facts = _row_road_facts(rec, cols) if road_attributes and cols.on.any() else None
    interior_rows = _interior_rows(rec.interior)
    impact = _impact(rec.derived, cols.times, thr_out)
    # extension columns of states, and the nullable columns the profile writes a placeholder for
    ext_cols = [c for c in s.column_names if c not in PROFILE_STATE_COLS]
    ext_vals = {c: _pylist(s, c) for c in ext_cols}
    nullable = [c for c in ("z", "z_std", "x_std", "y_std", "heading_std", "ax", "ay", "yaw_rate")
                if c in s.column_names]
    null_ofl = {c: s.column(c).is_null().to_numpy(zero_copy_only=False).tolist() for c in nullable}
    exact = _exact_values(s, cols) if extension and n else {}
    box_std, size_std, vel_std, vel_ok, acc_std, acc_ok = _uncertainty(rec.participants, cols)
    # per-row values as Python lists (the loop below is the hot path)
    cls_of, height, length, width, road_id = cols.cls_of, cols.height, cols.length, cols.width, cols.road_id
    xl, yl, hl = cols.x.tolist(), cols.y.tolist(), cols.h.tolist()
    onl = cols.on.tolist()
    lane_idl = cols.lane_id.tolist() if cols.lane_id is not None else None
    road_sl = cols.road_s.tolist() if cols.road_s is not None else None
    road_tl = cols.road_t.tolist() if cols.road_t is not None else None
    lightl = {c: a.tolist() for c, a in cols.lights.items()}
    zl = cols.z.tolist() if cols.z is not None else None
    vul, vvl, aul, avl = cols.vu.tolist(), cols.vv.tolist(), cols.au.tolist(), cols.av.tolist()
    yrl = cols.yaw_rate.tolist() if cols.yaw_rate is not None else None
    pidl, tl, fl = cols.pid.tolist(), cols.t.tolist(), cols.frame_of_row.tolist()

    frames: dict[str, dict[str, Any]] = {}
    for k, tv in enumerate(cols.times):
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
                if cls in ROAD_CLASSES:
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
            for c, name in (("automation_longitudinal_p", LONGITUDINAL),
                            # the profile's lateral flag carries the longitudinal name (quirk)
                            ("automation_lateral_p", LONGITUDINAL)):
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
                cuboid[EXT] = json_safe(ext)
        od: dict[str, Any] = {"cuboid": [cuboid], "vec": vec}
        od["boolean"] = boolean
        od["num"] = num
        od["text"] = text
        frames[str(fl[i])]["objects"][str(q)] = {"object_data": od}
    return frames


# ================================================================================================
# objects, contexts, events, the extension block
# ================================================================================================

def _objects(p: pa.Table, cols: _Columns, speed: np.ndarray, extension: bool) -> dict[str, Any]:
    """``objects``: per participant its type, name, frame intervals and static data (size,
    classification PMF, speed and acceleration extremes, ``is_recorder``, ``attached_to``)."""
    pid, h, part_ids, classes, height = cols.pid, cols.h, cols.part_ids, cols.classes, cols.height
    length, width, ax_w, ay_w = cols.length, cols.width, cols.ax_w, cols.ay_w
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
    p_ext_cols = [c for c in p.column_names if c not in PROFILE_PART_COLS]
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
        if cls not in NO_RECORDER:
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
            size[EXT] = json_safe(ext)
        objects[str(q)] = {
            "name": str(source_ids[j]) if source_ids else str(q),
            "type": CLASS_TO_TYPE[cls],
            "frame_intervals": _intervals(cols.frame_of_row[rows]),
            "object_data": obj_data,
        }
    return objects


def _part_std(p: pa.Table, q: int, c: str) -> float:
    if c not in p.column_names:
        return 0.0
    ids = p.column("participant_id").to_numpy()
    j = int(np.flatnonzero(ids == q)[0])
    v = p.column(c)[j].as_py()
    return float(v) if v is not None else 0.0


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
                              "context_data": environment_data(meta.conditions.model_dump())}
    env = rec.environment
    if env is not None and env.num_rows and len(times):
        for k, r in enumerate(env.to_pylist()):
            fs = int(np.clip(np.searchsorted(times, r["time_start"] - 1e-9), 0, len(times) - 1))
            fe = int(np.clip(np.searchsorted(times, r["time_end"] + 1e-9) - 1, fs, len(times) - 1))
            out[str(k + 2)] = {
                "name": "environment_context", "type": "EnvironmentContext",
                "frame_intervals": [{"frame_start": fs, "frame_end": fe}],
                "context_data": environment_data(r)}
    return out


def _events(ev: pa.Table | None, times: np.ndarray) -> dict[str, Any]:
    """``events``: the recording's events of the profile's types, with their frame intervals."""
    events = {}
    if ev is not None and ev.num_rows:
        for r in ev.to_pylist():
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
    return events


def _extension(rec, thr: dict[str, Any]) -> dict[str, Any]:
    """``metadata.aveas_format``: what the profile cannot carry (recording.json, the small tables,
    column lists, the derived tables with their recording.json entries)."""
    meta, p, s = rec.meta, rec.participants, rec.states
    md = meta.model_dump(mode="json", exclude_none=True)
    for k in ("tables", "derived", "map", "source"):
        md.pop(k, None)
    return json_safe({
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
