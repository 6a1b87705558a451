"""levelX drone datasets (highD; inD, rounD, uniD; exiD) -> recording.

Input: one recording's three CSV files, ``NN_tracks.csv``, ``NN_tracksMeta.csv`` and
``NN_recordingMeta.csv`` (pass any of them, or the folder holding exactly one ``*_tracks.csv``; the
others are found next to it by name). Converters: ``highd`` for highD, ``ind`` for inD, rounD and
uniD (same layout), ``exid`` for exiD.

highD (``highd``; builds its own map, ``--map`` optional):

- ``x``, ``y`` are the **upper-left corner** of the axis-aligned box in image-aligned metres with
  **y pointing down**; ``width`` is the vehicle's *length* (along x), ``height`` its *width*. The
  converter takes the box centre ``(x + width/2, y + height/2)`` and flips y: local
  ``(x, y) = (x + width/2, -(y + height/2))``; velocities and accelerations flip their y component.
- There is no heading column: heading = direction of the velocity where the speed is at least
  ``heading_min_speed``, else the driving direction (``drivingDirection`` 1 = upper lanes, driving
  towards -x, heading pi; 2 = lower lanes, towards +x, heading 0).
- Time = (frame - 1) / ``frameRate`` (highD frames start at 1); ``source_frame`` keeps the frame.
- The map (OpenDRIVE 1.6) is built from ``upperLaneMarkings``/``lowerLaneMarkings`` (image y of
  the markings, ``;``-separated) by :func:`highd_map`: one straight road along +x whose reference
  line runs in the middle of the median, left lanes = the upper carriageway (driving towards -x),
  right lanes = the lower one, each lane as wide as the spacing of its two markings, lanes +-1 of
  type ``median`` between the carriageways; it spans the tracks' x extent plus ``road_margin``.
  highD publishes neither the sites' coordinates nor the road's orientation: the map's
  ``geoReference`` (and so lon/lat) is the ``geo_reference`` option, by default a local transverse
  Mercator at 50.95 N 6.95 E (Cologne, where highD was recorded) with x pointing east, so lon/lat
  are nominal unless the option is given. With ``--map`` the given map is used instead (it must be
  in the same image-aligned, y-up frame).
- With the built map, ``coverage`` is the observed road (the tracks' x extent, the outer markings
  plus ``shoulder_width``) and ``unobserved`` holds the map's surroundings outside it as one
  ``outside_coverage`` region for the whole recording. Occlusions (bridges, trees) are not in the
  data and not claimed.
- ``class`` Car -> car, Truck -> truck (highD's trucks include buses). ``laneId`` changes within a
  track become ``lane_change`` events (origin ``derived``).

inD / rounD / uniD (``ind``) and exiD (``exid``), ``--map`` required (they ship Lanelet2 maps;
exiD also OpenDRIVE):

- ``xCenter``, ``yCenter`` are the box centre in metres, y pointing **up** (north), relative to the
  UTM point ``(xUtmOrigin, yUtmOrigin)`` of recordingMeta; ``heading`` is in degrees,
  counter-clockwise from +x. UTM zone: the ``utm_crs`` option, else WGS 84 / UTM of
  ``lonLocation``/``latLocation`` (EPSG:326zz). Where the map has a ``geoReference``, the UTM
  positions are projected into the map's frame (through its CRS and header ``<offset>``; headings
  and velocities are turned by the local grid convergence). Where it has none, the map is taken to
  be in the tracks' own frame (``x = xCenter``) and the recording's ``crs`` is that UTM zone
  shifted by the origin.
- Time = frame / ``frameRate`` (frames start at 0). ``width``/``length`` are the footprint; VRUs
  whose size is given as 0 get class defaults (pedestrian 0.6 x 0.6 m, bicycle 1.8 x 0.6 m,
  motorcycle 2.2 x 0.8 m) with a 0.3 m std and ``"size_assumed": true`` in their attributes.
- Classes: car, van, truck, bus, trailer, motorcycle, bicycle, pedestrian map to themselves,
  ``truck_bus`` -> truck (the source does not tell them apart), anything else -> other.
- exiD's extra columns are read: ``laneletId`` (a ``;``-separated list where a vehicle covers
  several lanelets) becomes the participant's ``lanelets`` attribute (the Lanelet2 ids it used),
  ``laneChange`` = 1 rows become ``lane_change`` events (origin ``derived``). Lane-relative values
  (``latLaneCenterOffset``, ``lonLaneletPos``, ``odrRoadId``/``odrLaneId``...) are not copied: road
  coordinates are computed through the map.

Uncertainty (all levelX): ``x_std`` = ``y_std`` = ``pixel_std`` x ``gsd`` (ground sampling
distance of the video; highD: 0.10106 m/px, the scale of the highD tools; the other datasets do not
publish the video's GSD (``orthoPxToMeter`` is the scale of the orthophoto, not of the video), so
0.10 m/px is assumed, in line with the datasets' stated typical position error below 10 cm).
``vx_std`` = ``vy_std`` = ``velocity_std`` (levelX velocities come from smoothed tracks);
``heading_std``: highD ``velocity_std / speed`` (capped at 0.1 rad, 0.1 rad where the driving
direction is used), inD family ``heading_std`` (default 2 deg); ``length_std`` = ``width_std`` =
sqrt(2) x position std. ``class_pmf`` puts ``class_confidence`` (default 1) on the labelled class.
Accelerations are copied (``ax``, ``ay``). Method ``aerial``, provenance ``natural``, role
``observed``; an aerial camera sees no lights and no interior (``acquisition.not_observable``).
The recordingMeta row is kept in ``extras.levelx``; its date fields (month, weekday, hour) give no
absolute time, so ``start_time`` is the option's (default 1970-01-01).

Tested on: fixtures written here in the datasets' exact CSV layouts (tracks, tracksMeta,
recordingMeta) from an analytic truth, with maps built from their lane markings (highD) or
written here (tests/converters/test_levelx.py); no recording of the levelX datasets is in
``../shared/data``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Footprint, Rows, Sensor
from aveas_format.converters.common.geometry import projected_to_local, rotate
from aveas_format.converters.common.tables import header_names, is_float, read_table
from aveas_format.converters.labels import class_pmf
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes

HIGHD_GSD = 0.10106  # m per video pixel (the highD tools' scale factor)
DEFAULT_GSD = 0.10
HIGHD_GEO_REFERENCE = ("+proj=tmerc +lat_0=50.95 +lon_0=6.95 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
                       "+units=m +no_defs")
PARTNER = "ika, RWTH Aachen University / fka GmbH (levelXData)"
NOT_OBSERVABLE = ["light_", "interior"]

LEVELX_CLASSES = {
    "car": "car", "van": "van", "truck": "truck", "bus": "bus", "truck_bus": "truck",
    "trailer": "trailer", "motorcycle": "motorcycle", "bicycle": "bicycle",
    "pedestrian": "pedestrian", "animal": "animal",
}
VRU_DEFAULT_SIZE = {"pedestrian": (0.6, 0.6), "bicycle": (1.8, 0.6), "motorcycle": (2.2, 0.8)}


class LevelXOptions(ImportOptions):
    pixel_std: float = 1.0
    """1-sigma position error of the box centre, in video pixels."""
    gsd: float | None = None
    """Ground sampling distance of the video (m/px); default highD 0.10106, others 0.10."""
    velocity_std: float = 0.1
    """1-sigma error of each velocity component (m/s)."""
    class_confidence: float = 1.0
    """Probability put on the labelled class in class_pmf (the rest spread over the others)."""


class HighDOptions(LevelXOptions):
    geo_reference: str = HIGHD_GEO_REFERENCE
    """PROJ string of the image-aligned frame (x right, y up) for the built map; nominal default
    (the shared ``crs`` option, ``--crs``, wins where given)."""
    heading_min_speed: float = 1.0
    """Below this speed (m/s) the heading is the driving direction instead of the velocity's."""
    road_margin: float = 10.0
    """Metres the built road extends beyond the tracks' x extent on each side."""
    shoulder_width: float = 0.0
    """Width of a shoulder lane outside each carriageway's outer marking (0: none)."""


class LevelXCentreOptions(LevelXOptions):
    utm_crs: str | None = None
    """CRS of xUtmOrigin/yUtmOrigin (default: WGS 84 / UTM zone of lonLocation/latLocation)."""
    heading_std: float = math.radians(2.0)
    """1-sigma heading error (rad)."""


class InDOptions(LevelXCentreOptions):
    dataset: Literal["inD", "rounD", "uniD"] | None = None
    """Which of the datasets with this layout (recorded in the platform and site)."""


class ExiDOptions(LevelXCentreOptions):
    pass


# --- files ---------------------------------------------------------------------------------------

_SUFFIXES = ("recordingMeta.csv", "tracksMeta.csv", "tracks.csv")


def find_recording_files(inputs: list[Path]) -> tuple[Path, Path, Path]:
    """(tracks, tracksMeta, recordingMeta) of the one recording the inputs name."""
    keys: set[tuple[Path, str]] = set()
    for p in inputs:
        if p.is_dir():
            found = sorted(p.glob("*tracks.csv"))
            if len(found) != 1:
                raise RecordingIOError(f"expected one *_tracks.csv in the folder, found {len(found)}",
                                       path=p)
            p = found[0]
        suffix = next((s for s in _SUFFIXES if p.name.endswith(s)), None)
        if suffix is None:
            raise RecordingIOError("not a levelX file (expected NN_tracks.csv, NN_tracksMeta.csv "
                                   "or NN_recordingMeta.csv)", path=p)
        keys.add((p.parent, p.name[: -len(suffix)]))
    if len(keys) != 1:
        names = sorted(f"{k[1]}*" for k in keys)
        raise FormatError(f"inputs belong to {len(keys)} recordings ({', '.join(names)}); convert "
                          "one recording at a time")
    folder, prefix = keys.pop()
    out = tuple(folder / f"{prefix}{s}" for s in ("tracks.csv", "tracksMeta.csv", "recordingMeta.csv"))
    for p in out:
        if not p.is_file():
            raise RecordingIOError("levelX file missing (tracks, tracksMeta and recordingMeta are "
                                   "all needed)", path=p)
    return out  # type: ignore[return-value]


def _recording_meta(path: Path, required: tuple[str, ...], numeric: tuple[str, ...]
                    ) -> tuple[dict[str, Any], float]:
    """The one row of recordingMeta.csv and its frame rate."""
    t = read_table(path, required=required, numeric=numeric)
    if t.num_rows < 1:
        raise FormatError("recordingMeta has no data row", path=path)
    row = {k: v[0] for k, v in t.slice(0, 1).to_pydict().items()}
    for k in required:
        if row.get(k) is None or (isinstance(row[k], float) and math.isnan(row[k])):
            raise FormatError(f"column {k!r} is empty", path=path, line=2)
    rate = float(row["frameRate"])
    if not rate > 0:
        raise FormatError(f"column 'frameRate': {rate!r} is not a positive number", path=path, line=2)
    return row, rate


def _markings(value: Any, name: str, path: Path) -> np.ndarray:
    try:
        m = np.array([float(v) for v in str(value).split(";") if v.strip()], np.float64)
    except ValueError:
        raise FormatError(f"column {name!r}: {value!r} is not a ';'-separated list of numbers",
                          path=path, line=2) from None
    if len(m) < 2 or np.any(np.diff(m) <= 0) or not np.isfinite(m).all():
        raise FormatError(f"column {name!r}: {value!r} must list at least two increasing "
                          "marking positions", path=path, line=2)
    return m


def _positive(values: np.ndarray, name: str, path: Path, header_lines: int = 1) -> None:
    bad = np.flatnonzero(~(values > 0))
    if len(bad):
        raise FormatError(f"column {name!r}: {float(values[bad[0]]):g} is not a positive number", path=path,
                          line=int(bad[0]) + 1 + header_lines)


def _finite(table: pa.Table, names: tuple[str, ...], path: Path) -> None:
    for c in names:
        v = column_numpy(table, c)
        bad = np.flatnonzero(~np.isfinite(v))
        if len(bad):
            raise FormatError(f"column {c!r} is empty or not finite", path=path, line=int(bad[0]) + 2)


def _track_index(track_ids: np.ndarray, meta_ids: np.ndarray, tracks_path: Path) -> np.ndarray:
    """Row index into tracksMeta of every tracks row (error naming the line of an unknown id)."""
    order = np.argsort(meta_ids, kind="stable")
    sorted_ids = meta_ids[order]
    pos = np.searchsorted(sorted_ids, track_ids)
    pos = np.clip(pos, 0, len(sorted_ids) - 1)
    found = sorted_ids[pos] == track_ids if len(sorted_ids) else np.zeros(len(track_ids), bool)
    if not found.all():
        i = int(np.flatnonzero(~found)[0])
        raise FormatError(f"track id {track_ids[i]:g} is not in tracksMeta.csv", path=tracks_path,
                          line=i + 2)
    return order[pos]


def _lane_changes(boxes: Boxes, mask: np.ndarray | None, source: str) -> dict[str, Any] | None:
    """``lane_change`` events (origin ``derived``) at the sorted boxes where ``mask`` holds."""
    idx = np.flatnonzero(mask) if mask is not None else []
    if not len(idx):
        return None
    n = len(idx)
    return {
        "event_id": np.arange(n, dtype=np.int64), "kind": ["lane_change"] * n,
        "time_start": boxes.time[idx], "time_end": boxes.time[idx],
        "participant_ids": pa.array([[int(p)] for p in boxes.pid[idx]], pa.list_(pa.int64())),
        "roles": pa.array([["actor"]] * n, pa.list_(pa.string())), "origin": ["derived"] * n,
        "attributes": [json.dumps({"source": source})] * n,
    }


def _jsonable(row: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in row.items():
        if isinstance(v, float) and not math.isfinite(v):
            v = None
        out[k] = v if isinstance(v, (int, float, str, bool, type(None))) else str(v)
    return out


# --- highD ---------------------------------------------------------------------------------------

def highd_map(upper: np.ndarray, lower: np.ndarray, x_start: float, x_end: float, *,
              geo_reference: str | None = HIGHD_GEO_REFERENCE, shoulder_width: float = 0.0,
              speed_limit: float | None = None, name: str = "highD") -> str:
    """OpenDRIVE 1.6 text of a highD site from its lane markings (image y, metres, y down).

    One straight road along +x from ``x_start`` to ``x_end`` in the image-aligned y-up frame
    (local y = -image y). Its reference line runs along the middle of the median; left lanes
    (ids 2, 3, ... outwards, lane 1 the median half) are the upper carriageway (traffic towards
    -x), right lanes (-2, -3, ..., lane -1 the median half) the lower one. Each driving lane spans
    two adjacent markings. Without a median (the two inner markings coincide) lanes +-1 are the
    innermost driving lanes.
    """
    from aveas_format.opendrive.model import (
        Geometry, Header, Lane, LaneSection, Road, RoadMark, RoadType)
    from aveas_format.opendrive.writer import write_xodr

    upper = np.asarray(upper, np.float64)
    lower = np.asarray(lower, np.float64)
    if len(upper) < 2 or len(lower) < 2:
        raise ValueError("each carriageway needs at least two markings")
    if np.any(np.diff(upper) <= 0) or np.any(np.diff(lower) <= 0) or upper[-1] > lower[0]:
        raise ValueError("markings must increase downwards, upper carriageway above the lower")
    if x_end <= x_start:
        raise ValueError("x_end must be greater than x_start")
    median = float(lower[0] - upper[-1])
    y_ref = -(upper[-1] + lower[0]) / 2.0  # local y of the reference line

    def mark(kind: str) -> RoadMark:
        return RoadMark(s_offset=0.0, type=kind, attributes={
            "weight": "standard", "color": "standard", "width": "0.15",
            "laneChange": "both" if kind == "broken" else "none"})

    def side(widths: list[float], sign: int) -> list[Lane]:
        lanes = []
        k = 1
        if median > 1e-3:
            lanes.append(Lane(id=sign * k, type="median", widths=np.array([[0, median / 2, 0, 0, 0]]),
                              road_marks=[mark("solid")]))
            k += 1
        for i, w in enumerate(widths):
            outer = i == len(widths) - 1
            lanes.append(Lane(id=sign * k, type="driving", widths=np.array([[0, w, 0, 0, 0]]),
                              road_marks=[mark("solid" if outer else "broken")]))
            k += 1
        if shoulder_width > 0:
            lanes.append(Lane(id=sign * k, type="shoulder",
                              widths=np.array([[0, shoulder_width, 0, 0, 0]]),
                              road_marks=[mark("none")]))
        return lanes

    left = side([float(w) for w in np.diff(upper)[::-1]], 1)
    right = side([float(w) for w in np.diff(lower)], -1)
    length = float(x_end - x_start)
    road = Road(
        id="1", name=name, length=length,
        types=[RoadType(s=0.0, type="motorway", country="DE",
                        speed_max=None if speed_limit is None else repr(float(speed_limit)),
                        speed_unit=None if speed_limit is None else "m/s")],
        geometries=[Geometry(s=0.0, x=float(x_start), y=float(y_ref), hdg=0.0, length=length,
                             kind="line")],
        lane_sections=[LaneSection(s=0.0, left=left,
                                   center=Lane(id=0, type="none", road_marks=[mark("none")]),
                                   right=right)],
    )
    top = -float(upper[0]) + shoulder_width
    bottom = -float(lower[-1]) - shoulder_width
    header = Header(rev_major=1, rev_minor=6, name=name, vendor="aveas_format", north=top,
                    south=bottom, east=float(x_end), west=float(x_start), geo_reference=geo_reference)
    return write_xodr((header, [road], []))


_HIGHD_TRACKS = ("frame", "id", "x", "y", "width", "height", "xVelocity", "yVelocity")
_HIGHD_META = ("id", "width", "height", "class", "drivingDirection")


def _is_highd(path: Path, head: bytes) -> bool:
    """A header of highD's tracks (``frame, id, xVelocity``), tracksMeta (``drivingDirection``)
    or recordingMeta (``upperLaneMarkings``)."""
    names = header_names(path, head)
    return ({"frame", "id", "xVelocity"} <= names or {"id", "drivingDirection"} <= names
            or "upperLaneMarkings" in names)


def _is_centre(exid: bool):
    """The sniff of inD/rounD/uniD (``exid`` False) or exiD: tracks with box centres (exiD's with
    lanelet lists), or the meta tables the two share."""
    def sniff(path: Path, head: bytes) -> bool:
        names = header_names(path, head)
        if {"trackId", "xCenter", "yCenter"} <= names:
            return ("laneletId" in names) == exid
        return {"trackId", "class", "numFrames"} <= names or "xUtmOrigin" in names
    sniff.__doc__ = ("A header of box-centre tracks (``trackId, xCenter, yCenter``" +
                     (", with ``laneletId``)" if exid else ", without ``laneletId``)") +
                     " or of the tracksMeta/recordingMeta tables of the levelX centre layout.")
    return sniff


@converter("highd", description="levelX highD drone recordings (tracks, tracksMeta, recordingMeta "
           "CSV); builds the map from the lane markings",
           patterns=("*_tracks.csv", "*_tracksMeta.csv", "*_recordingMeta.csv"), method="aerial",
           options=HighDOptions, needs_map=False, provides=("partner",), sniff=_is_highd)
def convert_highd(inputs: list[Path], *, map_source=None, options: HighDOptions):
    tracks_p, meta_p, rec_p = find_recording_files(inputs)
    rec, rate = _recording_meta(rec_p, ("frameRate", "upperLaneMarkings", "lowerLaneMarkings"),
                                ("frameRate", "speedLimit", "locationId"))
    upper = _markings(rec["upperLaneMarkings"], "upperLaneMarkings", rec_p)
    lower = _markings(rec["lowerLaneMarkings"], "lowerLaneMarkings", rec_p)
    if upper[-1] > lower[0]:
        raise FormatError("upperLaneMarkings must lie above (smaller y than) lowerLaneMarkings",
                          path=rec_p, line=2)
    meta = _highd_tracks_meta(meta_p)
    boxes, bw, p_meta, changes = _highd_boxes(tracks_p, meta, rate, options)
    gsd = options.gsd if options.gsd is not None else HIGHD_GSD
    size_std = math.sqrt(2.0) * options.pixel_std * gsd
    m = boxes.m
    classes = meta["class"][p_meta]
    participants = {
        "class": classes, "class_pmf": class_pmf(classes, options.class_confidence),
        "length": meta["length"][p_meta], "width": meta["width"][p_meta],
        "length_std": np.full(m, size_std), "width_std": np.full(m, size_std),
        "attributes": [json.dumps({"levelx_class": str(c), "driving_direction": int(d)})
                       for c, d in zip(meta["class_raw"][p_meta], meta["direction"][p_meta])],
    }
    coverage = None
    if map_source is not None:
        map_bytes = load_map_bytes(map_source)
    else:  # the map built from the lane markings; the observed road is the recording's coverage
        x = boxes["x"]
        x0 = math.floor(float(np.min(x - bw / 2.0)) - options.road_margin)
        x1 = math.ceil(float(np.max(x + bw / 2.0)) + options.road_margin)
        limit = rec.get("speedLimit")
        limit = float(limit) if limit is not None and float(limit) > 0 else None
        map_bytes = highd_map(upper, lower, x0, x1, geo_reference=options.crs or options.geo_reference,
                              shoulder_width=options.shoulder_width, speed_limit=limit,
                              name=f"highD location {rec.get('locationId', '')}".strip()).encode()
        top, bottom = -float(upper[0]) + options.shoulder_width, -float(lower[-1]) - options.shoulder_width
        coverage = Footprint(f"POLYGON (({x0} {bottom}, {x1} {bottom}, {x1} {top}, {x0} {top}, "
                             f"{x0} {bottom}))", "drone_camera")
    sensor = _drone(rec, rate, "highD", "motorway", f", GSD {gsd:g} m (levelX highD)",
                    coverage=coverage)
    return to_recording(boxes, sensor, converter="highd", inputs=[tracks_p, meta_p, rec_p],
                        options=options, map_bytes=map_bytes, participants=participants,
                        events=_lane_changes(boxes, changes, "highD laneId"))


def _highd_tracks_meta(meta_p: Path) -> dict[str, np.ndarray]:
    """tracksMeta.csv of highD: id, length (its ``width``: along x), width (``height``),
    driving direction, class (the source's and the format's)."""
    meta = read_table(meta_p, required=_HIGHD_META, numeric=("id", "width", "height", "drivingDirection"))
    _finite(meta, ("id", "width", "height", "drivingDirection"), meta_p)
    out = {"id": column_numpy(meta, "id"), "length": column_numpy(meta, "width"),
           "width": column_numpy(meta, "height"), "direction": column_numpy(meta, "drivingDirection")}
    _positive(out["length"], "width", meta_p)
    _positive(out["width"], "height", meta_p)
    bad = np.flatnonzero((out["direction"] != 1) & (out["direction"] != 2))
    if len(bad):
        raise FormatError(f"column 'drivingDirection': {out['direction'][bad[0]]:g} is neither 1 nor 2",
                          path=meta_p, line=int(bad[0]) + 2)
    out["class_raw"] = np.asarray(meta.column("class").cast(pa.string()).to_pylist(), dtype=object)
    out["class"] = np.array([{"car": "car", "truck": "truck", "bus": "bus"}.get(str(c).strip().lower(), "other")
                             for c in out["class_raw"]], dtype=object)
    return out


def _highd_boxes(tracks_p: Path, meta: dict[str, np.ndarray], rate: float, options: HighDOptions
                 ) -> tuple[Boxes, np.ndarray, np.ndarray, np.ndarray | None]:
    """The boxes of highD's tracks.csv (sorted), their extent along x (for the road's), each
    participant's row of tracksMeta and where its ``laneId`` changes (None without): the upper-left
    corner moved to the box centre and y flipped up, the heading from the velocity (the driving
    direction while slow)."""
    tr = read_table(tracks_p, required=_HIGHD_TRACKS,
                    numeric=_HIGHD_TRACKS + ("xAcceleration", "yAcceleration", "laneId"))
    _finite(tr, _HIGHD_TRACKS, tracks_p)
    if tr.num_rows == 0:
        raise FormatError("no track rows", path=tracks_p)
    frame = column_numpy(tr, "frame")
    tid = column_numpy(tr, "id")
    mi = _track_index(tid, meta["id"], tracks_p)
    bw, bh = column_numpy(tr, "width"), column_numpy(tr, "height")
    _positive(bw, "width", tracks_p)
    _positive(bh, "height", tracks_p)
    vx = column_numpy(tr, "xVelocity")
    vy = -column_numpy(tr, "yVelocity")
    speed = np.hypot(vx, vy)
    moving = speed >= options.heading_min_speed
    with np.errstate(divide="ignore", invalid="ignore"):
        h_std = np.where(moving, np.minimum(options.velocity_std / speed, 0.1), 0.1)
    pos_std = options.pixel_std * (options.gsd if options.gsd is not None else HIGHD_GSD)
    n = tr.num_rows
    has_acc = "xAcceleration" in tr.column_names and "yAcceleration" in tr.column_names
    uniq_ids, pid = np.unique(tid, return_inverse=True)
    boxes = Boxes(
        pid, (frame - min(1.0, float(frame.min()))) / rate, column_numpy(tr, "x") + bw / 2.0,
        -(column_numpy(tr, "y") + bh / 2.0), source_ids=[f"{v:g}" for v in uniq_ids],
        rows=Rows([tracks_p], place=np.arange(n) + 2),
        heading=np.where(moving, np.arctan2(vy, vx), np.where(meta["direction"][mi] == 1, math.pi, 0.0)),
        vx=vx, vy=vy, x_std=np.full(n, pos_std), y_std=np.full(n, pos_std), heading_std=h_std,
        vx_std=np.full(n, options.velocity_std), vy_std=np.full(n, options.velocity_std),
        source_frame=frame.astype(np.int64),
        ax=np.nan_to_num(column_numpy(tr, "xAcceleration")) if has_acc else None,
        ay=np.nan_to_num(-column_numpy(tr, "yAcceleration")) if has_acc else None).sort()
    changes = None
    if "laneId" in tr.column_names:  # a lane change: another laneId than the previous box's
        lane, ps = column_numpy(tr, "laneId")[boxes.order], boxes.pid
        changes = np.r_[False, (ps[1:] == ps[:-1]) & (lane[1:] != lane[:-1])]
    return boxes, bw[boxes.order], mi[boxes.order][boxes.first_rows()], changes


# --- inD / rounD / uniD / exiD ---------------------------------------------------------------------

_CENTRE_TRACKS = ("trackId", "frame", "xCenter", "yCenter", "heading", "width", "length",
                  "xVelocity", "yVelocity")
_CENTRE_META = ("trackId", "width", "length", "class")


def utm_crs_for(lon: float, lat: float) -> str:
    """WGS 84 / UTM zone of a point (EPSG:326zz north, 327zz south)."""
    zone = int((lon + 180.0) // 6.0) + 1
    return f"EPSG:{32600 + zone if lat >= 0 else 32700 + zone}"


def shifted_crs(crs: str, dx: float, dy: float) -> str:
    """A PROJ string whose coordinates are those of the (UTM / transverse Mercator) ``crs`` minus
    ``(dx, dy)``: the frame of the levelX tracks."""
    import pyproj

    from aveas_format.crs import parse_crs

    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # to_dict of an EPSG CRS: PROJ string loss
        d = pyproj.CRS(parse_crs(crs).crs).to_dict()
    proj = d.get("proj")
    if proj == "utm":
        zone = int(d["zone"])
        d = {"proj": "tmerc", "lat_0": 0, "lon_0": 6 * zone - 183, "k": 0.9996, "x_0": 500000.0,
             "y_0": 10000000.0 if d.get("south") else 0.0,
             **{k: v for k, v in d.items() if k in ("ellps", "datum", "towgs84")}}
    elif proj != "tmerc":
        raise FormatError(f"utm_crs {crs!r} is neither UTM nor transverse Mercator")
    d["x_0"] = float(d.get("x_0", 0.0)) - dx
    d["y_0"] = float(d.get("y_0", 0.0)) - dy
    if "ellps" not in d and "datum" not in d:
        d["ellps"] = "WGS84"
    d.pop("type", None)
    d.pop("no_defs", None)
    d.pop("units", None)
    return " ".join(f"+{k}={v!r}" if isinstance(v, float) else f"+{k}={v}"
                    for k, v in d.items()) + " +units=m +no_defs"


def _convert_centre(name: str, inputs: list[Path], map_source, options: LevelXCentreOptions,
                    dataset: str, road_type: str):
    from aveas_format.opendrive import load_map

    tracks_p, meta_p, rec_p = find_recording_files(inputs)
    rec, rate = _recording_meta(rec_p, ("frameRate", "xUtmOrigin", "yUtmOrigin"),
                                ("frameRate", "xUtmOrigin", "yUtmOrigin", "latLocation", "lonLocation",
                                 "orthoPxToMeter", "locationId", "speedLimit"))
    meta = _centre_tracks_meta(meta_p)
    tr = read_table(tracks_p, required=_CENTRE_TRACKS,
                    numeric=_CENTRE_TRACKS + ("xAcceleration", "yAcceleration", "laneChange"))
    _finite(tr, ("trackId", "frame", "xCenter", "yCenter", "heading", "xVelocity", "yVelocity"),
            tracks_p)
    if tr.num_rows == 0:
        raise FormatError("no track rows", path=tracks_p)
    mi = _track_index(column_numpy(tr, "trackId"), meta["id"], tracks_p)
    boxes = _centre_boxes(tr, tracks_p, rate, options)
    p_meta = mi[boxes.order][boxes.first_rows()]
    map_bytes = load_map_bytes(map_source)
    utm = options.utm_crs or _utm_of(rec, rec_p)
    crs = _to_map_frame(boxes, (float(rec["xUtmOrigin"]), float(rec["yUtmOrigin"])), utm,
                        load_map(map_bytes).header)
    assumed = meta["assumed"][p_meta]
    attrs: list[dict[str, Any]] = [{"levelx_class": str(c)} for c in meta["class_raw"][p_meta]]
    for k in np.flatnonzero(assumed):
        attrs[k]["size_assumed"] = True
    if "laneletId" in tr.column_names:
        _lanelets(tr, np.unique(column_numpy(tr, "trackId"), return_inverse=True)[1], tracks_p, attrs)
    changes = (np.nan_to_num(column_numpy(tr, "laneChange"))[boxes.order] > 0.5
               if "laneChange" in tr.column_names else None)
    pos_std = options.pixel_std * (options.gsd if options.gsd is not None else DEFAULT_GSD)
    size_std = np.where(assumed, 0.3, math.sqrt(2.0) * pos_std)
    classes = meta["class"][p_meta]
    participants = {
        "class": classes, "class_pmf": class_pmf(classes, options.class_confidence),
        "length": meta["length"][p_meta], "width": meta["width"][p_meta],
        "length_std": size_std, "width_std": size_std,
        "attributes": [json.dumps(a) for a in attrs],
    }
    sensor = _drone(rec, rate, dataset, road_type, f" (levelX {dataset})", crs=crs, utm_crs=utm)
    return to_recording(boxes, sensor, converter=name, inputs=[tracks_p, meta_p, rec_p],
                        options=options, map_bytes=map_bytes, participants=participants,
                        events=_lane_changes(boxes, changes, f"{dataset} laneChange"))


def _drone(rec: dict[str, Any], rate: float, dataset: str, road_type: str, camera: str, *,
           coverage: Footprint | None = None, crs: str | None = None, **extras: Any) -> Sensor:
    """The sensor of a levelX recording: a drone's 4K camera at ``rate`` fps (``camera``: the
    rest of the platform text), the site from recordingMeta, its row kept in ``extras.levelx``
    after ``extras``."""
    loc = rec.get("locationId")
    return Sensor(
        method="aerial", partner=PARTNER, nominal_rate_hz=rate, coverage=coverage, crs=crs,
        platform=f"drone, 4K camera, {rate:g} fps{camera}",
        sensors=[{"id": "drone_camera", "kind": "rgb_camera", "rate_hz": rate}],
        not_observable=NOT_OBSERVABLE,
        site={"name": f"{dataset} location {loc if loc is None else int(loc)}", "country": "DE",
              "road_type": road_type},
        extras={"levelx": {"dataset": dataset, **extras, **_jsonable(rec)}})


def _utm_of(rec: dict[str, Any], path: Path) -> str:
    lon, lat = rec.get("lonLocation"), rec.get("latLocation")
    if lon is None or lat is None or not (np.isfinite(lon) and np.isfinite(lat)):
        raise FormatError("recordingMeta has no lonLocation/latLocation to choose the UTM zone: "
                          "pass the utm_crs option", path=path)
    return utm_crs_for(float(lon), float(lat))


def _centre_tracks_meta(meta_p: Path) -> dict[str, np.ndarray]:
    """tracksMeta.csv of inD/rounD/uniD/exiD: id, length, width (class defaults for VRUs without
    a size: ``assumed``), class (the source's and the format's)."""
    meta = read_table(meta_p, required=_CENTRE_META, numeric=("trackId", "width", "length"))
    _finite(meta, ("trackId",), meta_p)
    m_id = column_numpy(meta, "trackId")
    m_wid, m_len = np.nan_to_num(column_numpy(meta, "width")), np.nan_to_num(column_numpy(meta, "length"))
    m_cls_raw = np.asarray(meta.column("class").cast(pa.string()).to_pylist(), dtype=object)
    m_cls = np.array([LEVELX_CLASSES.get(str(c).strip().lower(), "other") for c in m_cls_raw],
                     dtype=object)
    assumed = ~((m_len > 0) & (m_wid > 0))
    for i in np.flatnonzero(assumed):
        if m_cls[i] not in VRU_DEFAULT_SIZE:
            raise FormatError(f"track {m_id[i]:g} ({m_cls_raw[i]}) has no positive width/length",
                              path=meta_p, line=int(i) + 2)
        m_len[i], m_wid[i] = VRU_DEFAULT_SIZE[m_cls[i]]
    return {"id": m_id, "length": m_len, "width": m_wid, "class_raw": m_cls_raw, "class": m_cls,
            "assumed": assumed}


def _centre_boxes(tr: pa.Table, path: Path, rate: float, options: LevelXCentreOptions) -> Boxes:
    """The (sorted) boxes of the tracks, in the tracks' frame (metres from the UTM origin)."""
    frame = column_numpy(tr, "frame")
    has_acc = "xAcceleration" in tr.column_names and "yAcceleration" in tr.column_names
    pos_std = options.pixel_std * (options.gsd if options.gsd is not None else DEFAULT_GSD)
    n = tr.num_rows
    uniq_ids, pid = np.unique(column_numpy(tr, "trackId"), return_inverse=True)
    return Boxes(
        pid, (frame - min(0.0, float(frame.min()))) / rate, column_numpy(tr, "xCenter"),
        column_numpy(tr, "yCenter"), source_ids=[f"{v:g}" for v in uniq_ids],
        rows=Rows([path], place=np.arange(n) + 2), heading=np.radians(column_numpy(tr, "heading")),
        vx=column_numpy(tr, "xVelocity"), vy=column_numpy(tr, "yVelocity"),
        x_std=np.full(n, pos_std), y_std=np.full(n, pos_std),
        heading_std=np.full(n, options.heading_std), vx_std=np.full(n, options.velocity_std),
        vy_std=np.full(n, options.velocity_std), source_frame=frame.astype(np.int64),
        ax=np.nan_to_num(column_numpy(tr, "xAcceleration")) if has_acc else None,
        ay=np.nan_to_num(column_numpy(tr, "yAcceleration")) if has_acc else None).sort()


def _to_map_frame(boxes: Boxes, utm0: tuple[float, float], utm: str, header) -> str | None:
    """The boxes moved from the tracks' frame into the map's; the recording's CRS where the map
    has none. With a geoReference the positions (relative to the UTM origin ``utm0`` of the zone
    ``utm``) are projected into the map's frame, headings, velocities and accelerations turned
    by the grid convergence; without one the map is in the tracks' frame, whose CRS is the UTM
    zone shifted by the origin."""
    if not header.geo_reference:
        return shifted_crs(utm, *utm0)
    x, y, rot = projected_to_local(boxes["x"] + utm0[0], boxes["y"] + utm0[1], utm,
                                   header.geo_reference, header.offset)
    boxes["x"], boxes["y"] = x, y
    boxes["heading"] = boxes["heading"] + rot
    boxes["vx"], boxes["vy"] = rotate(boxes["vx"], boxes["vy"], rot)
    if "ax" in boxes:
        boxes["ax"], boxes["ay"] = rotate(boxes["ax"], boxes["ay"], rot)
    return None


def _lanelets(tr: pa.Table, pid: np.ndarray, path: Path, attrs: list[dict[str, Any]]) -> None:
    """exiD ``laneletId`` (';'-separated lists) -> each participant's sorted lanelet ids."""
    col = pc.utf8_trim_whitespace(tr.column("laneletId").cast(pa.string()))
    parts = pc.split_pattern(col, ";")
    flat = pc.utf8_trim_whitespace(pc.list_flatten(parts))
    rows = pc.list_parent_indices(parts).to_numpy()
    keep = pc.and_(pc.is_valid(flat), pc.not_equal(flat, "")).to_numpy(zero_copy_only=False)
    flat, rows = flat.filter(pa.array(keep)), rows[keep]
    try:
        ids = pc.cast(flat, pa.float64()).to_numpy()
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        vals = flat.to_pylist()
        bad = next(i for i, v in enumerate(vals) if not is_float(v))
        raise FormatError(f"column 'laneletId': {vals[bad]!r} is not a ';'-separated list of ids",
                          path=path, line=int(rows[bad]) + 2) from None
    ok = np.isfinite(ids) & (ids >= 0)
    pairs = np.unique(np.stack([pid[rows[ok]], ids[ok].astype(np.int64)], axis=1), axis=0)
    split = np.searchsorted(pairs[:, 0], np.arange(len(attrs) + 1))
    for p in range(len(attrs)):
        attrs[p]["lanelets"] = pairs[split[p]:split[p + 1], 1].tolist()


@converter("ind", description="levelX inD / rounD / uniD drone recordings (tracks, tracksMeta, "
           "recordingMeta CSV) on an OpenDRIVE map of the site",
           patterns=("*_tracks.csv", "*_tracksMeta.csv", "*_recordingMeta.csv"), method="aerial",
           options=InDOptions, provides=("partner",), sniff=_is_centre(exid=False))
def convert_ind(inputs: list[Path], *, map_source, options: InDOptions):
    dataset = options.dataset or "inD"
    road_type = "urban"
    return _convert_centre("ind", inputs, map_source, options, dataset, road_type)


@converter("exid", description="levelX exiD drone recordings (tracks with lanelet lists, "
           "tracksMeta, recordingMeta CSV) on an OpenDRIVE map of the site",
           patterns=("*_tracks.csv", "*_tracksMeta.csv", "*_recordingMeta.csv"), method="aerial",
           options=ExiDOptions, provides=("partner",), sniff=_is_centre(exid=True))
def convert_exid(inputs: list[Path], *, map_source, options: ExiDOptions):
    return _convert_centre("exid", inputs, map_source, options, "exiD", "motorway")
