"""Accident reconstructions (GIDAS Pre-Crash-Matrix style) -> recording with its own map.

The layout, modelled on the publicly described GIDAS Pre-Crash Matrix (PCM): one case = a
directory (or the files given one by one), CSV or Parquet, recognised by file name:

- ``participants.csv``: ``participant_id``, ``type`` (car, truck, bus, van, motorcycle, bicycle,
  pedestrian, ... or ``class_map`` names), ``length``, ``width``, optional ``height``; further
  columns (mass, ...) go to the participant's ``attributes``.
- ``dynamics.csv``: ``participant_id``, ``step`` (or ``time`` in s), ``x``, ``y`` (footprint
  centre, m, in the local accident-site frame), ``vx``, ``vy`` (m/s), optional ``ax``, ``ay``
  (m/s^2), ``yaw`` (``yaw_unit``, default degrees, counter-clockwise from +x); optional
  ``ref_offset`` (m ahead of the footprint centre where x, y lie, e.g. the centre of gravity).
  Time = step / ``rate_hz`` (PCM: 100 Hz).
- ``roads.csv``: road lines and markings as polylines: ``road_id``, ``line_id``, ``kind``, ``seq``
  (point order), ``x``, ``y``. Kinds: ``reference`` (or ``centre_line``): the road's reference
  line, its point order the road's direction; ``edge`` and ``lane_marking``: lane borders. Other
  kinds (stop_line, ...) are ignored.
- ``case.csv`` (optional, one row): ``case_id``, ``collision_step`` (or ``collision_time`` in s),
  ``collision_participants`` (ids separated by ``;``), ``position_tol_m``, ``velocity_tol_m_s``,
  ``yaw_tol_deg``, ``accel_tol_m_s2``, ``rate_hz``.

Map: every road becomes an OpenDRIVE road whose reference line follows the ``reference`` polyline
(resampled every ``map_step_m``, headings smoothed, a G1-continuous chain of arcs; a documented
fallback until the map builder has a polyline fitter); each border line's mean signed offset from
the reference line gives the lane widths (left lanes positive, right lanes negative ids), edges
solid and markings broken road marks; a road without border lines gets one ``lane_width`` lane per
side. The map's geoReference is the shared ``crs`` option (``--crs``) where given, else a transverse
Mercator at ``site_lonlat`` (PCM cases are anonymised: the default 0, 0 marks an unknown site).

Collision: the ``case.csv`` step and participants become an ``accident`` event (origin
``annotated``); without them, the first time two footprints overlap (origin ``derived``).
Uncertainty: the stated tolerances are 95 % bounds, std = tol / 1.96 (x, y, vx, vy, ax, ay,
heading); options give the defaults. Provenance ``natural``, method ``accident_reconstruction``,
sampling as given. Lights, interior and the trajectory far from the crash are not observable.

Tested on: PCM-style tables written here from an analytic collision (a car at 10 m/s and a
crossing pedestrian, first contact at 3 s; tests/converters/test_accident.py); no real GIDAS
case is in ``../shared/data``.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Rows, Sensor
from aveas_format.converters.common.geometry import footprint_corners
from aveas_format.converters.common.tables import factorize, read_table
from aveas_format.converters.labels import class_of
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError
from aveas_format.io.arrow import column_numpy
from aveas_format.schema.taxonomy import CLASSES

Z95 = 1.959963984540054


class AccidentOptions(ImportOptions):
    rate_hz: float = 100.0
    """Sampling rate of ``step`` (case.csv rate_hz overrides)."""
    yaw_unit: Literal["deg", "rad"] = "deg"
    """Unit of the dynamics' yaw."""
    position_tol_m: float = 0.5
    """Default 95 % tolerance of positions (m)."""
    velocity_tol_m_s: float = 0.5
    """Default 95 % tolerance of velocities (m/s)."""
    yaw_tol_deg: float = 3.0
    """Default 95 % tolerance of the yaw angle (deg)."""
    accel_tol_m_s2: float = 1.0
    """Default 95 % tolerance of accelerations (m/s^2)."""
    dimension_tol_m: float = 0.05
    """95 % tolerance of lengths and widths (m)."""
    site_lonlat: tuple[float, float] = (0.0, 0.0)
    """WGS 84 lon, lat of the site frame's origin (anonymised cases: 0, 0); ``crs`` wins where given."""
    lane_width: float = 3.5
    """Lane width of roads without border lines (m)."""
    map_step_m: float = 2.0
    """Resampling step of the reference polylines (m)."""
    class_map: dict[str, str] = {}
    """Participant type -> one of the 13 classes."""


# --- reading ---------------------------------------------------------------------------------------

def _files(inputs: list[Path]) -> dict[str, Path]:
    found: dict[str, Path] = {}
    paths: list[Path] = []
    for p in inputs:
        paths.extend(sorted(p.iterdir()) if p.is_dir() else [p])
    for p in paths:
        stem = p.name.split(".")[0].lower()
        for key in ("participants", "dynamics", "roads", "case"):
            if stem == key or stem.endswith("_" + key):
                found[key] = p
    for need in ("participants", "dynamics", "roads"):
        if need not in found:
            raise FormatError(f"accident case lacks its {need}.csv (files: {[p.name for p in paths]})",
                              path=inputs[0])
    return found


def _check_finite(t: pa.Table, cols, path: Path, positive=()):
    for c in cols:
        if c not in t.column_names:
            continue
        a = column_numpy(t, c)
        bad = ~np.isfinite(a) | ((a <= 0) if c in positive else False)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = "must be positive" if np.isfinite(a[i]) else "is missing"
            line = None if path.suffix.lower() == ".parquet" else i + 2
            raise FormatError(f"column {c!r}: value {what}", path=path, line=line,
                              row=i if line is None else None)


# --- map from road lines ---------------------------------------------------------------------------

def _project(points: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s, t) of points on a polyline: arc length of the nearest point and the signed lateral
    offset (positive to the left)."""
    a, b = line[:-1], line[1:]
    d = b - a
    seg_len = np.linalg.norm(d, axis=1)
    s0 = np.r_[0.0, np.cumsum(seg_len)][:-1]
    rel = points[:, None, :] - a[None]
    u = np.clip((rel * d[None]).sum(-1) / np.maximum(seg_len ** 2, 1e-12)[None], 0.0, 1.0)
    near = a[None] + u[..., None] * d[None]
    dist = np.linalg.norm(points[:, None, :] - near, axis=2)
    k = np.argmin(dist, axis=1)
    i = np.arange(len(points))
    cross = d[k, 0] * rel[i, k, 1] - d[k, 1] * rel[i, k, 0]
    return s0[k] + u[i, k] * seg_len[k], np.sign(cross) * dist[i, k]


def polyline_road_geometries(line: np.ndarray, step: float = 2.0):
    """A G1 chain of OpenDRIVE arcs/lines following a polyline: resampled every ``step`` m,
    headings smoothed, curvature = heading change / step. Returns (geometries, length)."""
    from aveas_format.opendrive.model import Geometry

    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    keep = np.r_[True, seg > 1e-9]
    line = line[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))]
    total = float(s[-1])
    if total <= 0:
        raise ValueError("reference line has zero length")
    n = max(int(np.ceil(total / step)), 1)
    ss = np.linspace(0.0, total, n + 1)
    px, py = np.interp(ss, s, line[:, 0]), np.interp(ss, s, line[:, 1])
    if n == 1:
        hd = np.array([np.arctan2(py[1] - py[0], px[1] - px[0])] * 2)
    else:
        hd = np.unwrap(np.arctan2(np.gradient(py), np.gradient(px)))
        if n >= 4:  # light smoothing of vertex kinks
            k = np.array([0.25, 0.5, 0.25])
            hd[1:-1] = np.convolve(hd, k, mode="valid")
    ds = np.diff(ss)
    kappa = np.diff(hd) / ds
    # chain (vectorised: start heading of each piece is a cumulative sum)
    h0 = hd[0] + np.r_[0.0, np.cumsum(kappa * ds)][:-1]
    h1 = h0 + kappa * ds
    straight = np.abs(kappa) < 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        dx = np.where(straight, ds * np.cos(h0), (np.sin(h1) - np.sin(h0)) / kappa)
        dy = np.where(straight, ds * np.sin(h0), (np.cos(h0) - np.cos(h1)) / kappa)
    x0 = px[0] + np.r_[0.0, np.cumsum(dx)][:-1]
    y0 = py[0] + np.r_[0.0, np.cumsum(dy)][:-1]
    geoms = []
    for i in range(n):
        if straight[i]:
            geoms.append(Geometry(s=float(ss[i]), x=float(x0[i]), y=float(y0[i]), hdg=float(h0[i]),
                                  length=float(ds[i]), kind="line"))
        else:
            geoms.append(Geometry(s=float(ss[i]), x=float(x0[i]), y=float(y0[i]), hdg=float(h0[i]),
                                  length=float(ds[i]), kind="arc",
                                  params={"curvature": float(kappa[i])}))
    return geoms, total


def build_map_from_lines(roads: dict[str, dict[str, tuple[str, np.ndarray]]], geo_reference: str,
                         lane_width: float = 3.5, step: float = 2.0, path: Path | None = None) -> str:
    """OpenDRIVE text of roads given as ``{road_id: {line_id: (kind, (n,2) points)}}``."""
    from aveas_format.opendrive.model import Header, Lane, LaneSection, Road, RoadMark, RoadType
    from aveas_format.opendrive.writer import write_xodr

    def mark(kind: str) -> RoadMark:
        return RoadMark(s_offset=0.0, type="solid" if kind == "edge" else "broken",
                        attributes={"weight": "standard", "color": "standard", "width": "0.15",
                                    "laneChange": "none" if kind == "edge" else "both"})

    if not roads:
        raise FormatError("no road lines (the table of road lines has no rows): the map is built "
                          "from them", path=path)
    out_roads = []
    xs, ys = [], []
    for rid, lines in roads.items():
        refs = [pts for kind, pts in lines.values() if kind in ("reference", "centre_line",
                                                                 "center_line", "centerline")]
        if not refs:
            raise FormatError(f"road {rid!r} has no reference line (kind 'reference' or "
                              "'centre_line')", path=path)
        ref = refs[0]
        if len(ref) < 2:
            raise FormatError(f"road {rid!r}: the reference line needs at least 2 points", path=path)
        geoms, length = polyline_road_geometries(ref, step)
        borders = []
        for lid, (kind, pts) in lines.items():
            if kind in ("edge", "lane_marking"):
                _, t = _project(pts, ref)
                borders.append((float(np.mean(t)), kind))
        left = sorted((b for b in borders if b[0] > 0.05), key=lambda b: b[0])
        right = sorted((b for b in borders if b[0] < -0.05), key=lambda b: -b[0])
        if not borders:
            left, right = [(lane_width, "edge")], [(-lane_width, "edge")]

        def lanes(side: list[tuple[float, str]], sign: int) -> list[Lane]:
            out, prev = [], 0.0
            for k, (t, kind) in enumerate(side, start=1):
                w = abs(t) - prev
                prev = abs(t)
                out.append(Lane(id=sign * k, type="driving", widths=np.array([[0.0, w, 0, 0, 0]]),
                                road_marks=[mark(kind)]))
            return out

        centre_kind = "lane_marking" if left and right else "none"
        section = LaneSection(s=0.0, left=lanes(left, 1),
                              center=Lane(id=0, type="none", road_marks=[
                                  RoadMark(s_offset=0.0, type="none" if centre_kind == "none" else "solid")]),
                              right=lanes(right, -1))
        out_roads.append(Road(id=str(rid), name=f"road {rid}", length=length,
                              types=[RoadType(s=0.0, type="town")], geometries=geoms,
                              lane_sections=[section]))
        pts = np.vstack([p for _, p in lines.values()])
        xs.extend(pts[:, 0])
        ys.extend(pts[:, 1])
    header = Header(rev_major=1, rev_minor=6, name="accident site", vendor="aveas_format",
                    north=float(max(ys)), south=float(min(ys)), east=float(max(xs)),
                    west=float(min(xs)), geo_reference=geo_reference)
    return write_xodr((header, out_roads, []))


# --- the converter ---------------------------------------------------------------------------------

_CASE_FILES = ("participants.csv", "dynamics.csv", "roads.csv", "case.csv")


def _is_case_file(path: Path, head: bytes) -> bool:
    """One of a case's tables by its name (participants, dynamics, roads, case)."""
    return path.name.lower() in _CASE_FILES


@converter("accident", description="Accident reconstruction (GIDAS Pre-Crash-Matrix style tables); "
           "builds its map from the road lines", patterns=_CASE_FILES,
           method="accident_reconstruction", options=AccidentOptions, needs_map=False,
           sniff=_is_case_file)
def convert_accident(inputs: list[Path], *, map_source, options: AccidentOptions):
    o = options
    f = _files(inputs)
    case = _case(f.get("case"))
    rate = float(case.get("rate_hz") or o.rate_hz)

    def tol(key: str, default: float) -> float:
        v = case.get(key)
        return float(v) if v is not None and np.isfinite(v) else default

    stds = {"position": tol("position_tol_m", o.position_tol_m) / Z95,
            "velocity": tol("velocity_tol_m_s", o.velocity_tol_m_s) / Z95,
            "yaw": np.radians(tol("yaw_tol_deg", o.yaw_tol_deg)) / Z95,
            "accel": tol("accel_tol_m_s2", o.accel_tol_m_s2) / Z95}
    parts = _participants(f["participants"], o)
    boxes, t_min = _dynamics(f["dynamics"], parts, rate, stds, o)
    xodr = _road_map(f["roads"], o)
    events = _collision(case, boxes, parts, rate, t_min, f)
    m = len(parts["source_id"])
    pmf = np.zeros((m, len(CLASSES)), np.float32)
    pmf[np.arange(m), [CLASSES.index(c) for c in parts["class"]]] = 1.0
    dim_std = o.dimension_tol_m / Z95
    participants = {
        "class": parts["class"], "class_pmf": pmf, "length": parts["length"],
        "width": parts["width"], "height": parts["height"], "length_std": np.full(m, dim_std),
        "width_std": np.full(m, dim_std), "attributes": parts["attributes"],
    }
    case_id = str(case.get("case_id", "")) if case else ""
    sensor = Sensor(
        method="accident_reconstruction", partner="accident database", nominal_rate_hz=rate,
        title=f"accident case {case_id}" if case_id else None,
        platform="accident reconstruction (pre-crash matrix)",
        sensors=[{"id": "reconstruction", "kind": "manual",
                  "description": "reconstructed from the accident scene"}],
        not_observable=["light_", "interior", "lane_offset"])
    return to_recording(boxes, sensor, converter="accident", inputs=list(f.values()),
                        options=options, map_bytes=xodr.encode(), participants=participants,
                        events=events)


def _case(path: Path | None) -> dict[str, object]:
    """The one row of case.csv ({} without the file)."""
    if path is None:
        return {}
    ct = read_table(path, numeric=("collision_step", "collision_time", "position_tol_m",
                                   "velocity_tol_m_s", "yaw_tol_deg", "accel_tol_m_s2", "rate_hz"))
    if ct.num_rows != 1:
        raise FormatError(f"case table has {ct.num_rows} rows; one case per directory", path=path)
    return {k: v[0] for k, v in ct.to_pydict().items()}


def _participants(pp: Path, o: AccidentOptions) -> dict[str, Any]:
    """participants.csv: source ids (in the file's order: the participant codes), classes,
    sizes, the further columns as attributes, and the code of each source id (``index``)."""
    pt = read_table(pp, required=("participant_id", "type", "length", "width"),
                    numeric=("length", "width", "height"))
    _check_finite(pt, ("length", "width"), pp, positive=("length", "width"))
    p_src = pt.column("participant_id").cast(pa.string()).to_pylist()
    if len(set(p_src)) != len(p_src):
        raise FormatError("participant_id values repeat", path=pp)
    types = pt.column("type").cast(pa.string()).to_pylist()
    extra = [c for c in pt.column_names if c not in ("participant_id", "type", "length", "width",
                                                      "height")]
    return {
        "path": pp, "source_id": p_src, "index": {s: i for i, s in enumerate(p_src)},
        "class": [class_of(ty, o.class_map) for ty in types],
        "length": column_numpy(pt, "length"), "width": column_numpy(pt, "width"),
        "height": column_numpy(pt, "height", missing=np.nan),
        "attributes": [json.dumps({"type": ty, **{c: pt.column(c)[i].as_py() for c in extra}},
                                  default=str) for i, ty in enumerate(types)],
    }


def _dynamics(dp: Path, parts: dict[str, Any], rate: float, stds: dict[str, float],
              o: AccidentOptions) -> tuple[Boxes, float]:
    """dynamics.csv as (sorted) boxes with the stated tolerances as std, and the earliest time
    before it was moved to 0 (where it was negative)."""
    dt_ = read_table(dp, required=("participant_id", "x", "y", "vx", "vy"),
                     numeric=("step", "time", "x", "y", "vx", "vy", "ax", "ay", "yaw", "ref_offset"))
    names = set(dt_.column_names)
    if "step" not in names and "time" not in names:
        raise FormatError(f"dynamics needs a column 'step' or 'time'; found {dt_.column_names}", path=dp)
    tcol = "step" if "step" in names else "time"
    _check_finite(dt_, (tcol, "x", "y", "vx", "vy", "yaw", "ax", "ay"), dp)
    d_src = dt_.column("participant_id").cast(pa.string()).to_pylist()
    index = parts["index"]
    unknown = [i for i, s in enumerate(d_src) if s not in index]
    csv = dp.suffix.lower() != ".parquet"
    if unknown:
        i = unknown[0]
        raise FormatError(f"participant_id {d_src[i]!r} is not in {parts['path'].name}", path=dp,
                          line=i + 2 if csv else None)
    if not d_src:
        raise FormatError("dynamics has no rows", path=dp)
    n = len(d_src)
    tv = column_numpy(dt_, tcol)
    time = tv / rate if tcol == "step" else tv
    t_min = float(time.min())
    acc = {c: column_numpy(dt_, c) for c in ("ax", "ay") if c in names}
    boxes = Boxes(
        np.fromiter((index[s] for s in d_src), np.int64, n), time - t_min if t_min < 0 else time,
        column_numpy(dt_, "x"), column_numpy(dt_, "y"), source_ids=parts["source_id"],
        rows=Rows([dp], place=np.arange(n) + 2 if csv else None, unit="line" if csv else "row"),
        vx=column_numpy(dt_, "vx"), vy=column_numpy(dt_, "vy"),
        x_std=np.full(n, stds["position"]), y_std=np.full(n, stds["position"]),
        heading_std=np.full(n, stds["yaw"]), vx_std=np.full(n, stds["velocity"]),
        vy_std=np.full(n, stds["velocity"]), **acc,
        **{f"{c}_std": np.full(n, stds["accel"]) for c in acc}).sort()
    if "yaw" in names:
        yaw = column_numpy(dt_, "yaw")[boxes.order]
        heading = np.radians(yaw) if o.yaw_unit == "deg" else yaw
    else:
        from aveas_format.mapref.build import heading_from_velocity

        heading = heading_from_velocity(boxes.pid, boxes["vx"], boxes["vy"])
    boxes["heading"] = heading
    if "ref_offset" in names:  # the given point lies ahead of the footprint centre
        off = np.nan_to_num(column_numpy(dt_, "ref_offset"))[boxes.order]
        boxes["x"] = boxes["x"] - off * np.cos(heading)
        boxes["y"] = boxes["y"] - off * np.sin(heading)
    return boxes, t_min


def _road_map(rp: Path, o: AccidentOptions) -> str:
    """The OpenDRIVE text of the case's road lines (roads.csv), its geoReference the ``crs``
    option (``--crs``), else a transverse Mercator at ``site_lonlat``."""
    rt = read_table(rp, required=("line_id", "kind", "seq", "x", "y"), numeric=("seq", "x", "y"))
    _check_finite(rt, ("seq", "x", "y"), rp)
    rid = (rt.column("road_id").cast(pa.string()).to_pylist() if "road_id" in rt.column_names
           else ["1"] * rt.num_rows)
    lid = rt.column("line_id").cast(pa.string()).to_pylist()
    kinds = [str(k).strip().lower() for k in rt.column("kind").to_pylist()]
    seq, rx, ry = column_numpy(rt, "seq"), column_numpy(rt, "x"), column_numpy(rt, "y")
    roads: dict[str, dict[str, tuple[str, np.ndarray]]] = {}
    key_codes, keys = factorize([f"{a}\x00{b}" for a, b in zip(rid, lid)])
    order_r = np.lexsort((seq, key_codes))
    first_row = np.unique(key_codes[order_r], return_index=True)[1]
    bounds = np.r_[first_row, len(order_r)]
    for k in range(len(keys)):
        rows = order_r[bounds[k]:bounds[k + 1]]
        i0 = rows[0]
        roads.setdefault(rid[i0], {})[lid[i0]] = (kinds[i0], np.c_[rx[rows], ry[rows]])
    lon, lat = o.site_lonlat
    geo = o.crs or (f"+proj=tmerc +lat_0={lat} +lon_0={lon} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m "
                    "+no_defs")
    return build_map_from_lines(roads, geo, o.lane_width, o.map_step_m, rp)


def _collision(case: dict[str, object], boxes: Boxes, parts: dict[str, Any], rate: float,
               t_min: float, f: dict[str, Path]) -> dict[str, Any] | None:
    """The ``accident`` event: the case table's step and participants (origin ``annotated``),
    else the first time two footprints overlap (origin ``derived``); None (with a warning)
    without either."""
    index = parts["index"]
    cstep = case.get("collision_step")
    ctime = case.get("collision_time")
    if cstep is not None and np.isfinite(cstep):
        ctime = float(cstep) / rate - (t_min if t_min < 0 else 0.0)
    if ctime is not None and np.isfinite(ctime):
        cp = str(case.get("collision_participants") or "")
        ids = [s.strip() for s in cp.replace(",", ";").split(";") if s.strip()]
        for s in ids:
            if s not in index:
                raise FormatError(f"collision participant {s!r} is not in {parts['path'].name}",
                                  path=f["case"])
        if not ids:
            ids = parts["source_id"][:2]
        return {"event_id": [0], "kind": ["accident"], "time_start": [float(ctime)],
                "time_end": [float(ctime)], "participant_ids": [[index[s] for s in ids]],
                "roles": [["collision_partner"] * len(ids)], "confidence": [1.0],
                "origin": ["annotated"],
                "attributes": [json.dumps({"case_id": str(case.get("case_id", "")),
                                           "source": "case table"})]}
    hit = _first_contact(boxes.pid, boxes.time, boxes["x"], boxes["y"], boxes["heading"],
                         parts["length"], parts["width"])
    if hit is None:
        warnings.warn("no collision step given and no footprint overlap found: no accident "
                      "event", stacklevel=3)
        return None
    tc, a, b = hit
    return {"event_id": [0], "kind": ["accident"], "time_start": [tc], "time_end": [tc],
            "participant_ids": [[a, b]], "roles": [["collision_partner"] * 2],
            "confidence": [1.0], "origin": ["derived"],
            "attributes": [json.dumps({"method": "first footprint overlap"})]}


def _first_contact(pid, time, x, y, heading, length, width):
    """(time, a, b) of the first sample at which two footprints overlap, or None."""
    import shapely

    corners = footprint_corners(x, y, heading, length[pid], width[pid])
    polys = shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))
    best = None
    ids = np.unique(pid)
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            ia, ib = np.flatnonzero(pid == a), np.flatnonzero(pid == b)
            common, ka, kb = np.intersect1d(time[ia], time[ib], return_indices=True)
            if not len(common):
                continue
            hit = shapely.intersects(polys[ia[ka]], polys[ib[kb]])
            if hit.any():
                tc = float(common[np.argmax(hit)])
                if best is None or tc < best[0]:
                    best = (tc, int(a), int(b))
    return best
