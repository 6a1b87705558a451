"""INTERACTION dataset track files (+ their Lanelet2 map) -> recording.

Input: ``vehicle_tracks_NNN.csv`` (``track_id, frame_id, timestamp_ms, agent_type, x, y, vx, vy,
psi_rad, length, width``) and/or ``pedestrian_tracks_NNN.csv`` (``track_id, frame_id,
timestamp_ms, agent_type, x, y, vx, vy``), with the scenario's map: its Lanelet2 ``.osm``
(converted on the fly, :mod:`aveas_format.opendrive.lanelet2`) or an OpenDRIVE map.

The dataset's conventions and what the converter does with them:

- **Frame.** x/y are metres in UTM zone 31 minus the UTM coordinates of (lat 0, lon 0), the
  frame in which the dataset's maps are drawn (Lanelet2 ``UtmProjector(Origin(0, 0))``). The
  Lanelet2 map is converted in exactly that frame (``+proj=utm +zone=31``, the header ``<offset>``
  holding UTM(0, 0)), so x/y stay as they are and lon/lat come out where the dataset puts them.
  Option ``origin`` names another origin for maps drawn elsewhere.
- **Time.** ``timestamp_ms`` from the first row (``source_frame`` keeps ``frame_id``).
- **Kinematics.** ``psi_rad`` is the heading, ``vx``/``vy`` the velocity, both copied as written
  (the validator checks them against the positions: in the dataset's own test file, track 2 drives
  towards -x with vx = +10, which ``validate`` reports). Pedestrian rows have no heading: it comes
  from the velocity where they move faster than 0.2 m/s, else from the last such state.
- **Classes.** ``car`` -> car, ``truck`` and ``truck_bus`` (the dataset's one label for both) ->
  truck, ``bus``, ``motorcycle``, ``bicycle``, ``pedestrian`` as named, the pedestrian files'
  ``pedestrian/bicycle`` -> pedestrian with a PMF shared half and half with bicycle (the label
  does not say which).
- **Uncertainty.** The dataset states none for its tracks; the converter uses the options
  ``position_std`` (0.1 m), ``velocity_std`` (0.3 m/s), ``heading_std`` (0.05 rad) and
  ``size_std`` (0.1 m) and says so once (a ``source.other`` finding).
- **Ids.** One participant per track id and file kind (``vehicle/12``, ``pedestrian/P3``).

Tested on: the dataset's own test map and ``vehicle_tracks_000.csv`` (``../shared/data/real/lanelet2``)
and on track files written in its layout (tests/converters/test_interaction.py).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Footprint, Rows, Sensor
from aveas_format.converters.common.tables import read_table
from aveas_format.converters.labels import class_pmf
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, UsageError, report_source
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes

VEHICLE_COLUMNS = ("track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy", "psi_rad",
                   "length", "width")
PEDESTRIAN_COLUMNS = ("track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy")
NUMERIC = ("frame_id", "timestamp_ms", "x", "y", "vx", "vy", "psi_rad", "length", "width")
#: INTERACTION agent types -> the format's classes
CLASSES = {"car": "car", "truck": "truck", "bus": "bus", "truck_bus": "truck", "motorcycle": "motorcycle",
           "bicycle": "bicycle", "pedestrian": "pedestrian", "pedestrian/bicycle": "pedestrian"}
#: sizes of participants without one (pedestrian files): length, width [m]
DEFAULT_SIZE = {"pedestrian": (0.6, 0.6), "bicycle": (1.8, 0.6)}


class InteractionOptions(ImportOptions):
    origin: tuple[float, float] = (0.0, 0.0)
    """(lat, lon) of the origin of the tracks' frame (UTM minus the origin's UTM), as the
    dataset's maps are drawn: (0, 0)."""
    position_std: float = Field(0.1, gt=0)
    """x/y std [m]: the dataset states none."""
    velocity_std: float = Field(0.3, gt=0)
    """vx/vy std [m/s]: the dataset states none."""
    heading_std: float = Field(0.05, gt=0)
    """heading std [rad]: the dataset states none."""
    size_std: float = Field(0.1, gt=0)
    """length/width std [m]: the dataset states none."""
    rate_hz: float = Field(10.0, gt=0)
    """Nominal rate (the dataset's tracks are at 10 Hz)."""


def _kind(path: Path, table: pa.Table) -> str:
    name = path.name.lower()
    if name.startswith("pedestrian") or "psi_rad" not in table.column_names:
        return "pedestrian"
    return "vehicle"


def _read(path: Path) -> tuple[str, pa.Table]:
    head = path.read_text(encoding="utf-8", errors="replace").split("\n", 1)[0]
    cols = [c.strip() for c in head.split(",")]
    required = VEHICLE_COLUMNS if "psi_rad" in cols or path.name.lower().startswith("vehicle") \
        else PEDESTRIAN_COLUMNS
    numeric = tuple(c for c in NUMERIC if c in required)
    table = read_table(path, required=required, numeric=numeric)
    for c in numeric:
        col = table.column(c)
        if col.null_count:
            import pyarrow.compute as pc

            row = int(pc.index(pc.is_null(col), True).as_py())
            raise FormatError(f"column {c!r}: empty value", path=path, line=row + 2)
    return _kind(path, table), table


def _map_bytes(map_source: Any, origin: tuple[float, float]) -> bytes:
    """The OpenDRIVE map: converted from a Lanelet2 .osm in the dataset's frame, or as given."""
    data = load_map_bytes(map_source)
    head = data[:2048].lstrip()
    if b"<osm" in head:
        from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive

        conv = lanelet2_to_opendrive(data, origin=origin, projection_kind="utm",
                                     name=Path(str(map_source)).name if not isinstance(map_source, bytes) else None)
        for w in conv.warnings:
            report_source("source.other", f"map: {w}", file=str(map_source) if not isinstance(map_source, bytes) else None)
        return conv.xodr.encode()
    return data


def _heading_from_velocity(pid: np.ndarray, vx: np.ndarray, vy: np.ndarray, min_speed: float = 0.2) -> np.ndarray:
    """Heading of the velocity where faster than ``min_speed``, else the previous moving state's
    (the next one's at a track's start; 0 where a track never moves)."""
    from aveas_format.mapref.build import heading_from_velocity

    return heading_from_velocity(pid, vx, vy, min_speed)


@converter("interaction", description="INTERACTION dataset track files (vehicle_tracks_*.csv, "
           "pedestrian_tracks_*.csv) with their Lanelet2 map (.osm) or an OpenDRIVE map",
           patterns=("vehicle_tracks_*.csv", "pedestrian_tracks_*.csv"), method="aerial",
           options=InteractionOptions, provides=("partner",))
def convert_interaction(inputs: list[Path], *, map_source, options: InteractionOptions):
    if map_source is None:
        raise UsageError("converter interaction needs the scenario's map: pass --map MAP.osm (Lanelet2) or .xodr")
    parts = []
    for p in inputs:
        kind, table = _read(Path(p))
        if table.num_rows == 0:
            raise FormatError("no track rows", path=p)
        parts.append((Path(p), kind, table))
    # participants: one per (file kind, track id)
    keys, kinds, types, files, lines = [], [], [], [], []
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("frame", "ms", "x", "y", "vx", "vy", "psi",
                                                         "length", "width")}
    for fi, (path, kind, t) in enumerate(parts):
        n = t.num_rows
        tid = t.column("track_id").cast(pa.string()).to_numpy(zero_copy_only=False)
        keys.append(np.array([f"{kind}/{v.strip()}" for v in tid], dtype=object))
        types.append(np.array([str(v).strip().lower() for v in
                               t.column("agent_type").cast(pa.string()).to_numpy(zero_copy_only=False)], dtype=object))
        cols["frame"].append(column_numpy(t, "frame_id"))
        cols["ms"].append(column_numpy(t, "timestamp_ms"))
        for c in ("x", "y", "vx", "vy"):
            cols[c].append(column_numpy(t, c))
        for c, name in (("psi", "psi_rad"), ("length", "length"), ("width", "width")):
            cols[c].append(column_numpy(t, name) if name in t.column_names else np.full(n, np.nan))
        kinds.append(np.full(n, kind, dtype=object))
        files.append(np.full(n, fi))
        lines.append(np.arange(n) + 2)
    key = np.concatenate(keys)
    agent = np.concatenate(types)
    arr = {k: np.concatenate(v).astype(np.float64) for k, v in cols.items()}
    file_idx, line_no = np.concatenate(files), np.concatenate(lines)
    bad = np.flatnonzero(~np.isfinite(arr["x"]) | ~np.isfinite(arr["y"]) | ~np.isfinite(arr["ms"]))
    if len(bad):
        i = int(bad[0])
        raise FormatError("x, y or timestamp_ms is not finite", path=parts[file_idx[i]][0], line=int(line_no[i]))
    unknown = sorted({a for a in agent if a not in CLASSES})
    if unknown:
        i = int(np.flatnonzero(agent == unknown[0])[0])
        raise FormatError(f"agent_type {unknown[0]!r} is none of {sorted(CLASSES)}", path=parts[file_idx[i]][0],
                          line=int(line_no[i]))
    uniq, pid = np.unique(key, return_inverse=True)
    t = (arr["ms"] - arr["ms"].min()) / 1000.0
    o = options
    boxes = Boxes(pid, t, arr["x"], arr["y"], source_ids=uniq,
                  rows=Rows([p for p, _, _ in parts], file_idx, line_no),
                  vx=arr["vx"], vy=arr["vy"], source_frame=arr["frame"].astype(np.int64),
                  length=arr["length"], width=arr["width"]).sort()
    pid, n = boxes.pid, len(boxes)
    psi, vx, vy = arr["psi"][boxes.order], boxes["vx"], boxes["vy"]
    heading = np.where(np.isfinite(psi), psi, np.nan)
    if np.isnan(heading).any():
        heading = np.where(np.isfinite(heading), heading, _heading_from_velocity(pid, vx, vy))
    boxes["heading"] = heading
    for name, std in (("x_std", o.position_std), ("y_std", o.position_std),
                      ("heading_std", o.heading_std), ("vx_std", o.velocity_std),
                      ("vy_std", o.velocity_std)):
        boxes[name] = np.full(n, std)
    report_source("source.other", "the INTERACTION dataset states no uncertainty for its tracks: "
                  f"x/y std {o.position_std:g} m, velocity std {o.velocity_std:g} m/s, heading std "
                  f"{o.heading_std:g} rad, size std {o.size_std:g} m assumed (options position_std, "
                  "velocity_std, heading_std, size_std)", file=str(parts[0][0]))
    # per participant: class, size (median of the track's rows; a class default where none)
    m = len(uniq)
    first = boxes.first_rows()
    p_agent = agent[boxes.order][first]
    classes = np.array([CLASSES[a] for a in p_agent], dtype=object)
    length = np.full(m, np.nan)
    width = np.full(m, np.nan)
    L, W = boxes["length"], boxes["width"]
    bounds = np.r_[first, n]
    for k in range(m):
        seg = slice(bounds[k], bounds[k + 1])
        if np.isfinite(L[seg]).any():
            length[k], width[k] = np.nanmedian(L[seg]), np.nanmedian(W[seg])
    assumed = ~(np.isfinite(length) & (length > 0) & np.isfinite(width) & (width > 0))
    for k in np.flatnonzero(assumed):
        length[k], width[k] = DEFAULT_SIZE.get(classes[k], (4.5, 1.8))
    pmf = class_pmf(classes)
    shared = p_agent == "pedestrian/bicycle"
    if shared.any():
        from aveas_format.schema.pmf import one_hot

        pmf[shared] = (0.5 * one_hot(np.array(["pedestrian"] * int(shared.sum()), dtype=object), "class")
                       + 0.5 * one_hot(np.array(["bicycle"] * int(shared.sum()), dtype=object), "class"))
    participants = {
        "class": classes, "class_pmf": pmf, "length": length, "width": width,
        "length_std": np.where(assumed, 0.3, o.size_std), "width_std": np.where(assumed, 0.3, o.size_std),
        "attributes": [json.dumps({"interaction_agent_type": str(a), **({"size_assumed": True} if s else {})})
                       for a, s in zip(p_agent, assumed)],
    }
    map_bytes = _map_bytes(map_source, o.origin)
    # the dataset draws its map over the area its camera observed: that is the coverage
    from aveas_format.opendrive import load_map

    x0, y0, x1, y1 = load_map(map_bytes).bounds
    coverage = f"POLYGON (({x0} {y0}, {x1} {y0}, {x1} {y1}, {x0} {y1}, {x0} {y0}))"
    site = Path(str(map_source)).stem if not isinstance(map_source, (bytes, bytearray)) else "INTERACTION site"
    sensor = Sensor(method="aerial", platform="drone or fixed camera (INTERACTION dataset)",
                    sensors=[{"id": "camera", "kind": "rgb_camera", "rate_hz": o.rate_hz}],
                    partner="INTERACTION dataset", not_observable=["light_", "interior"],
                    site={"name": site}, coverage=Footprint(coverage, "camera"),
                    nominal_rate_hz=o.rate_hz,
                    extras={"interaction": {"files": [p.name for p, _, _ in parts],
                                            "origin": list(o.origin)}})
    return to_recording(boxes, sensor, converter="interaction", inputs=[p for p, _, _ in parts],
                        options=options, map_bytes=map_bytes, participants=participants)


__all__ = ["InteractionOptions", "convert_interaction"]
