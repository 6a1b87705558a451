"""Eclipse SUMO floating-car data (FCD) -> recording.

Input: the FCD output of ``sumo --fcd-output fcd.xml`` (XML, optionally gzipped) or its Parquet/CSV
variant (``--fcd-output fcd.parquet``: columns ``timestep_time``, ``vehicle_id``, ``vehicle_x``, ...).

SUMO's conventions and what the converter does with them:

- ``x``, ``y`` are the **front-bumper centre** in the network frame; the converter moves them back
  by half the vehicle length along the heading to the footprint centre. Lengths and widths come from
  the ``vType`` definitions of a route/additional file (option ``vtypes``), else SUMO's defaults per
  vClass (passenger 5.0 x 1.8 m, ...).
- The network frame is the OpenDRIVE map frame shifted by the net's ``netOffset`` when the network
  was made with ``netconvert --opendrive-files`` (option ``net_file`` reads it from the .net.xml,
  or ``net_offset``). With ``--fcd-output.geo`` x/y are lon/lat (option ``geo``, auto-detected from the
  configuration SUMO writes into the file header) and are projected through the map's CRS.
- ``angle`` is navigational (degrees, 0 = north, clockwise) -> heading in radians, counter-clockwise
  from +x. ``speed`` is SUMO's speed *along the lane*; during a lane change the vehicle also moves
  across it and ``angle`` includes that motion. The velocity is built as SUMO defines it: the
  speed along the lane's direction (the map's, at the footprint centre) plus the lateral speed
  across it — ``speedLat`` where the file has it (``--fcd-output.attributes speedLat``, or the
  sublane model), else the motion of the positions across the lane. (The speed along the heading
  is short by v (1 - cos theta) there: with it TTC against SUMO's SSM device is off by a median
  0.4 % during lane changes, with the lane-based velocity 0.05 %; tests/realdata/test_sumo.py.)
- Instantaneous lane changes (SUMO's default: the vehicle is moved one lane width across in one
  step, without lateral speed) are kept as they are and reported by ``validate`` as
  ``kinematics.instant_lane_change``, once per vehicle. ``-O lane_change_duration=N`` reconstructs
  each as a smooth lateral manoeuvre over N seconds centred on the jump (quintic profile: zero
  lateral speed and acceleration at both ends, peak lateral speed 1.875 w / N for a jump of w):
  positions, lateral velocity and heading follow it. The count is recorded in the ``source``
  block (``lane_changes_reconstructed``) and per participant in ``attributes``
  (``reconstructed_lane_changes``, ``lane_change_duration_s``). A jump is a step of 0.5-1.5 lane
  widths into the adjacent lane faster than ``max_lateral_speed`` that the lateral speed does
  not explain (:func:`aveas_format.numeric.instant_lateral_steps`, shared with ``validate``).
- vClass -> class: passenger/private/taxi/emergency/authority/army/vip/custom -> car, delivery -> van,
  truck/trailer -> truck, bus/coach -> bus, motorcycle/moped -> motorcycle, bicycle -> bicycle,
  pedestrian (``<person>`` elements) -> pedestrian, rail* / tram -> railvehicle, else other.
- Provenance ``simulated``, role ``simulated_agent``, all ``_std`` 0 (exact). Lane and position on the
  SUMO lane are not copied: road coordinates are computed from the positions through the map.

Tested on: SUMO's own test outputs ``../shared/data/sumo/fcd_{cartesian,geo}_excerpt.xml``, the
default run ``../shared/data/real/sumo/fcd_default_lanechanges.xml.gz`` (SUMO 1.28, 44 vehicles
with instantaneous lane changes; with and without ``lane_change_duration``) and runs of the
installed SUMO on its inputs with ``--lanechange.duration 3`` against the SSM device
(tests/realdata/test_sumo.py, tests/converters/test_sumo_fcd.py, tests/sim).
"""

from __future__ import annotations

import gzip
import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
from lxml import etree
from pydantic import Field

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Rows, Sensor
from aveas_format.converters.common.geometry import move_along_heading, navigation_deg_to_heading
from aveas_format.converters.common.tables import factorize, header_names, read_table
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes
from aveas_format.safeio import iterparse, xml_parser

# SUMO's vType defaults per vClass: (length, width, height) in m
VCLASS_SIZE: dict[str, tuple[float, float, float]] = {
    "passenger": (5.0, 1.8, 1.5), "private": (5.0, 1.8, 1.5), "taxi": (5.0, 1.8, 1.5),
    "emergency": (6.5, 2.16, 2.86), "authority": (5.0, 1.8, 1.5), "army": (5.0, 1.8, 1.5),
    "vip": (5.0, 1.8, 1.5), "custom1": (5.0, 1.8, 1.5), "custom2": (5.0, 1.8, 1.5),
    "delivery": (6.5, 2.16, 2.86), "truck": (7.1, 2.4, 2.4), "trailer": (16.5, 2.55, 4.0),
    "bus": (12.0, 2.5, 3.4), "coach": (14.0, 2.6, 4.0), "motorcycle": (2.2, 0.9, 1.5),
    "moped": (2.1, 0.8, 1.7), "bicycle": (1.6, 0.65, 1.7), "pedestrian": (0.215, 0.478, 1.719),
    "tram": (22.0, 2.4, 3.2), "rail_urban": (36.5, 3.0, 3.6), "rail": (67.0, 2.84, 3.75),
    "rail_electric": (25.0, 2.84, 3.75), "rail_fast": (25.0, 2.84, 3.75),
}
VCLASS_TO_CLASS = {
    "delivery": "van", "truck": "truck", "trailer": "truck", "bus": "bus", "coach": "bus",
    "motorcycle": "motorcycle", "moped": "motorcycle", "bicycle": "bicycle",
    "pedestrian": "pedestrian", "tram": "railvehicle", "rail_urban": "railvehicle",
    "rail": "railvehicle", "rail_electric": "railvehicle", "rail_fast": "railvehicle",
    "evehicle": "car", "ignoring": "other", "ship": "other", "container": "other",
}
DEFAULT_VTYPES = {"DEFAULT_VEHTYPE": "passenger", "DEFAULT_PEDTYPE": "pedestrian",
                  "DEFAULT_BIKETYPE": "bicycle", "DEFAULT_CONTAINERTYPE": "ignoring",
                  "DEFAULT_TAXITYPE": "taxi", "DEFAULT_RAILTYPE": "rail"}


class SumoFcdOptions(ImportOptions):
    vtypes: list[Path] = []
    """Route/additional files with ``<vType>`` definitions (length, width, height, vClass)."""
    net_file: Path | None = None
    """The SUMO network; its ``<location netOffset>`` is subtracted from x/y."""
    net_offset: tuple[float, float] | None = None
    """netOffset (dx, dy) given directly instead of ``net_file``."""
    geo: bool | None = None
    """x/y are lon/lat (``--fcd-output.geo``); default: read from the file's header."""
    default_vclass: str = "passenger"
    """vClass of types without a definition."""
    lane_change_duration: float = Field(0.0, ge=0.0)
    """Seconds over which each instantaneous lane change (SUMO's default: the vehicle jumps one
    lane width in one step) is reconstructed as a smooth lateral manoeuvre (0: keep the jumps,
    which validate reports as ``kinematics.instant_lane_change``)."""
    max_lateral_speed: float = Field(3.0, gt=0.0)
    """Lateral speed (m/s) above which a step of about one lane width into the adjacent lane
    counts as an instantaneous lane change."""


def _parse_vtypes(paths: list[Path]) -> dict[str, dict[str, float | str]]:
    types: dict[str, dict[str, float | str]] = {}
    for p in paths:
        try:
            root = etree.parse(str(p), xml_parser())
        except (OSError, etree.XMLSyntaxError) as e:
            raise FormatError(f"cannot parse vType file: {e}", path=p,
                              line=getattr(e, "lineno", None)) from None
        for vt in root.iter("vType"):
            vid = vt.get("id")
            if not vid:
                raise FormatError("<vType> without id", path=p, line=vt.sourceline)
            d: dict[str, float | str] = {"vClass": vt.get("vClass", "passenger")}
            for k in ("length", "width", "height"):
                if vt.get(k) is not None:
                    try:
                        d[k] = float(vt.get(k))
                    except ValueError:
                        raise FormatError(f"<vType id={vid!r}> {k}={vt.get(k)!r} is not a number",
                                          path=p, line=vt.sourceline) from None
            types[vid] = d
    return types


def _net_offset(opts: SumoFcdOptions) -> tuple[float, float]:
    if opts.net_offset is not None:
        return opts.net_offset
    if opts.net_file is None:
        return 0.0, 0.0
    if not opts.net_file.is_file():
        raise RecordingIOError("SUMO network not found", path=opts.net_file)
    for _, el in iterparse(str(opts.net_file), tag="location"):
        off = el.get("netOffset", "0,0").split(",")
        try:
            return float(off[0]), float(off[1])
        except (ValueError, IndexError):
            raise FormatError(f"netOffset {el.get('netOffset')!r} is not 'dx,dy'", path=opts.net_file,
                              line=el.sourceline) from None
    return 0.0, 0.0


_COLS = ("time", "id", "x", "y", "angle", "type", "speed", "speed_lat", "kind", "line")


def _read_xml(path: Path) -> tuple[dict[str, list], bool]:
    """Rows of <vehicle>/<person> elements; and whether the header says fcd-output.geo."""
    opener = gzip.open if path.suffix == ".gz" else open
    rows: dict[str, list] = {k: [] for k in _COLS}
    geo = False
    try:
        with opener(path, "rb") as f:
            head = f.read(4096)
            geo = bool(re.search(rb'fcd-output\.geo\s+value="(true|1)"', head))
            f.seek(0)
            time = None
            for event, el in iterparse(f, events=("start", "end"),
                                       tag=("timestep", "vehicle", "person")):
                if el.tag == "timestep":
                    if event == "start":
                        try:
                            time = float(el.get("time"))
                        except (TypeError, ValueError):
                            raise FormatError(f"<timestep> time={el.get('time')!r} is not a number",
                                              path=path, line=el.sourceline) from None
                    else:
                        el.clear()
                    continue
                if event != "end":
                    continue
                a = el.attrib
                if time is None:
                    raise FormatError(f"<{el.tag}> outside a <timestep>", path=path, line=el.sourceline)
                try:
                    rows["x"].append(float(a["x"]))
                    rows["y"].append(float(a["y"]))
                    rows["angle"].append(float(a["angle"]))
                    rows["speed"].append(float(a.get("speed", "nan")))
                    rows["speed_lat"].append(float(a.get("speedLat", "nan")))
                except KeyError as e:
                    raise FormatError(f"<{el.tag} id={a.get('id')!r}> lacks attribute {e.args[0]!r}",
                                      path=path, line=el.sourceline) from None
                except ValueError as e:
                    raise FormatError(f"<{el.tag} id={a.get('id')!r}>: {e}", path=path,
                                      line=el.sourceline) from None
                rows["time"].append(time)
                rows["id"].append(("p:" if el.tag == "person" else "") + a.get("id", ""))
                rows["type"].append(a.get("type", "DEFAULT_PEDTYPE" if el.tag == "person"
                                          else "DEFAULT_VEHTYPE"))
                rows["kind"].append(el.tag)
                rows["line"].append(el.sourceline)
    except etree.XMLSyntaxError as e:
        raise FormatError(f"malformed XML: {e.msg}", path=path, line=e.lineno) from None
    except (OSError, EOFError) as e:
        raise RecordingIOError(f"cannot read: {e}", path=path) from None
    return rows, geo


def _read_tabular(path: Path) -> dict[str, list]:
    t = read_table(path)
    names = set(t.column_names)
    prefix = "vehicle_" if "vehicle_id" in names else ""
    tcol = "timestep_time" if "timestep_time" in names else "time"
    need = [tcol, f"{prefix}id", f"{prefix}x", f"{prefix}y", f"{prefix}angle"]
    missing = [c for c in need if c not in names]
    if missing:
        raise FormatError(f"FCD table lacks columns {missing}", path=path)
    t = read_table(path, numeric=[tcol, f"{prefix}x", f"{prefix}y", f"{prefix}angle",
                                  f"{prefix}speed", f"{prefix}speedLat"])
    t = t.filter(pa.compute.is_valid(t.column(f"{prefix}id")))
    n = t.num_rows
    return {
        "time": column_numpy(t, tcol).tolist(), "id": t.column(f"{prefix}id").cast(pa.string()).to_pylist(),
        "x": column_numpy(t, f"{prefix}x").tolist(), "y": column_numpy(t, f"{prefix}y").tolist(),
        "angle": column_numpy(t, f"{prefix}angle").tolist(),
        "speed": column_numpy(t, f"{prefix}speed", missing=np.nan).tolist(),
        "speed_lat": column_numpy(t, f"{prefix}speedLat", missing=np.nan).tolist(),
        "type": (t.column(f"{prefix}type").cast(pa.string()).to_pylist() if f"{prefix}type" in names
                 else ["DEFAULT_VEHTYPE"] * n),
        "kind": ["vehicle"] * n,
        "line": list(range(2, n + 2)) if path.suffix.lower() == ".csv" else [None] * n,
    }


def _is_fcd(path: Path, head: bytes) -> bool:
    """SUMO's FCD output: ``<fcd-export`` (XML), its Parquet/CSV columns ``timestep_time`` or
    ``vehicle_id``."""
    if path.suffix.lower() in (".parquet", ".csv"):
        return bool(header_names(path, head) & {"timestep_time", "vehicle_id"})
    return b"<fcd-export" in head


@converter("sumo-fcd", description="Eclipse SUMO floating-car data (XML, .xml.gz, Parquet/CSV)",
           patterns=("*.xml", "*.xml.gz", "*.fcd.xml", "*.parquet", "*.csv"),
           method="traffic_simulation", options=SumoFcdOptions, sniff=_is_fcd)
def convert_sumo_fcd(inputs: list[Path], *, map_source, options: SumoFcdOptions):
    rows: dict[str, list] = {k: [] for k in _COLS}
    files: list[int] = []
    geo_detected = False
    for fi, p in enumerate(inputs):
        if p.suffix.lower() in (".parquet", ".csv"):
            part, g = _read_tabular(p), False
        else:
            part, g = _read_xml(p)
        geo_detected |= g
        for k in _COLS:
            rows[k].extend(part[k])
        files += [fi] * len(part["time"])
    if not rows["time"]:
        raise FormatError("no <vehicle> or <person> samples found", path=inputs[0])
    vtypes = {**{k: {"vClass": v} for k, v in DEFAULT_VTYPES.items()}, **_parse_vtypes(options.vtypes)}
    pid, source_ids = factorize(rows["id"])
    boxes = Boxes(pid, rows["time"], rows["x"], rows["y"], source_ids=source_ids,
                  rows=Rows(inputs, file=np.asarray(files), place=np.asarray(rows["line"], dtype=object)),
                  heading=navigation_deg_to_heading(np.asarray(rows["angle"], np.float64))).sort()
    p_types = np.asarray(rows["type"], dtype=object)[boxes.order][boxes.first_rows()]
    size, classes = _sizes_and_classes(p_types, vtypes, options)
    map_bytes = load_map_bytes(map_source)
    from aveas_format.opendrive import load_map

    net = load_map(map_bytes)
    _to_map_frame(boxes, net, geo_detected if options.geo is None else options.geo, options)
    # the footprint centre: half the length behind the front bumper, along the FCD angle
    boxes["x"], boxes["y"] = move_along_heading(boxes["x"], boxes["y"], boxes["heading"],
                                                -size[boxes.pid, 0] / 2.0)
    speed = np.nan_to_num(np.asarray(rows["speed"], np.float64)[boxes.order])
    speed_lat = np.asarray(rows["speed_lat"], np.float64)[boxes.order]
    motion = _lane_motion(net, boxes.pid, boxes.time, boxes["x"], boxes["y"], boxes["heading"],
                          speed, speed_lat, options)
    n = len(boxes)
    for k in ("x", "y", "heading", "vx", "vy"):
        boxes[k] = motion[k]
        boxes[f"{k}_std"] = np.zeros(n)
    m = boxes.m
    recon = np.bincount(boxes.pid[1:][motion["jumps"]], minlength=m) if options.lane_change_duration \
        else np.zeros(m, np.int64)
    attrs = []
    for i, ty in enumerate(p_types):
        a = {"sumo_type": str(ty)}
        if recon[i]:
            a["reconstructed_lane_changes"] = int(recon[i])
            a["lane_change_duration_s"] = options.lane_change_duration
        attrs.append(json.dumps(a))
    participants = {
        "class": np.asarray(classes, dtype=object),
        "length": size[:, 0], "width": size[:, 1], "height": size[:, 2],
        "length_std": np.zeros(m), "width_std": np.zeros(m), "height_std": np.zeros(m),
        "attributes": attrs,
    }
    resolved = {"lateral_speed": motion["lateral_source"]}
    if options.lane_change_duration:
        resolved["lane_changes_reconstructed"] = int(recon.sum())
    sensor = Sensor(method="traffic_simulation", provenance="simulated",
                    partner="Eclipse SUMO simulation", platform="Eclipse SUMO",
                    sensors=[{"id": "sumo", "kind": "simulator"}])
    return to_recording(boxes, sensor, converter="sumo-fcd", inputs=inputs, options=options,
                        map_bytes=map_bytes, participants=participants, resolved=resolved)


def _sizes_and_classes(p_types: np.ndarray, vtypes: dict[str, dict], options: SumoFcdOptions
                       ) -> tuple[np.ndarray, list[str]]:
    """(length, width, height) and class of each participant from its (first seen) type."""
    sizes, classes = [], []
    for ty in p_types:
        d = vtypes.get(ty, {"vClass": options.default_vclass})
        vclass = str(d.get("vClass", options.default_vclass))
        base = VCLASS_SIZE.get(vclass, VCLASS_SIZE["passenger"])
        sizes.append((float(d.get("length", base[0])), float(d.get("width", base[1])),
                      float(d.get("height", base[2]))))
        classes.append(VCLASS_TO_CLASS.get(vclass, "car" if vclass in VCLASS_SIZE else "other"))
    return np.asarray(sizes), classes


def _to_map_frame(boxes: Boxes, net, geo: bool, options: SumoFcdOptions) -> None:
    """Positions from the network frame (minus its offset) or lon/lat (geo FCD, through the map's
    geoReference) into the map's frame."""
    x, y = boxes["x"], boxes["y"]
    if geo:
        from aveas_format.crs import LocalFrame

        from aveas_format.converters.common.geometry import map_crs, missing_crs

        crs = map_crs(net.header, options)
        if crs is None:
            raise missing_crs("geo FCD (lon/lat) needs the map frame's CRS to project")
        x, y = LocalFrame(crs, net.header.offset).from_wgs84(x, y)
    else:
        dx, dy = _net_offset(options)
        x, y = x - dx, y - dy
    boxes["x"], boxes["y"] = x, y


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quintic 0 -> 1 over u in [0, 1] (zero slope and curvature at both ends) and its slope."""
    u = np.clip(u, 0.0, 1.0)
    return u ** 3 * (10 - 15 * u + 6 * u * u), 30 * u ** 2 * (1 - u) ** 2


def _lane_motion(net, pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray,
                 heading: np.ndarray, speed: np.ndarray, speed_lat: np.ndarray,
                 options: SumoFcdOptions) -> dict[str, np.ndarray]:
    """Velocity as SUMO defines it, instantaneous lane changes, and their reconstruction.

    Rows sorted by (participant, time); x, y the footprint centre. SUMO's ``speed`` is the speed along
    the lane; the vehicle's lateral speed is ``speedLat`` where the file has it, else the lateral
    motion of the positions (an instantaneous lane change has none: SUMO moves the vehicle
    across without lateral speed). The lane's direction is the map's at the vehicle's footprint
    centre (the FCD angle off the map). With ``lane_change_duration`` = N > 0 each
    instantaneous lane change becomes a smooth lateral manoeuvre over N s centred on the jump
    (quintic profile, peak lateral speed 1.875 w / N for a jump w): the positions move across by
    the profile, the velocity gets its lateral speed and the heading its direction."""
    from aveas_format.numeric import instant_lateral_steps, same_participant

    n = len(t)
    proj = net.world_to_road_track(x, y, heading, time=t, track_id=pid)
    on = np.asarray(proj.n_candidates) > 0
    road_h = np.asarray(proj.road_heading, np.float64)
    # the lane's direction: the road's, turned to the vehicle's side of travel
    lane_dir = np.where(on, road_h, heading)
    lane_dir = np.where(np.cos(heading - lane_dir) < 0, lane_dir + np.pi, lane_dir)
    width = np.full(n, np.nan)
    if on.any():
        roads = np.asarray(proj.road_id, dtype=object)
        idx = np.flatnonzero(on)
        for rid in set(roads[idx].tolist()):
            sel = idx[roads[idx] == rid]
            inner, outer = net.lane_borders(rid, np.asarray(proj.s)[sel], np.asarray(proj.lane_id)[sel])
            width[sel] = np.abs(outer - inner)
    nx, ny = -np.sin(lane_dir), np.cos(lane_dir)
    same = same_participant(pid)
    dt = np.diff(t)
    ddx, ddy = np.diff(x), np.diff(y)
    has_lat = np.isfinite(speed_lat)
    v_lat_file = np.where(has_lat, speed_lat, speed * np.sin(heading - lane_dir))
    road_id = np.asarray(proj.road_id, dtype=object)
    lane_id = np.asarray(proj.lane_id)
    changed = (road_id[1:] != road_id[:-1]) | (lane_id[1:] != lane_id[:-1])
    jumps = instant_lateral_steps(same, dt, ddx, ddy, lane_dir[:-1], width[:-1], changed,
                                  0.5 * (v_lat_file[1:] + v_lat_file[:-1]), options.max_lateral_speed)
    # lateral offset of the continuous motion (jumps removed), per participant
    lat_step = np.where(same & ~jumps, ddx * nx[:-1] + ddy * ny[:-1], 0.0)
    lat = np.r_[0.0, np.cumsum(lat_step)]
    if has_lat.all():
        v_lat, source = speed_lat, "speedLat (the file's lateral speed)"
    else:
        from aveas_format.numeric import central_differences

        v_lat = central_differences(pid, t, lat, np.zeros(n), std=False)[0]
        v_lat = np.where(has_lat, speed_lat, np.nan_to_num(v_lat))
        source = "from the positions' motion across the lane"
    out_heading = heading.copy()
    if options.lane_change_duration > 0 and jumps.any():
        dur = options.lane_change_duration
        corr = np.zeros(n)
        dcorr = np.zeros(n)
        starts = np.r_[0, np.flatnonzero(~same) + 1]
        ends = np.r_[starts[1:], n]
        seg = np.repeat(np.arange(len(starts)), ends - starts)
        for k in np.flatnonzero(jumps):  # one lane change at a time (few per vehicle)
            j = k + 1
            step = ddx[k] * nx[k] + ddy[k] * ny[k]
            tj = 0.5 * (t[k] + t[j])
            a, b = starts[seg[j]], ends[seg[j]]
            u = (t[a:b] - (tj - dur / 2)) / dur
            sm, slope = _smoothstep(u)
            corr[a:b] += step * (sm - (np.arange(a, b) >= j))
            dcorr[a:b] += step * slope / dur
        x = x + corr * nx
        y = y + corr * ny
        v_lat = v_lat + dcorr
        inside = dcorr != 0
        out_heading = np.where(inside, lane_dir + np.arctan2(v_lat, np.maximum(speed, 1e-9)), heading)
    vx = speed * np.cos(lane_dir) + v_lat * nx
    vy = speed * np.sin(lane_dir) + v_lat * ny
    from aveas_format.numeric import wrap_angle

    return {"x": x, "y": y, "heading": wrap_angle(out_heading), "vx": vx, "vy": vy, "jumps": jumps,
            "lateral_source": source}
