"""Recording -> OpenLABEL (the export): one AVEAS-profile document per recording.

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

import json
import math
from collections import defaultdict
from datetime import datetime, timezone
from functools import partial
from pathlib import Path
from collections.abc import Iterator
from typing import Any

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.converters.openlabel.profile import (
    DEFAULT_THRESHOLDS,
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
from aveas_format.converters.openlabel.encode import CHUNK_ROWS, frame_chunks
from aveas_format.converters.common.geometry import rotate, rotated_std
from aveas_format.converters.registry import ConverterOptions, converter
from aveas_format.io.arrow import column_numpy
from aveas_format.io.jsontext import dumps, orjson
from aveas_format.io.tablejson import json_safe, table_to_json
from aveas_format.io.timemajor import chunk_bounds, open_states
from aveas_format.numeric import no_gc
from aveas_format.safeio.compressed import compressed, compression
from aveas_format.safeio.parts import ForkedParts

# ================================================================================================
# helpers
# ================================================================================================

def _pylist(table: pa.Table, name: str) -> list | None:
    if table is None or name not in table.column_names:
        return None
    col = table.column(name)
    if pa.types.is_dictionary(col.type):
        col = col.cast(col.type.value_type)
    return col.to_pylist()


def _codes(col: pa.ChunkedArray | pa.Array) -> tuple[list, np.ndarray]:
    """A column's distinct values and each row's index into them (-1 where null)."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if not pa.types.is_dictionary(col.type):
        col = col.dictionary_encode()
    return col.dictionary.to_pylist(), col.indices.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int64)


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
    workers: int = Field(0, ge=0, exclude=True)
    """Processes encoding the frames of a large compact ``.json`` (0 = one per core, 1 = in this
    process; CLI ``--workers``): the other parts are encoded by forked processes into files next
    to the output, copied in by the kernel. The file is the same whatever the number."""


def recording_to_openlabel(rec, *, opendrive: str = "map.xodr", extension: bool = True,
                           road_attributes: bool = True) -> dict[str, Any]:
    """The OpenLABEL document (a dict with the root key ``openlabel``) of a recording (the parsed
    bytes of :func:`openlabel_chunks`: one writer for the file and the dict)."""
    data = b"".join(openlabel_chunks(rec, opendrive=opendrive, extension=extension,
                                     road_attributes=road_attributes))
    return orjson.loads(data) if orjson is not None else json.loads(data)


def openlabel_chunks(rec, *, opendrive: str = "map.xodr", extension: bool = True,
                     road_attributes: bool = True, chunk_rows: int | None = None, workers: int = 1,
                     spill_dir: Path | None = None) -> Iterator[Any]:
    """The compact JSON of the OpenLABEL document of a recording, streamed: the keys of the
    document in this order (metadata, frames, frame_intervals, objects, contexts, events), the
    frames a chunk of about ``chunk_rows`` (default :data:`CHUNK_ROWS`) state rows at a time (never
    the whole text in memory). ``workers`` > 1 with a ``spill_dir`` (fork available, enough
    rows): the frames in that many parts, all but the first encoded by forked processes into
    files in ``spill_dir``, given as :class:`~aveas_format.safeio.atomic.FileSegment` s (for
    :func:`write_chunks_atomic`). A recording opened without its states
    (``open_recording(path, states=False)``) has them read from its file in bounded memory
    (:class:`~aveas_format.io.timemajor.SpilledStates`, spilled to a temporary directory in
    ``spill_dir``)."""
    chunk_rows = chunk_rows or CHUNK_ROWS
    states = open_states(rec, chunk_rows, spill_dir, _acceleration(rec.derived), prefix=".openlabel-states.")
    try:
        yield from _document(rec, states, opendrive, extension, road_attributes, chunk_rows, workers,
                             spill_dir)
    finally:
        states.close()


def _document(rec, states, opendrive: str, extension: bool, road_attributes: bool, chunk_rows: int,
              workers: int, spill_dir: Path | None) -> Iterator[Any]:
    """The chunks of :func:`openlabel_chunks`, the states read through ``states``
    (:func:`~aveas_format.io.timemajor.open_states`)."""
    meta = rec.meta
    thr = meta.thresholds.model_dump() if meta.thresholds else {}
    thr_out = {k: (thr.get(k) or v) for k, v in DEFAULT_THRESHOLDS.items()}
    metadata = _profile_metadata(meta, opendrive, thr_out)
    if extension:
        metadata[EXT] = _extension(rec, thr, states.column_names)
    static = _Statics(rec.participants)
    times, frame_of_row = states.times, states.frame_of_row
    summary = _Summary(static)
    interior, impact = _interior_rows(rec.interior), _impact(rec.derived, times, thr_out)

    def prepare(rows: np.ndarray) -> dict[str, Any]:
        """The inputs of the frames' objects for the state rows ``rows`` (one chunk: the memory
        of the export is the states as ``states`` holds them plus one chunk's columns)."""
        cols = _Columns(*states.take(rows), static)
        summary.add(cols)
        inputs = _frame_inputs(rec, cols, extension, road_attributes)
        inputs.update(interior=interior, impact=impact)
        return inputs

    parts = None
    if workers > 1 and spill_dir is not None:  # (forked before the writer's thread and before
        # prepare has run: the forked processes' extremes start empty)
        parts = ForkedParts(partial(frame_chunks, frame_of_row, times, prepare, chunk_rows=chunk_rows),
                            chunk_bounds(np.sort(frame_of_row), chunk_rows), workers, spill_dir,
                            state=summary.state, merge=summary.merge, prefix=".openlabel-frames.")
    try:
        yield b'{"openlabel":{"metadata":' + dumps(metadata) + b',"frames":{'
        del metadata
        with no_gc():
            if parts is not None:
                yield from parts.chunks()
            else:
                yield from frame_chunks(frame_of_row, times, prepare, chunk_rows=chunk_rows)
    finally:
        if parts is not None:
            parts.close()
    tail: dict[str, Any] = {}
    tail["frame_intervals"] = [{"frame_start": 0, "frame_end": int(len(times) - 1)}] if len(times) else []
    tail["objects"] = _objects(rec.participants, states.participant_ids(), static, frame_of_row, summary,
                               extension)
    del frame_of_row
    tail["contexts"] = _contexts(rec, times, summary)
    events = _events(rec.events, times)
    if events:
        tail["events"] = events
    yield b"}," + dumps(tail)[1:] + b"}"


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

def _acceleration(derived: dict | None):
    """``track_columns`` of :func:`~aveas_format.io.timemajor.open_states` for states without
    ``ax``/``ay``: the world-frame acceleration ``ax_w, ay_w`` (the states' component where they
    have it, else the derived kinematics' where it has a row per state, else estimated from the
    velocities along each track)."""

    def columns(names: list[str], n: int):
        if "ax" in names and "ay" in names:
            return None
        kin = derived.get("kinematics") if derived else None
        kin = None if kin is None or kin.num_rows != n else [column_numpy(kin, c, missing=None) for c in ("ax", "ay")]

        def acc(t: pa.Table, offset: int) -> dict[str, np.ndarray]:
            ax, ay = (column_numpy(t, c, missing=None) for c in ("ax", "ay"))
            est = None if kin is None else [a[offset:offset + t.num_rows] for a in kin]
            if est is None:
                from aveas_format.mapref.build import velocity_from_positions

                est = velocity_from_positions(t.column("participant_id").to_numpy(), column_numpy(t, "time"),
                                              *(column_numpy(t, c, missing=None) for c in ("vx", "vy")))
            return {"ax_w": np.nan_to_num(est[0]) if ax is None else ax,
                    "ay_w": np.nan_to_num(est[1]) if ay is None else ay}
        return acc
    return columns


class _Statics:
    """The participants' static values, by id (sizes, class, size uncertainties)."""

    def __init__(self, p: pa.Table) -> None:
        self.part_ids = part_ids = p.column("participant_id").to_numpy()
        ids = part_ids.tolist()
        self.classes = _pylist(p, "class")
        self.length = dict(zip(ids, column_numpy(p, "length", missing=None).tolist()))
        self.width = dict(zip(ids, column_numpy(p, "width", missing=None).tolist()))
        self.height = dict(zip(ids, column_numpy(p, "height", missing=np.nan).tolist()))
        self.pos = {q: j for j, q in enumerate(ids)}
        self.size_std = np.column_stack([column_numpy(p, c, null=0.0, missing=0.0).astype(np.float64)
                                         for c in ("length_std", "width_std", "height_std")]).reshape(-1, 3)
        self.sizes = np.asarray([[self.length[q], self.width[q], self.height[q]] for q in ids],
                                dtype=np.float64).reshape(-1, 3)
        self.road_class = np.asarray([c in ROAD_CLASSES for c in self.classes], dtype=bool)

    def rows(self, pid: np.ndarray) -> np.ndarray:
        """The participants' row of each state (KeyError: a state of no participant)."""
        pid = np.asarray(pid)
        if pid.dtype.kind not in "iu" or self.part_ids.dtype.kind not in "iu":
            pos = self.pos
            return np.fromiter((pos[q] for q in pid.tolist()), dtype=np.int64, count=len(pid))
        order = np.argsort(self.part_ids, kind="stable")  # (an id twice: its last row, as the dict)
        at = np.maximum(np.searchsorted(self.part_ids[order], pid, side="right") - 1, 0)
        rows = order[at] if len(order) else np.zeros(len(pid), np.int64)
        bad = self.part_ids[rows] != pid if len(order) else np.ones(len(pid), bool)
        if bad.any():
            raise KeyError(pid[np.argmax(bad)].item())
        return rows.astype(np.int64)


class _Columns:
    """The state rows ``s`` (one chunk of the frames) as numpy columns, with velocity and
    acceleration in the profile's vehicle frame (``vu, vv``, ``au, av``; the world-frame
    acceleration ``ax_w, ay_w``: ``extra``'s where the states have none, :func:`_acceleration`)."""

    def __init__(self, s: pa.Table, extra: dict | None, static: _Statics) -> None:
        self.static = static
        self.s = s
        self.pid = pid = s.column("participant_id").to_numpy()
        self.prow = static.rows(pid)
        self.t = column_numpy(s, "time")
        self.n = n = s.num_rows
        self.x = column_numpy(s, "x", missing=None)
        self.y = column_numpy(s, "y", missing=None)
        self.h = h = column_numpy(s, "heading", missing=None)
        self.z = column_numpy(s, "z", missing=None)
        self.vx, self.vy = vx, vy = tuple(column_numpy(s, c, missing=None) for c in ("vx", "vy"))
        self.vu, self.vv = rotate(vx, vy, -h)  # (the vehicle frame)
        self.ax, self.ay = ax, ay = tuple(column_numpy(s, c, missing=None) for c in ("ax", "ay"))
        self.ax_w, self.ay_w = (ax, ay) if extra is None else (extra["ax_w"], extra["ay_w"])
        self.au, self.av = rotate(np.nan_to_num(self.ax_w), np.nan_to_num(self.ay_w), -h)
        self.yaw_rate = column_numpy(s, "yaw_rate", missing=None)
        self.stds = {c: column_numpy(s, c, missing=None) for c in
                     ("x_std", "y_std", "z_std", "heading_std", "vx_std", "vy_std", "ax_std",
                      "ay_std", "yaw_rate_std")}
        self.vxvy = column_numpy(s, "vxvy_corr", missing=None)
        self.axay = column_numpy(s, "axay_corr", missing=None)
        #: road ids: the distinct values (``road_words``) and each row's index into them (-1: null)
        self.road_words, self.road_code = _codes(s.column("road_id") if "road_id" in s.column_names
                                                 else pa.nulls(n, pa.string()))
        self.road_id = np.asarray([*self.road_words, None], dtype=object)[self.road_code]
        self.lane_id = column_numpy(s, "lane_id", missing=None)
        self.road_s = road_s = column_numpy(s, "road_s", missing=None)
        self.road_t = column_numpy(s, "road_t", missing=None)
        self.lane_offset = column_numpy(s, "lane_offset", missing=None)
        self.lights = {c: column_numpy(s, c, missing=None) for c in LIGHTS if c in s.column_names}
        #: rows on a road (road id and s known)
        self.on = (self.road_code >= 0) & np.isfinite(
            road_s if road_s is not None else np.full(n, np.nan))


class _Summary:
    """Per participant the extremes of speed and signed acceleration over its states, and the
    fastest and slowest moving speeds of the recording, accumulated chunk by chunk."""

    def __init__(self, static: _Statics) -> None:
        m = len(static.part_ids)
        self.count = np.zeros(m, np.int64)
        self.speed_max, self.speed_min = np.full(m, -np.inf), np.full(m, np.inf)
        self.acc_max, self.acc_min = np.full(m, -np.inf), np.full(m, np.inf)
        self.moving_min = np.inf
        self.nan_speed = False

    def add(self, cols: _Columns) -> None:
        speed = np.hypot(cols.vx, cols.vy)
        ax_w, ay_w, h = np.nan_to_num(cols.ax_w), np.nan_to_num(cols.ay_w), cols.h
        acc = np.hypot(ax_w, ay_w) * np.sign(ax_w * np.cos(h) + ay_w * np.sin(h))
        r = cols.prow
        np.add.at(self.count, r, 1)
        for target, fn, v in ((self.speed_max, np.maximum, speed), (self.speed_min, np.minimum, speed),
                              (self.acc_max, np.maximum, acc), (self.acc_min, np.minimum, acc)):
            fn.at(target, r, v)  # NaN propagates, as numpy's max/min of the track
        moving = speed[speed > 0]
        if len(moving):
            self.moving_min = min(self.moving_min, float(moving.min()))
        self.nan_speed = self.nan_speed or bool(np.isnan(speed).any())

    def state(self) -> tuple:
        """What :meth:`merge` takes (the extremes accumulated here)."""
        return (self.count, self.speed_max, self.speed_min, self.acc_max, self.acc_min, self.moving_min,
                self.nan_speed)

    def merge(self, state: tuple) -> None:
        """The extremes of another part of the states (:meth:`state`) added to these."""
        count, smax, smin, amax, amin, moving_min, nan_speed = state
        self.count += count
        for target, fn, v in ((self.speed_max, np.maximum, smax), (self.speed_min, np.minimum, smin),
                              (self.acc_max, np.maximum, amax), (self.acc_min, np.minimum, amin)):
            fn(target, v, out=target)  # NaN propagates, as in add
        self.moving_min = min(self.moving_min, moving_min)
        self.nan_speed = self.nan_speed or nan_speed

    @property
    def max_speed(self) -> float:
        return math.nan if self.nan_speed else float(self.speed_max[self.count > 0].max())


# ================================================================================================
# per-row inputs of the frames, prepared vectorised
# ================================================================================================

def _road_facts(net, road_id: np.ndarray, s: np.ndarray, lane_id: np.ndarray, lane_offset: np.ndarray
                ) -> dict[str, np.ndarray] | None:
    """Per sample: lane_position, lanes left/right (physical, legal), classification (in a
    junction, else by the reference line's curvature).

    Best effort: None where the map engine cannot answer (never fails the export)."""
    try:
        lanes = net.lane_counts(road_id, s, lane_id)
        with np.errstate(invalid="ignore", divide="ignore"):
            lane_position = np.clip(lane_offset / np.abs(lanes["outer"] - lanes["inner"]), -0.5, 0.5)
        ri = net.road_index_of(road_id)
        kappa = net.reference_line(road_id, np.clip(s, 0.0, net.road_length[ri]))[3]
        shape = np.where(np.abs(kappa) > 1e-3, "curve", "straight")
        return {"lane_position": lane_position, "left_phys": lanes["left"], "left_legal": lanes["left_drivable"],
                "right_phys": lanes["right"], "right_legal": lanes["right_drivable"],
                "classification": np.where(net.road_in_junction[ri], "x_intersection", shape).astype(object)}
    except Exception:  # noqa: BLE001 — optional attributes; the map engine may not support them
        return None


def _row_road_facts(rec, cols: _Columns) -> dict[str, np.ndarray] | None:
    """:func:`_road_facts` for the rows on a road, spread to all rows (None where the map cannot
    answer)."""
    n, on, lane_id, lane_offset = cols.n, cols.on, cols.lane_id, cols.lane_offset
    idx = np.flatnonzero(on)
    lid = np.nan_to_num(lane_id[idx]).astype(int) if lane_id is not None else np.zeros(len(idx), int)
    lo = lane_offset[idx] if lane_offset is not None else np.full(len(idx), np.nan)
    f = _road_facts(rec.map, cols.road_id[idx], cols.road_s[idx], lid, lo)
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


def _exact_values(s: pa.Table, cols: _Columns) -> dict[str, np.ndarray]:
    """Values the importer rebuilds with rounding (vehicle -> world frame, box centre -> ground):
    the exact value (NaN elsewhere) of each column where the rebuilt one would differ in any bit,
    so that an unchanged round trip hashes the same (and derived tables stay fresh)."""
    from aveas_format.numeric import wrap_angle

    exact: dict[str, list] = {}
    hw = wrap_angle(cols.h)
    back = dict(zip(("vx", "vy"), rotate(cols.vu, cols.vv, hw)))
    if cols.ax is not None and cols.ay is not None:
        back.update(zip(("ax", "ay"), rotate(cols.au, cols.av, hw)))
    z = cols.z
    if z is not None:
        hv = cols.static.sizes[cols.prow, 2]
        hv = np.where(np.isfinite(hv), hv, 0.0)
        back["z"] = (np.where(np.isfinite(z), z, 0.0) + hv / 2) - hv / 2
    for c, b in back.items():
        orig = column_numpy(s, c, missing=None)
        off = np.isfinite(orig) & (b != orig)
        if off.any():
            exact[c] = np.where(off, orig, np.nan)
    return exact


def _uncertainty(cols: _Columns) -> tuple:
    """The ``/ustddev`` vectors, as lists of their components (arrays over the states, 0.0 where
    constant: ``box_std``, ``vel_std``, ``acc_std``; velocity and acceleration only in rows where
    ``vel_ok``/``acc_ok``): ``(box_std, vel_std, vel_ok, acc_std, acc_ok)``."""
    n, stds, h = cols.n, cols.stds, cols.h

    def _z(a):
        return np.zeros(n) if a is None else np.nan_to_num(a)

    box_std = vel_std = acc_std = None
    if any(stds[c] is not None for c in ("x_std", "y_std", "heading_std")):
        box_std = [_z(stds["x_std"]), _z(stds["y_std"]), _z(stds["z_std"]), 0.0, 0.0, _z(stds["heading_std"])]
    vel_ok = acc_ok = np.zeros(n, bool)
    if stds["vx_std"] is not None and stds["vy_std"] is not None:
        vel_ok = np.isfinite(stds["vx_std"]) & np.isfinite(stds["vy_std"])
        su, sv = rotated_std(_z(stds["vx_std"]), _z(stds["vy_std"]), cols.vxvy, h)
        vel_std = [su, sv, 0.0, 0.0, 0.0, _z(stds["yaw_rate_std"])]
    if stds["ax_std"] is not None and stds["ay_std"] is not None:
        acc_ok = np.isfinite(stds["ax_std"]) & np.isfinite(stds["ay_std"])
        su, sv = rotated_std(_z(stds["ax_std"]), _z(stds["ay_std"]), cols.axay, h)
        acc_std = [su, sv, 0.0, 0.0, 0.0, 0.0]
    return box_std, vel_std, vel_ok, acc_std, acc_ok


# ================================================================================================
# frames: one object per state row
# ================================================================================================

def _frame_inputs(rec, cols: _Columns, extension: bool, road_attributes: bool) -> dict[str, Any]:
    """The inputs of the frames' objects of the rows of ``cols`` as columns, for
    :func:`aveas_format.converters.openlabel.encode.frame_chunks` (the sparse interior and
    ``impact`` data, dicts by (participant, time), are added by the caller)."""
    s, n, static, prow = cols.s, cols.n, cols.static, cols.prow
    length, width, height = (static.sizes[prow, k] for k in range(3))
    hh = np.where(np.isfinite(height), height, 0.0)
    z = np.zeros(n) if cols.z is None else np.where(np.isfinite(cols.z), cols.z, 0.0)
    yr = 0.0 if cols.yaw_rate is None else np.where(np.isfinite(cols.yaw_rate), cols.yaw_rate, 0.0)
    box_std, vel_std, vel_ok, acc_std, acc_ok = _uncertainty(cols)
    if box_std is not None:
        box_std = [*box_std, *(static.size_std[prow, k] for k in range(3))]
    ext = None
    if extension:
        nullable = [c for c in ("z", "z_std", "x_std", "y_std", "heading_std", "ax", "ay", "yaw_rate")
                    if c in s.column_names]
        ext = {"columns": {c: s.column(c) for c in s.column_names if c not in PROFILE_STATE_COLS},
               "nullable": {c: s.column(c).is_null().to_numpy(zero_copy_only=False) for c in nullable},
               "exact": _exact_values(s, cols) if n else {}}
    return {
        "pid": cols.pid, "t": cols.t, "on": cols.on,
        # vectors as lists of their components
        "box": [cols.x, cols.y, z + hh / 2, 0.0, 0.0, cols.h, length, width, hh],
        "vel": [cols.vu, cols.vv, 0.0, 0.0, 0.0, yr],
        "acc": [cols.au, cols.av, 0.0, 0.0, 0.0, 0.0],
        "box_std": box_std, "vel_std": vel_std, "vel_ok": vel_ok, "acc_std": acc_std, "acc_ok": acc_ok,
        "road_words": cols.road_words, "road_code": cols.road_code, "lane_id": cols.lane_id,
        "road_s": cols.road_s,
        "road_t": cols.road_t if cols.road_t is not None else np.full(n, np.nan),
        "facts": _row_road_facts(rec, cols) if road_attributes and cols.on.any() else None,
        "road_class": static.road_class[prow], "lights": cols.lights,
        "ext": ext,
    }


# ================================================================================================
# objects, contexts, events, the extension block
# ================================================================================================

def _objects(p: pa.Table, pid: np.ndarray, static: _Statics, frame_of_row: np.ndarray,
             summary: _Summary, extension: bool) -> dict[str, Any]:
    """``objects``: per participant its type, name, frame intervals and static data (size,
    classification PMF, speed and acceleration extremes, ``is_recorder``, ``attached_to``; ``pid``:
    the participant of each state row)."""
    part_ids, classes, height = static.part_ids, static.classes, static.height
    length, width = static.length, static.width
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
    p_nulls = {c: p.column(c).is_null().to_numpy(zero_copy_only=False) for c in
               ("height", "length_std", "width_std", "height_std", "class_pmf") if c in p.column_names}
    objects: dict[str, Any] = {}
    for j, q in enumerate(part_ids.tolist()):
        cls = classes[j]
        rows = order[bounds[0][j]:bounds[1][j]]
        hh = height[q]
        size = {"name": "dimensions/size", "val": [float(length[q]), float(width[q]), 0.0 if math.isnan(hh) else hh]}
        vec = [size]
        if any(c in p.column_names for c in ("length_std", "width_std")):
            vec.append({"name": "dimensions/size/ustddev",
                        "val": static.size_std[j].tolist()})
        if pmf is not None and np.isfinite(pmf[j]).all():
            w = pmf[j].astype(np.float64)
            w = w / w.sum()
            vec.append({"name": "classification/uncertainties", "val": [float(v) for v in w]})
        num = []
        if len(rows):
            num += [{"name": "summary/speed/max", "val": float(summary.speed_max[j])},
                    {"name": "summary/speed/min", "val": float(summary.speed_min[j])},
                    {"name": "summary/accel/max", "val": float(summary.acc_max[j]), "type": "value"},
                    {"name": "summary/accel/min", "val": float(summary.acc_min[j]), "type": "value"}]
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
            for c, isnull in p_nulls.items():
                if isnull[j]:
                    ext[c] = None
            if pmf is not None and np.isfinite(pmf[j]).all():
                ext["class_pmf"] = [float(v) for v in pmf[j]]
            size[EXT] = json_safe(ext)
        objects[str(q)] = {
            "name": str(source_ids[j]) if source_ids else str(q),
            "type": CLASS_TO_TYPE[cls],
            "frame_intervals": _intervals(frame_of_row[rows]),
            "object_data": obj_data,
        }
    return objects


def _contexts(rec, times: np.ndarray, summary: _Summary) -> dict[str, Any]:
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
    if summary.count.sum():
        num.append({"name": "scenario/maximum_vehicle_speed", "val": summary.max_speed})
        if math.isfinite(summary.moving_min):
            num.append({"name": "scenario/minimum_vehicle_speed", "val": summary.moving_min})
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
            out[str(k + 2)] = {"name": "environment_context", "type": "EnvironmentContext",
                               "frame_intervals": _interval(times, r), "context_data": environment_data(r)}
    return out


def _interval(times: np.ndarray, r: dict[str, Any]) -> list[dict[str, int]]:
    """The frame interval of a row's ``time_start`` .. ``time_end``."""
    last = max(len(times) - 1, 0)
    fs = int(np.clip(np.searchsorted(times, r["time_start"] - 1e-9), 0, last))
    fe = int(np.clip(np.searchsorted(times, r["time_end"] + 1e-9) - 1, fs, last))
    return [{"frame_start": fs, "frame_end": fe}]


def _events(ev: pa.Table | None, times: np.ndarray) -> dict[str, Any]:
    """``events``: the recording's events of the profile's types, with their frame intervals."""
    events = {}
    if ev is not None and ev.num_rows:
        for r in ev.to_pylist():
            etype = EVENT_TO_TYPE.get(str(r["kind"]))
            ids = r["participant_ids"] or []
            if etype is None or not ids:
                continue
            events[str(r["event_id"])] = {
                "name": f"{etype}{r['event_id']}", "type": etype, "frame_intervals": _interval(times, r),
                "event_data": {
                    "text": [{"name": "event_participant/role_a_id", "val": str(ids[0]), "type": "value"}],
                    "vec": [{"name": "event_participants/role_b_ids", "val": [str(v) for v in ids[1:]],
                             "type": "values"}],
                },
            }
    return events


def _extension(rec, thr: dict[str, Any], states_columns: list[str]) -> dict[str, Any]:
    """``metadata.aveas_format``: what the profile cannot carry (recording.json, the small tables,
    column lists, the derived tables with their recording.json entries)."""
    meta, p = rec.meta, rec.participants
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
        "states_columns": states_columns,
        "participants_columns": p.column_names,
        "tables": {name: table_to_json(getattr(rec, name)) for name in
                   ("unobserved", "events", "environment", "interior")
                   if getattr(rec, name) is not None},
        # derived tables (columnar) and their recording.json ``derived`` entries
        "derived": {name: table_to_json(t) for name, t in sorted((rec.derived or {}).items())
                    if t is not None},
        "derived_entries": [e.model_dump(mode="json", exclude_none=True) for e in meta.derived],
    })


def _map_name(output: Path, options: OpenLabelExportOptions) -> str:
    name = output.name
    if compression(output):
        name = name[:-len(output.suffix)]
    stem = name[:-5] if name.endswith(".json") else Path(name).stem
    return options.map_file or f"{stem}.xodr"


def _outputs(output: Path, options: OpenLabelExportOptions) -> list[Path]:
    """The export's files: the JSON and, with ``write_map``, the map next to it."""
    return [output] + ([output.parent / _map_name(output, options)] if options.write_map else [])


@converter("openlabel", direction="export", options=OpenLabelExportOptions, outputs=_outputs,
           streams_states=True,
           description="ASAM OpenLABEL 1.0 JSON, AVEAS profile (+ the map as .xodr next to it); "
                       "OUT.json.gz / OUT.json.zst: compressed")
def export_openlabel(rec, output: Path, *, options: OpenLabelExportOptions) -> list[Path]:
    from aveas_format.safeio import write_chunks_atomic

    output = Path(output)
    map_name = _map_name(output, options)
    kind = compression(output)
    plain = not kind and not options.indent
    from aveas_format.parallel import default_workers

    chunks = openlabel_chunks(rec, opendrive=map_name, extension=options.extension,
                              road_attributes=options.road_attributes,
                              workers=(options.workers or default_workers()) if plain else 1,
                              spill_dir=output.parent)  # (parts: only with workers > 1)
    if options.indent:  # human-readable: the document whole (compact files are streamed)
        doc = json.loads(b"".join(chunks))
        chunks = iter([json.dumps(doc, indent=options.indent, allow_nan=False).encode()])
    if kind:
        chunks = compressed(chunks, kind)
    written = [write_chunks_atomic(output, chunks)]
    if options.write_map and rec.map_source is not None:
        from aveas_format.converters.common.companion import write_companion_map

        written.append(write_companion_map(rec, output.parent / map_name))
    return written

