"""The OpenSCENARIO export: a recording -> a scenario that replays it (timed polylines).

**Export** (``aveas-format export --to openscenario REC -o OUT.xosc``) writes a scenario that
replays the recording (or a time window of it, or chosen participants) and the map next to it
(``OUT.xodr``, the ``RoadNetwork/LogicFile``):

- each participant is a ``ScenarioObject`` named ``p<participant_id>``: a ``Vehicle`` (car, van,
  truck, bus, trailer, motorbike, bicycle, tram), a ``Pedestrian`` (pedestrian, animal,
  wheelchair = mobility device) or a ``MiscObject`` (obstacle: pushable/pullable, other) with a
  ``BoundingBox`` from length, width, height centred on the reference point (the footprint
  centre, so ``Center`` = (0, 0, height / 2)); class, source id and role go into ``Properties``;
- ``Init``: a ``TeleportAction`` to each participant's first position in the window;
- one ``Story``/``Act`` with a ``ManeuverGroup`` per participant whose ``Event`` starts at
  simulation time 0 and runs a ``FollowTrajectoryAction`` with a ``Polyline`` of timed vertices
  (``Vertex time`` = recording time - window start, ``TimeReference`` absolute,
  ``followingMode="position"``), positions as ``WorldPosition`` (x, y, z, h) or, with
  ``positions=lane``, as ``LanePosition`` (roadId, laneId, offset, s) where the sample is on a lane;
- a ``StopTrigger`` at the end of the window.

Participants that appear after the window start wait at their first position until their first
vertex (OpenSCENARIO has no spawn time in 1.2); choose a window or a set of participants to avoid
that. The system under test can be given an external controller by the simulation tool (the
entity of ``role = system_under_test`` / ``recording_vehicle`` is marked in its ``Properties``).
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from aveas_format.converters.common.companion import companion_map_path, write_companion_map
from aveas_format.converters.registry import ConverterOptions, converter
from aveas_format.errors import FormatError

VEHICLE_CATEGORY = {"car": "car", "van": "van", "truck": "truck", "bus": "bus", "trailer": "trailer",
                    "motorcycle": "motorbike", "bicycle": "bicycle", "railvehicle": "tram"}
PEDESTRIAN_CATEGORY = {"pedestrian": "pedestrian", "animal": "animal", "mobility_device": "wheelchair"}
_MASS = {"car": 1500.0, "van": 2500.0, "truck": 20000.0, "bus": 15000.0, "trailer": 8000.0,
         "motorbike": 250.0, "bicycle": 90.0, "tram": 40000.0, "pedestrian": 75.0, "animal": 30.0,
         "wheelchair": 120.0}


class OpenScenarioExportOptions(ConverterOptions):
    version: str = "1.2"
    """OpenSCENARIO version to write: 1.2 or 1.3."""
    time_start: float | None = None
    """Start of the exported window (s, recording time); default: the first sample."""
    time_end: float | None = None
    """End of the exported window (s); default: the last sample."""
    participants: list[int] | None = None
    """Participant ids to export (default: all with samples in the window)."""
    max_rate_hz: float | None = 10.0
    """Thin the polylines to at most this many vertices per second (None: every sample)."""
    positions: str = "world"
    """Vertex positions: ``world`` (x, y, z, h) or ``lane`` (LanePosition where on a lane)."""
    map_file: str | None = None
    """File name of the map written next to the output (default: the output's name with .xodr)."""
    write_map: bool = True
    """Write the map next to the output."""


def _sub(parent, tag: str, **attrs) -> etree._Element:
    el = etree.SubElement(parent, tag)
    for k, v in attrs.items():
        el.set(k, _fmt(v) if not isinstance(v, str) else v)
    return el


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def _bbox(parent, length: float, width: float, height: float) -> None:
    bb = _sub(parent, "BoundingBox")
    _sub(bb, "Center", x=0.0, y=0.0, z=height / 2)
    _sub(bb, "Dimensions", width=width, length=length, height=height)


def _position(parent, row: dict, mode: str) -> None:
    pos = _sub(parent, "Position")
    if mode == "lane" and row.get("road_id") is not None and row.get("lane_id") not in (None, 0):
        lp = _sub(pos, "LanePosition", roadId=str(row["road_id"]), laneId=str(int(row["lane_id"])),
                  offset=float(row.get("lane_offset") or 0.0), s=float(row["road_s"]))
        # the orientation relative to the lane: the heading itself, absolute
        _sub(lp, "Orientation", type="absolute", h=float(row["heading"]), p=0.0, r=0.0)
        return
    _sub(pos, "WorldPosition", x=float(row["x"]), y=float(row["y"]), z=float(row.get("z") or 0.0),
         h=float(row["heading"]), p=0.0, r=0.0)


def _sim_time_trigger(parent, tag: str, name: str, value: float, rule: str = "greaterThan") -> None:
    trig = _sub(parent, tag)
    cg = _sub(trig, "ConditionGroup")
    cond = _sub(cg, "Condition", name=name, delay=0.0, conditionEdge="rising")
    bv = _sub(cond, "ByValueCondition")
    _sub(bv, "SimulationTimeCondition", value=value, rule=rule)


def _carried_header(header, rec, t0: float) -> None:
    """The recording's partner, rights, start time (of the exported window) and title in the
    ``FileHeader`` (its ``License`` and ``Properties``, ``aveas:`` names): the re-import asks
    for nothing (:mod:`aveas_format.converters.common.carried`)."""
    from aveas_format.converters.common.carried import carried_meta
    from aveas_format.converters.common.timestamps import utc_iso_from_ns

    values = carried_meta(rec)
    if "start_time" in values and t0:
        values["start_time"] = utc_iso_from_ns(rec.meta.start_time_ns + int(round(t0 * 1e9)))
    if "license" in values:
        lic = values["license"]
        _sub(header, "License", name=lic, **({"spdxId": lic} if _SPDX.fullmatch(lic) else {}))
    if values:
        props = _sub(header, "Properties")
        for k, v in values.items():
            _sub(props, "Property", name=f"aveas:{k}", value=v)


#: an SPDX licence id or expression (``CC-BY-4.0``, ``MIT OR Apache-2.0``)
_SPDX = re.compile(r"[A-Za-z0-9.+-]+(?: (?:AND|OR|WITH) [A-Za-z0-9.+-]+)*")


def _by_participant(rows: list[dict]) -> dict[int, list[dict]]:
    out: dict[int, list[dict]] = {}
    for r in rows:
        out.setdefault(r["participant_id"], []).append(r)
    return out


#: a step longer than this many of the recording's median steps is a gap: no vertex is made up in it
GAP_STEPS = 1.5


def vertices(states, max_rate_hz: float) -> list[dict]:
    """The polyline vertices of each participant at most ``max_rate_hz`` per second: where the
    recording is sampled faster, on a regular grid of ``1 / max_rate_hz`` from each participant's
    first sample (so that a simulator's replay, and this toolkit's re-import, sees steady
    steps), the values linearly interpolated between the two samples around each grid time
    (heading on the circle; road coordinates where both lie on the same lane, else a world
    position); a participant's last samples after its last grid time (less than one step) are
    not exported; no vertex is made up inside a gap (two samples more than :data:`GAP_STEPS` of the
    recording's median steps apart). Where the recording is not faster: every sample. ``states``
    sorted by (participant, time) (as a recording's are)."""
    from aveas_format.io.arrow import column_numpy

    pid = states.column("participant_id").to_numpy()
    t = column_numpy(states, "time")
    same = pid[1:] == pid[:-1]
    steps = np.diff(t)[same]
    period = 1.0 / max_rate_hz
    if not len(steps) or float(np.median(steps)) >= period * (1 - 1e-6):
        return states.to_pylist()
    native = float(np.median(steps))
    starts = np.r_[0, np.flatnonzero(~same) + 1]
    ends = np.r_[starts[1:], len(t)]
    span = t[ends - 1] - t[starts]
    k = np.floor(span / period + 1e-6).astype(np.int64) + 1
    seg = np.repeat(np.arange(len(starts)), k)
    rel = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) * period  # grid, from each start
    stride = float(span.max()) + 2 * period + 1.0  # (participants apart on one key axis)
    row_seg = np.repeat(np.arange(len(starts)), ends - starts)
    key = (t - t[starts][row_seg]) + row_seg * stride
    i = np.searchsorted(key, rel + seg * stride + 1e-9, side="right") - 1
    i = np.clip(i, starts[seg], ends[seg] - 1)
    j = np.minimum(i + 1, ends[seg] - 1)
    g = t[starts][seg] + rel
    dt = t[j] - t[i]
    w = np.clip(np.where(j > i, (g - t[i]) / np.where(j > i, dt, 1.0), 0.0), 0.0, 1.0)
    exact = np.abs(g - t[i]) <= 1e-9
    keep = exact | (dt <= GAP_STEPS * native + 1e-9)
    i, j, w, g = i[keep], j[keep], np.where(exact, 0.0, w)[keep], g[keep]
    near = np.where(w <= 0.5, i, j)
    out: dict[str, Any] = {"participant_id": pid[i], "time": np.round(g, 9)}
    for c in ("x", "y", "z", "road_s", "lane_offset"):
        if c in states.column_names:
            v = column_numpy(states, c, null=np.nan)
            a, b = v[i], v[j]
            out[c] = np.where(np.isfinite(a) & np.isfinite(b), a + w * (b - a), v[near])
    h = column_numpy(states, "heading", null=0.0)
    out["heading"] = h[i] + w * np.angle(np.exp(1j * (h[j] - h[i])))
    road = {c: states.column(c).to_pylist() for c in ("road_id", "lane_id") if c in states.column_names}
    rows = []
    for n in range(len(i)):
        r = {c: (None if isinstance(v[n], float) and not np.isfinite(v[n]) else v[n].item())
             for c, v in out.items()}
        if road:
            a, b = int(i[n]), int(j[n])
            same_lane = all(road[c][a] == road[c][b] for c in road)
            for c in road:
                r[c] = road[c][a] if same_lane or w[n] == 0.0 else None
        rows.append(r)
    return rows


def recording_to_openscenario(rec, *, logic_file: str = "map.xodr",
                              options: OpenScenarioExportOptions | None = None) -> bytes:
    """The OpenSCENARIO XML of a recording (bytes)."""
    import pyarrow.compute as pc

    o = options or OpenScenarioExportOptions()
    if o.version not in ("1.2", "1.3"):
        raise FormatError(f"openscenario: version {o.version!r}; expected 1.2 or 1.3")
    if o.positions not in ("world", "lane"):
        raise FormatError(f"openscenario: positions {o.positions!r}; expected world or lane")
    s = rec.states
    t_all = s.column("time").to_numpy()
    t0 = float(t_all.min()) if len(t_all) and o.time_start is None else float(o.time_start or 0.0)
    t1 = float(t_all.max()) if len(t_all) and o.time_end is None else float(o.time_end or 0.0)
    mask = (t_all >= t0 - 1e-9) & (t_all <= t1 + 1e-9)
    if o.participants is not None:
        mask &= np.isin(s.column("participant_id").to_numpy(), np.asarray(o.participants, np.int64))
    s = s.filter(mask)
    if s.num_rows == 0:
        raise FormatError("openscenario: no samples in the chosen window / participants")
    p = rec.participants
    pids = np.unique(s.column("participant_id").to_numpy())
    p = p.filter(pc.is_in(p.column("participant_id"), value_set=__import__("pyarrow").array(pids)))

    root = etree.Element("OpenSCENARIO")
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    title = rec.meta.title or rec.meta.recording_id
    header = _sub(root, "FileHeader", revMajor=1, revMinor=int(o.version.split(".")[1]), date=now,
                  description=f"{title} [{t0:g} s, {t1:g} s] (recording {rec.meta.recording_id}, "
                              f"start {rec.meta.start_time})",
                  author="aveas-format")
    _carried_header(header, rec, t0)
    _sub(root, "ParameterDeclarations")
    _sub(root, "CatalogLocations")
    rn = _sub(root, "RoadNetwork")
    _sub(rn, "LogicFile", filepath=logic_file)
    ents = _sub(root, "Entities")
    for r in p.to_pylist():
        name = f"p{r['participant_id']}"
        so = _sub(ents, "ScenarioObject", name=name)
        cls = str(r["class"])
        h = float(r.get("height") or (1.7 if cls in PEDESTRIAN_CATEGORY else 1.5))
        if cls in VEHICLE_CATEGORY:
            cat = VEHICLE_CATEGORY[cls]
            el = _sub(so, "Vehicle", name=cls, vehicleCategory=cat, mass=_MASS[cat])
            _bbox(el, r["length"], r["width"], h)
            _sub(el, "Performance", maxSpeed=70.0, maxAcceleration=10.0, maxDeceleration=10.0)
            axles = _sub(el, "Axles")
            wb = 0.6 * r["length"]
            _sub(axles, "FrontAxle", maxSteering=0.5, wheelDiameter=0.6, trackWidth=r["width"],
                 positionX=wb / 2, positionZ=0.3)
            _sub(axles, "RearAxle", maxSteering=0.0, wheelDiameter=0.6, trackWidth=r["width"],
                 positionX=-wb / 2, positionZ=0.3)
        elif cls in PEDESTRIAN_CATEGORY:
            cat = PEDESTRIAN_CATEGORY[cls]
            el = _sub(so, "Pedestrian", name=cls, mass=_MASS[cat], model=cls, pedestrianCategory=cat)
            _bbox(el, r["length"], r["width"], h)
        else:
            el = _sub(so, "MiscObject", name=cls, mass=100.0, miscObjectCategory="obstacle")
            _bbox(el, r["length"], r["width"], h)
        props = _sub(el, "Properties")
        for k, v in (("aveas:class", cls), ("aveas:participant_id", str(r["participant_id"])),
                     ("aveas:source_id", str(r.get("source_id"))), ("aveas:role", str(r.get("role")))):
            _sub(props, "Property", name=k, value=v)

    sb = _sub(root, "Storyboard")
    init = _sub(sb, "Init")
    acts = _sub(init, "Actions")
    cols = [c for c in ("participant_id", "time", "x", "y", "z", "heading", "road_id", "lane_id",
                        "road_s", "lane_offset") if c in s.column_names]
    rows_by_pid = _by_participant(s.select(cols).to_pylist())
    for q in pids.tolist():
        first = rows_by_pid[q][0]
        pr = _sub(acts, "Private", entityRef=f"p{q}")
        pa_ = _sub(pr, "PrivateAction")
        tp = _sub(pa_, "TeleportAction")
        _position(tp, first, "world")
    if o.max_rate_hz:
        rows_by_pid = _by_participant(vertices(s.select(cols), o.max_rate_hz))
    story = _sub(sb, "Story", name="recorded")
    act = _sub(story, "Act", name="replay")
    for q in pids.tolist():
        rows = rows_by_pid[q]
        mg = _sub(act, "ManeuverGroup", maximumExecutionCount=1, name=f"mg_p{q}")
        actors = _sub(mg, "Actors", selectTriggeringEntities=False)
        _sub(actors, "EntityRef", entityRef=f"p{q}")
        man = _sub(mg, "Maneuver", name=f"m_p{q}")
        ev = _sub(man, "Event", name=f"e_p{q}", priority="override" if o.version != "1.0" else "overwrite",
                  maximumExecutionCount=1)
        action = _sub(ev, "Action", name=f"follow_p{q}")
        pa_ = _sub(action, "PrivateAction")
        ra = _sub(pa_, "RoutingAction")
        fta = _sub(ra, "FollowTrajectoryAction")
        traj = _sub(fta, "Trajectory", name=f"trajectory_p{q}", closed=False)
        shape = _sub(traj, "Shape")
        pl = _sub(shape, "Polyline")
        for r in rows:
            v = _sub(pl, "Vertex", time=float(r["time"] - t0))
            _position(v, r, o.positions)
        tr = _sub(fta, "TimeReference")
        _sub(tr, "Timing", domainAbsoluteRelative="absolute", scale=1.0, offset=0.0)
        _sub(fta, "TrajectoryFollowingMode", followingMode="position")
        _sim_time_trigger(ev, "StartTrigger", f"start_p{q}", 0.0, "greaterOrEqual")
    _sim_time_trigger(act, "StartTrigger", "act_start", 0.0, "greaterOrEqual")
    _sim_time_trigger(sb, "StopTrigger", "end", float(t1 - t0), "greaterThan")
    return etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")


@converter("openscenario", direction="export", options=OpenScenarioExportOptions,
           description="ASAM OpenSCENARIO XML 1.2/1.3: entities + FollowTrajectoryAction polylines "
                       "(+ the map as .xodr)")
def export_openscenario(rec, output: Path, *, options: OpenScenarioExportOptions) -> list[Path]:
    from aveas_format.safeio import write_bytes_atomic

    output = Path(output)
    companion = companion_map_path(output, options)
    map_name = companion.name if companion is not None else (options.map_file or f"{output.stem}.xodr")
    data = recording_to_openscenario(rec, logic_file=map_name, options=options)
    written = [write_bytes_atomic(output, data)]
    if companion is not None and rec.map_source is not None:
        # the recording's crs travels in the map's <geoReference> (OpenSCENARIO has no place for it)
        written.append(write_companion_map(rec, companion))
    return written


__all__ = ["export_openscenario", "recording_to_openscenario"]
