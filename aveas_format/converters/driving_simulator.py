"""Driving-simulator log (subject vehicle + surrounding traffic) -> recording.

Input: one CSV or Parquet table per simulator run (several files are concatenated), one row per
object and time step, in the simulator's map frame (the OpenDRIVE map the run used, ``--map``):

| column | unit | required | meaning |
|---|---|---|---|
| ``time`` | s | yes | since the start of the run |
| ``id`` | | yes | object id; the subject vehicle's id is the ``subject_id`` option (default ``ego``) |
| ``x``, ``y`` | m | yes | reference point of the object (``reference_offset`` m ahead of the footprint centre) |
| ``z`` | m | no | height |
| ``heading`` | rad (``angle_unit``) | yes | yaw, counter-clockwise from +x (``heading_convention="navigation"``: 0 = north, clockwise) |
| ``vx``, ``vy`` or ``speed`` | m/s | yes | velocity in the map frame, or speed along the heading |
| ``ax``, ``ay``, ``yaw_rate`` | m/s², rad/s | no | |
| ``length``, ``width``, ``height`` | m | no | size (default per class: car 4.5 x 1.8 x 1.5 m); the first row of an object counts |
| ``class`` | | no | one of the format's 13 classes (default ``car``) |
| ``light_brake``, ``light_indicator_left``, ``light_indicator_right``, ``light_hazard``, ``light_reverse``, ``light_front``, ``light_high_beam`` | 0/1 | no | light states -> ``light_*_p`` |

Interior columns (FORMAT.md section 9; read on the subject's rows, written to ``interior``):
``steering_angle``, ``steering_wheel_angle``, ``driver_head_yaw``/``_pitch``/``_roll``,
``driver_gaze_yaw``/``_pitch`` (rad, or ``angle_unit``), ``accelerator_pedal``, ``brake_pedal``
(0..1), ``gear`` (integer, negative = reverse), ``automation_longitudinal``, ``automation_lateral``,
``takeover_request``, ``hands_on_wheel`` (0/1 or probabilities; a ``_p`` suffix is accepted) and
``driver_focus`` (a label: road_ahead, mirrors, instrument_cluster, infotainment, handheld_device,
other -> one-hot PMF). Each may have a ``_std`` column.

What the converter does: positions moved by ``-reference_offset`` along the heading to the footprint
centre; angles to radians and the format's convention; velocity from ``speed`` along the heading
where no ``vx``/``vy``. The subject gets role ``subject_role`` (default ``recording_vehicle``) and
provenance ``subject_provenance`` (default ``staged``: a person driving in an experiment); the
traffic is ``simulated_agent`` / ``simulated``; the recording is ``mixed`` when the two differ. The
simulator's state is exact: every ``_std`` is 0. Method ``driving_simulator``.

Tested on: simulator logs (CSV/Parquet) written here from an analytic truth
(tests/converters/test_driving_simulator.py); no log of a real simulator is in ``../shared/data``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Rows, Sensor
from aveas_format.converters.common.geometry import move_along_heading
from aveas_format.converters.common.tables import factorize, header_names, read_table
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes
from aveas_format.schema.taxonomy import CLASSES, DRIVER_FOCUS

DEFAULT_SIZE = {"car": (4.5, 1.8, 1.5), "van": (5.5, 2.0, 2.2), "truck": (12.0, 2.5, 3.5),
                "bus": (12.0, 2.55, 3.2), "trailer": (8.0, 2.5, 3.5), "motorcycle": (2.2, 0.8, 1.4),
                "bicycle": (1.8, 0.6, 1.7), "pedestrian": (0.5, 0.6, 1.75),
                "mobility_device": (1.0, 0.7, 1.4), "pushable_pullable": (1.0, 0.6, 1.0),
                "animal": (1.5, 0.6, 1.2), "railvehicle": (30.0, 2.65, 3.5), "other": (2.0, 1.0, 1.5)}
LIGHTS = ("light_brake", "light_indicator_left", "light_indicator_right", "light_hazard",
          "light_reverse", "light_front", "light_high_beam")
INTERIOR_ANGLES = ("steering_angle", "steering_wheel_angle", "driver_head_yaw", "driver_head_pitch",
                   "driver_head_roll", "driver_gaze_yaw", "driver_gaze_pitch")
INTERIOR_REAL = INTERIOR_ANGLES + ("accelerator_pedal", "brake_pedal")
INTERIOR_PROB = ("automation_longitudinal", "automation_lateral", "takeover_request",
                 "hands_on_wheel")


class DrivingSimulatorOptions(ImportOptions):
    subject_id: str = "ego"
    """Id of the subject (driven) vehicle in the ``id`` column."""
    angle_unit: Literal["rad", "deg"] = "rad"
    """Unit of heading, yaw rate and the interior angles."""
    heading_convention: Literal["math", "navigation"] = "math"
    """math: counter-clockwise from +x; navigation: 0 = north, clockwise."""
    reference_offset: float = 0.0
    """Metres the logged point lies ahead of the footprint centre (e.g. rear axle: negative)."""
    subject_role: Literal["recording_vehicle", "system_under_test"] = "recording_vehicle"
    """Role of the subject vehicle."""
    subject_provenance: Literal["staged", "simulated"] = "staged"
    """staged: a person drove it in the experiment; simulated: a driver model did."""
    simulator: str = "driving simulator"
    """Name of the simulator (acquisition.platform)."""


def _strings(t: pa.Table, name: str) -> np.ndarray:
    return np.asarray(t.column(name).cast(pa.string()).to_pylist(), dtype=object)


def _is_simulator_log(path: Path, head: bytes) -> bool:
    """A header with ``time, id, x, y, heading`` and ``vx, vy`` or ``speed``."""
    names = header_names(path, head)
    return {"time", "id", "x", "y", "heading"} <= names and ({"vx", "vy"} <= names or "speed" in names)


@converter("driving-simulator", description="Driving-simulator log: subject vehicle with interior "
           "columns + surrounding traffic (CSV/Parquet)", patterns=("*.csv", "*.parquet"),
           method="driving_simulator", options=DrivingSimulatorOptions, sniff=_is_simulator_log)
def convert_driving_simulator(inputs: list[Path], *, map_source, options: DrivingSimulatorOptions):
    log = _Log(inputs)
    # the subject first, then traffic in order of appearance
    ids = log.text("id").astype(str)
    is_subj = ids == options.subject_id
    if not is_subj.any():
        raise FormatError(f"no rows of the subject vehicle {options.subject_id!r} (option "
                          "subject_id)", path=log.parts[0][0])
    codes, uniq = factorize(np.where(is_subj, "\x00subject", ids))
    subj_code = int(codes[np.flatnonzero(is_subj)[0]])
    remap = np.empty(len(uniq), np.int64)
    others = [k for k in range(len(uniq)) if k != subj_code]
    remap[subj_code] = 0
    remap[others] = np.arange(1, len(uniq))
    source_ids = np.empty(len(uniq), dtype=object)
    source_ids[0] = options.subject_id
    source_ids[remap[others]] = uniq[others]
    t = log.num("time")
    boxes = Boxes(remap[codes], t, log.num("x"), log.num("y"), source_ids=source_ids.astype(str),
                  rows=Rows([p for p, _ in log.parts], file=log.files, place=log.lines)).sort()
    for k, v in _state_columns(log, options).items():
        boxes[k] = v[boxes.order]
    if options.reference_offset:  # the logged point -> the footprint centre
        boxes["x"], boxes["y"] = move_along_heading(boxes["x"], boxes["y"], boxes["heading"],
                                                    -options.reference_offset)
    m = boxes.m
    classes, size = _classes_and_sizes(log, boxes)
    provenance = np.array([options.subject_provenance] + ["simulated"] * (m - 1), dtype=object)
    roles = np.array([options.subject_role] + ["simulated_agent"] * (m - 1), dtype=object)
    participants = {
        "class": classes, "length": size[:, 0], "width": size[:, 1], "height": size[:, 2],
        "length_std": np.zeros(m), "width_std": np.zeros(m), "height_std": np.zeros(m),
        "role": roles, "provenance": provenance,
        "attributes": [json.dumps({"subject": True})] + ["{}"] * (m - 1),
    }
    rate_dt = np.diff(np.unique(t[is_subj]))
    rate = float(round(1.0 / np.median(rate_dt), 6)) if len(rate_dt) else None
    subj_prov = options.subject_provenance
    sensor = Sensor(
        method="driving_simulator", partner="driving simulator experiment", nominal_rate_hz=rate,
        provenance=subj_prov if subj_prov == "simulated" or m == 1 else "mixed",
        platform=options.simulator,
        sensors=[{"id": "simulator", "kind": "simulator", **({"rate_hz": rate} if rate else {})}])
    return to_recording(boxes, sensor, converter="driving-simulator",
                        inputs=[p for p, _ in log.parts], options=options,
                        map_bytes=load_map_bytes(map_source), participants=participants,
                        interior=_interior(log, is_subj, t, options.angle_unit == "deg"))


class _Log:
    """The log's tables (one per input file, checked), their rows as one: each row's file and
    line, the columns all files have (``names``), numbers (``num``) and texts (``text``)."""

    def __init__(self, inputs: list[Path]) -> None:
        self.parts = []
        for p in inputs:
            t = read_table(p, required=("time", "id", "x", "y", "heading"))
            numeric = [c for c in t.column_names if c not in ("id", "class", "driver_focus")]
            t = read_table(p, numeric=numeric)
            for c in ("time", "x", "y", "heading"):
                bad = np.flatnonzero(~np.isfinite(column_numpy(t, c)))
                if len(bad):
                    raise FormatError(f"column {c!r} is empty", path=p, line=int(bad[0]) + 2)
            if not ({"vx", "vy"} <= set(t.column_names) or "speed" in t.column_names):
                raise FormatError("the log needs 'vx' and 'vy' or 'speed'", path=p)
            self.parts.append((p, t))
        n_rows = [t.num_rows for _, t in self.parts]
        self.files = np.repeat(np.arange(len(self.parts)), n_rows)
        self.lines = np.concatenate([np.arange(n) + 2 for n in n_rows])
        self.names = set.intersection(*(set(t.column_names) for _, t in self.parts))
        ids = self.text("id")
        if (ids == None).any():  # noqa: E711 - object array
            i = int(np.flatnonzero(ids == None)[0])  # noqa: E711
            raise FormatError("column 'id' is empty", path=self.parts[self.files[i]][0],
                              line=int(self.lines[i]))

    def num(self, name: str, default: float = np.nan) -> np.ndarray:
        if name not in self.names:
            return np.full(len(self.lines), default)
        return np.concatenate([column_numpy(t, name) for _, t in self.parts])

    def text(self, name: str) -> np.ndarray | None:
        if name not in self.names:
            return None
        return np.concatenate([_strings(t, name) for _, t in self.parts])

    def where(self, i: int) -> dict[str, Any]:
        return {"path": self.parts[self.files[i]][0], "line": int(self.lines[i])}


def _state_columns(log: _Log, options: DrivingSimulatorOptions) -> dict[str, Any]:
    """The states columns of the log's rows: angles to radians and the format's convention,
    velocity from ``speed`` along the heading where there is no vx/vy, positions moved to the
    footprint centre, lights as probabilities; the simulator's state is exact (std 0)."""
    names = log.names
    deg = options.angle_unit == "deg"
    heading = log.num("heading")
    heading = np.radians(heading) if deg else heading
    if options.heading_convention == "navigation":
        heading = np.pi / 2 - heading
    if "vx" in names and "vy" in names:
        vx, vy = log.num("vx"), log.num("vy")
    else:
        speed = log.num("speed")
        vx, vy = speed * np.cos(heading), speed * np.sin(heading)
    n = len(heading)
    out: dict[str, Any] = {"heading": heading, "vx": vx, "vy": vy,
                           **{f"{c}_std": np.zeros(n) for c in ("x", "y", "heading", "vx", "vy")}}
    if "z" in names:
        out["z"], out["z_std"] = log.num("z"), np.zeros(n)
    for c in ("ax", "ay"):
        if c in names:
            out[c] = log.num(c)
    if "yaw_rate" in names:
        yr = log.num("yaw_rate")
        out["yaw_rate"] = np.radians(yr) if deg else yr
        if options.heading_convention == "navigation":
            out["yaw_rate"] = -out["yaw_rate"]
    for c in LIGHTS:
        for name in (c, f"{c}_p"):
            if name in names:
                v = log.num(name)
                _check_prob(v, name, log, np.arange(n))
                out[f"{c}_p"] = v.astype(np.float32)
    return out


def _classes_and_sizes(log: _Log, boxes: Boxes) -> tuple[np.ndarray, np.ndarray]:
    """Class and size (length, width, height) of each object: its first row's, the class's
    defaults where the row has none."""
    first = boxes.order[boxes.first_rows()]
    cls_rows = log.text("class")
    classes = (np.full(boxes.m, "car", dtype=object) if cls_rows is None
               else cls_rows[first].astype(object))
    for k, c in enumerate(classes):
        c = "car" if c is None or c == "" else str(c).strip().lower()
        if c not in CLASSES:
            raise FormatError(f"column 'class': {c!r} is not one of {list(CLASSES)}",
                              **log.where(first[k]))
        classes[k] = c
    size = np.array([DEFAULT_SIZE[c] for c in classes])
    for j, name in enumerate(("length", "width", "height")):
        v = log.num(name)[first]
        size[:, j] = np.where(np.isfinite(v) & (v > 0), v, size[:, j])
    return classes, size


def _check_prob(v: np.ndarray, name: str, log: _Log, rows: np.ndarray) -> None:
    """Values (of the log's ``rows``) outside [0, 1]: an error naming the first's file and line."""
    bad = np.flatnonzero(np.isfinite(v) & ((v < 0) | (v > 1)))
    if len(bad):
        i = bad[0]
        raise FormatError(f"column {name!r}: {v[i]:g} is not a probability in [0, 1]",
                          **log.where(int(rows[i])))


def _interior(log: _Log, is_subj: np.ndarray, t: np.ndarray, deg: bool) -> dict[str, Any] | None:
    """The interior table: the subject's rows (sorted by time) of the interior columns."""
    names, num = log.names, log.num
    rows = np.flatnonzero(is_subj)
    rows = rows[np.argsort(t[rows], kind="stable")]
    cols: dict[str, Any] = {}
    for c in INTERIOR_REAL:
        if c in names:
            v = num(c)
            scale = math.pi / 180 if deg and c in INTERIOR_ANGLES else 1.0
            if c in ("accelerator_pedal", "brake_pedal"):
                _check_prob(v[rows], c, log, rows)
            cols[c] = v[rows] * scale
            std = f"{c}_std"
            cols[std] = num(std, 0.0)[rows] * scale
    for c in INTERIOR_PROB:
        for name in (c, f"{c}_p"):
            if name in names:
                v = num(name)[rows]
                _check_prob(v, name, log, rows)
                cols[f"{c}_p"] = v.astype(np.float32)
    if "gear" in names:
        g = num("gear")[rows]
        cols["gear"] = pa.array(np.nan_to_num(g).astype(np.int8), mask=~np.isfinite(g))
    focus = log.text("driver_focus")
    if focus is not None:
        f = focus[rows]
        codes, uniq = factorize(np.where(f == None, "", f).astype(str))  # noqa: E711
        index = np.full(len(uniq), -1, np.int64)
        for k, lab in enumerate(uniq):
            lab = str(lab).strip().lower()
            if lab == "":
                continue
            if lab not in DRIVER_FOCUS:
                i = rows[int(np.flatnonzero(codes == k)[0])]
                raise FormatError(f"column 'driver_focus': {lab!r} is not one of "
                                  f"{list(DRIVER_FOCUS)}", **log.where(int(i)))
            index[k] = DRIVER_FOCUS.index(lab)
        idx = index[codes]
        pm = np.zeros((len(rows), len(DRIVER_FOCUS)), np.float32)
        pm[idx < 0] = np.nan
        pm[np.flatnonzero(idx >= 0), idx[idx >= 0]] = 1.0
        cols["driver_focus"] = pm
    if not cols:
        return None
    return {"participant_id": np.zeros(len(rows), np.int64), "time": t[rows], **cols}
