"""Semantically degenerate but well-formed sources, for every importer (issue 11): a track with a
single sample, samples at identical times, a track that never moves, no tracks at all, times out of
order within a track, a huge time gap. Each conversion either gives a recording that validates
without tool failures and keeps every input sample, or a clear library error naming the input file
and where in it (never another exception). The successful single-sample / static / identical-time
recordings also go through every derivation.

The valid sources come from the converters' own test generators (tests/converters); a degenerate
case replaces the second track of a small truth by a degraded copy (``degrade``)."""

from __future__ import annotations

import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert
from aveas_format.errors import AveasError
from aveas_format.opendrive.builder import straight_highway

from helpers_common import REALDATA

sys.path.insert(0, str(Path(__file__).parents[1] / "converters"))

N = 10                     # samples of a truth track
GAP_S = 36000.0            # the "very large gap": ten hours
PERM = [5, 1, 3, 0, 2, 4, 9, 7, 8, 6]
CASES = ["single", "only_single", "dup_time", "same_time", "static", "empty", "unsorted", "gap"]
#: words a located error names (besides the file)
LOCATORS = ("line", "row", "track", "participant", "frame", "vehicle", "object", "message", "id",
            "no rows", "no tracks", "no samples", "empty", "no objects", "no participants")


# --- degrading a truth --------------------------------------------------------------------------

def _take(v: dict, idx) -> dict:
    idx = np.asarray(idx, dtype=int)
    return {k: (x[idx].copy() if isinstance(x, np.ndarray) and x.ndim and len(x) == N else x)
            for k, x in v.items()}


def degrade(veh: list[dict], case: str, times: dict[str, float],
            vel: tuple[str, ...] = ()) -> list[dict]:
    """The truth ``veh`` (tracks of N samples, the first two used) degraded by ``case``: track 0
    stays a normal companion, track 1 is degraded. ``times``: the time fields (name -> units per
    second), ``vel``: velocity/acceleration fields (zero when the track stands still)."""
    a, b = veh[0], veh[1]
    if case == "empty":
        return []
    if case == "single":
        return [a, _take(b, [3])]
    if case == "only_single":
        return [_take(b, [3])]
    if case == "dup_time":     # two samples at the same time (at different places)
        b2 = _take(b, [0, 1, 2, 3, 4])
        for k in times:
            b2[k][2] = b2[k][1]
        return [a, b2]
    if case == "same_time":    # every sample at the same time
        b2 = _take(b, [0, 1, 2])
        for k in times:
            b2[k][:] = b2[k][0]
        return [a, b2]
    if case == "static":       # never moves: every sample at the first place, speed zero
        b2 = _take(b, [0] * N)
        for k in times:
            b2[k] = b[k].copy()
        for k in vel:
            b2[k] = np.zeros(N)
        return [a, b2]
    if case == "unsorted":
        return [a, _take(b, PERM)]
    if case == "gap":
        b2 = _take(b, range(N))
        for k, scale in times.items():
            b2[k][5:] = b2[k][5:] + type(b2[k][0])(GAP_S * scale)
        return [a, b2]
    raise AssertionError(case)


def samples(veh: list[dict], key: str) -> int:
    return sum(len(v[key]) for v in veh)


def time_major(veh: list[dict], key: str = "t", once: bool = False
               ) -> list[tuple[float, list[tuple[dict, int]]]]:
    """Group samples by time for frame-by-frame formats; message order = first appearance, the
    degraded track first (so its disorder shows in the message order). ``once``: a track appears
    at most once per frame (a repeated time opens another frame with the same time)."""
    order = veh[1:] + veh[:1] if len(veh) > 1 else veh
    groups: dict[tuple[float, int], list] = {}
    for v in order:
        for i, ti in enumerate(v[key]):
            j = 0
            while once and any(w is v for w, _ in groups.get((float(ti), j), [])):
                j += 1
            groups.setdefault((float(ti), j), []).append((v, i))
    return [(k[0], g) for k, g in groups.items()]


def _header_only(*paths: Path) -> None:
    for p in paths:
        p.write_text(p.read_text().split("\n", 1)[0] + "\n")


# --- one source builder per importer: (tmp, case) -> (convert thunk, input samples, file names) ---

def _map(d: Path, **kw) -> Path:
    p = d / "map.xodr"
    p.write_text(straight_highway(**kw))
    return p


def src_highd(d, case):
    import test_levelx as lx

    veh = degrade(lx.highd_truth(N), case, {"t": 1.0, "frames": lx.RATE}, ("vx", "vyi", "ax", "ayi"))
    files = lx.write_highd(d / "h", veh or lx.highd_truth(N)[:1])
    if not veh:
        _header_only(files[0], files[1])
    return (lambda: convert("highd", [d / "h"])), samples(veh, "t"), [f.name for f in files]


def _src_centre(d, case, exid):
    import test_levelx as lx

    veh = degrade(lx.ind_truth(N), case, {"t": 1.0, "frames": lx.RATE},
                  ("vx", "vy", "ax", "ay"))
    files = lx.write_centre(d / "i", veh, exid=exid)
    m = _map(d, length=200.0, lanes_right=1, lanes_left=1, x0=-100.0, y0=0.0,
             geo_reference=lx.SITE_CRS)
    name = "exid" if exid else "ind"
    return (lambda: convert(name, [d / "i"], map_source=m)), samples(veh, "t"), [f.name for f in files]


def src_ind(d, case):
    return _src_centre(d, case, False)


def src_exid(d, case):
    return _src_centre(d, case, True)


def src_rotated_boxes(d, case):
    import test_rotated_boxes as rb

    veh = degrade(rb.truth(N), case, {"t": 1.0, "frame": rb.RATE}, ("vx", "vy"))
    tracks = rb.write_tracks(d / "tracks.csv", veh, scramble=False)
    tfw = rb.write_world_file(d / "ortho.tfw")
    (d / "ortho.prj").write_text(rb.SITE_CRS)
    m = _map(d, length=400.0, lanes_right=2, lanes_left=2, x0=-200.0, y0=0.0,
             geo_reference=rb.SITE_CRS)
    return (lambda: convert("rotated-boxes", [tracks, tfw, d / "ortho.prj"], map_source=m,
                            options={"frame_rate": rb.RATE, "image_size": [3000, 1500]})), \
        samples(veh, "t"), ["tracks.csv"]


def src_driving_simulator(d, case):
    import test_driving_simulator as ds

    ego, lead = ds.truth(N)
    veh = degrade([lead, ego], case, {"t": 1.0}, ("vx", "vy"))   # the subject is degraded
    lines = ["time,id,x,y,heading,speed,length,width,class"]
    for v in veh:
        for i in range(len(v["t"])):
            speed = float(math.hypot(v["vx"][i], v["vy"][i]))
            lines.append(",".join([repr(float(v["t"][i])), v["id"], repr(float(v["x"][i])),
                                   repr(float(v["y"][i])), repr(float(v["heading"][i])), repr(speed),
                                   str(v["L"]), str(v["W"]), v.get("cls", "car")]))
    p = d / "run.csv"
    p.write_text("\n".join(lines) + "\n")
    m = _map(d, length=1000.0, lanes_right=2, geo_reference=ds.GEO)
    return (lambda: convert("driving-simulator", [p], map_source=m)), samples(veh, "t"), ["run.csv"]


def src_accident(d, case):
    import test_accident as ac

    ac.write_case(d / "case", case=False)
    t = np.arange(N) / ac.RATE
    car = dict(id=1, t=t, step=np.arange(N), x=-30 + 10 * t, y=np.full(N, -1.75), vx=np.full(N, 10.0),
               vy=np.zeros(N), yaw=np.zeros(N))
    ped = dict(id=2, t=t.copy(), step=np.arange(N), x=np.full(N, 2.5), y=5 - 2 * t, vx=np.zeros(N),
               vy=np.full(N, -2.0), yaw=np.full(N, -90.0))
    veh = degrade([car, ped], case, {"t": 1.0, "step": ac.RATE}, ("vx", "vy"))
    lines = ["participant_id,step,x,y,vx,vy,ax,ay,yaw"]
    for v in veh:
        for i in range(len(v["t"])):
            vals = [float(v[k][i]) for k in ("x", "y", "vx", "vy")]
            lines.append(f"{v['id']},{int(v['step'][i])},{','.join(map(repr, vals))},0,0,"
                         f"{float(v['yaw'][i])!r}")
    (d / "case" / "dynamics.csv").write_text("\n".join(lines) + "\n")
    return (lambda: convert("accident", [d / "case"])), samples(veh, "t"), ["dynamics.csv"]


def src_infra_lwir(d, case):
    import test_infra_lwir as iw

    t = np.arange(N) / iw.RATE
    cars = [dict(id=tid, t=t.copy(), frame=np.arange(N) + 1, x=fx(t), y=np.full(N, y))
            for tid, y, fx, _ in iw.CARS]
    veh = degrade(cars, case, {"t": 1.0, "frame": iw.RATE})
    lines = []
    for v in veh:
        u, vv = iw.project(v["x"], v["y"])
        for i in range(len(v["t"])):
            lines.append(f"{int(v['frame'][i])},{v['id']},{u[i] - 20:.6f},{vv[i] - 30:.6f},40.0,30.0,"
                         "1,-1,-1,-1")
    gt = d / "gt.txt"
    gt.write_text("\n".join(lines) + "\n")
    xs = np.array([0.0, 0.0, 30.0, 30.0, 60.0, 60.0, 100.0, 100.0, 15.0, 80.0])
    ys = np.array([0.0, -10.5, 0.0, -10.5, 2.0, -10.5, 0.0, -10.5, -5.0, -3.0])
    u, v = iw.project(xs, ys)
    lm = d / "landmarks.csv"
    lm.write_text("name,u,v,x,y\n" + "".join(f"L{i},{a:.6f},{b:.6f},{c},{e}\n"
                                            for i, (a, b, c, e) in enumerate(zip(u, v, xs, ys))))
    m = _map(d, length=300.0, lanes_right=3, x0=-50.0, geo_reference=iw.GEO)
    return (lambda: convert("infra-lwir", [gt, lm], map_source=m)), samples(veh, "t"), ["gt.txt"]


def src_infra_lidar(d, case):
    import test_infra_lidar as il
    from scipy.spatial.transform import Rotation

    t = np.arange(N) / il.RATE
    veh = []
    for j, (uid, typ, fx, y, hd, ln, w, h, n) in enumerate(il.TRUTH[:2]):
        veh.append(dict(id=j, typ=typ.lower(), t=t.copy(), frame=np.arange(N), x=fx(t), y=np.full(N, y),
                        hd=hd, dims=(ln, w, h), n=n))
    veh = degrade(veh, case, {"t": 1.0, "frame": il.RATE})
    lines = ["frame,track_id,class,x,y,z,yaw,length,width,height,num_points"]
    for v in veh:
        ln, w, h = v["dims"]
        for i in range(len(v["t"])):
            c = il.lidar_cuboid(v["x"][i], v["y"][i], v["hd"], ln, w, h)
            yaw = math.atan2(*(Rotation.from_quat(c[3:7]).as_matrix()[[1, 0], 0]))
            lines.append(f"{int(v['frame'][i])},{v['id']},{v['typ']},{c[0]},{c[1]},{c[2]},{yaw},"
                         f"{ln},{w},{h},{v['n']}")
    p = d / "tracks.csv"
    p.write_text("\n".join(lines) + "\n")
    m = _map(d, length=300.0, lanes_right=2, lanes_left=2, x0=-100.0, y0=0.0, geo_reference=il.GEO)
    return (lambda: convert("infra-lidar", [p], map_source=m,
                            options={"sensor_pose": str(il.calib()), "rate_hz": il.RATE})), \
        samples(veh, "t"), ["tracks.csv"]


def src_infra_lidar_tum(d, case):
    """The TUM Traffic layout: one OpenLABEL file per LiDAR frame (a repeated time: two files)."""
    import test_infra_lidar as il

    t = np.arange(N) / il.RATE
    veh = [dict(id=uid, typ=typ, t=t.copy(), x=fx(t), y=np.full(N, y), hd=hd, dims=(ln, w, h), n=n)
           for uid, typ, fx, y, hd, ln, w, h, n in il.TRUTH[:2]]
    veh = degrade(veh, case, {"t": 1.0})
    files = []
    for k, (ti, group) in enumerate(time_major(veh, once=True) or [(0.0, [])]):
        doc = il.tum_frame(k)
        fr = doc["openlabel"]["frames"][str(k)]
        fr["frame_properties"]["timestamp"] = il.T0 + ti
        objects = {}
        for v, i in group:
            ob = json.loads(json.dumps(fr["objects"][v["id"]]))
            ob["object_data"]["cuboid"]["val"] = il.lidar_cuboid(float(v["x"][i]), float(v["y"][i]),
                                                                 v["hd"], *v["dims"])
            objects[v["id"]] = ob
        fr["objects"] = objects
        p = d / f"{k:06d}_s110_lidar_ouster_south.json"
        p.write_text(json.dumps(doc))
        files.append(p)
    m = _map(d, length=300.0, lanes_right=2, lanes_left=2, x0=-100.0, y0=0.0, geo_reference=il.GEO)
    return (lambda: convert("infra-lidar", files, map_source=m)), samples(veh, "t"), \
        [f.name for f in files]


def src_osi(d, case):
    pytest.importorskip("betterosi")
    import test_osi as o

    t, objs = o.truth(N)
    for v in objs:
        v["t"] = t.copy()
    veh = degrade(objs, case, {"t": 1.0}, ("vx", "vy", "ax"))
    msgs = []
    for ti, group in time_major(veh):
        msgs += list(o.messages(np.array([ti]), [_take1(v, i) for v, i in group]))
    p = o.write_osi(d / "run_gt.osi", msgs)
    m = _map(d, length=600.0, lanes_right=2, lanes_left=1, geo_reference=o.GEO)
    return (lambda: convert("osi", [p], map_source=m)), samples(veh, "t"), ["run_gt.osi"]


def _take1(v: dict, i: int) -> dict:
    return {k: (x[i:i + 1] if isinstance(x, np.ndarray) else x) for k, x in v.items()}


def src_sumo_fcd(d, case):
    t = np.arange(N, dtype=float)
    veh = [dict(id="0", t=t.copy(), x=1495.25 - 10 * t, y=np.full(N, 401.65), speed=np.full(N, 10.0)),
           dict(id="1", t=t.copy(), x=1400.25 - 8 * t, y=np.full(N, 401.65), speed=np.full(N, 8.0))]
    veh = degrade(veh, case, {"t": 1.0}, ("speed",))
    out = ['<?xml version="1.0" encoding="UTF-8"?>', "<fcd-export>"]
    for ti, group in time_major(veh):
        out.append(f'    <timestep time="{ti:.2f}">')
        for v, i in group:
            out.append(f'        <vehicle id="{v["id"]}" x="{v["x"][i]:.2f}" y="{v["y"][i]:.2f}" '
                       f'angle="270.00" type="t1" speed="{v["speed"][i]:.2f}" pos="0" '
                       'lane="a_0" slope="0.00"/>')
        out.append("    </timestep>")
    out.append("</fcd-export>")
    p = d / "fcd.xml"
    p.write_text("\n".join(out) + "\n")
    m = _map(d, length=2000.0, lanes_right=1, x0=1600.0, y0=401.65 - 1.75, hdg=math.pi,
             geo_reference="+proj=tmerc +lat_0=48.8 +lon_0=11.1 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
             "+units=m +no_defs")
    return (lambda: convert("sumo-fcd", [p], map_source=m)), samples(veh, "t"), ["fcd.xml"]


OL_GEO = "+proj=tmerc +lat_0=49.0 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
UNIX0 = 1.7e9


def src_openlabel(d, case):
    t = np.arange(N) / 10.0
    veh = [dict(id="car-1", t=t.copy(), x=10 + 10 * t, y=np.full(N, -1.75), yaw=0.0,
                dims=(4.5, 1.8, 1.5)),
           dict(id="truck-2", t=t.copy(), x=150 - 8 * t, y=np.full(N, 1.75), yaw=math.pi,
                dims=(12.0, 2.5, 3.8))]
    veh = degrade(veh, case, {"t": 1.0})
    frames = {}
    for k, (ti, group) in enumerate(time_major(veh, once=True)):
        frames[str(k)] = {"frame_properties": {"timestamp": UNIX0 + ti}, "objects": {
            v["id"]: {"object_data": {"cuboid": [{"name": "bounding_box", "val": [
                float(v["x"][i]), float(v["y"][i]), v["dims"][2] / 2, 0.0, 0.0, v["yaw"], *v["dims"]]}]}}
            for v, i in group}}
    doc = {"openlabel": {"metadata": {"schema_version": "1.0.0"},
                         "objects": {v["id"]: {"name": v["id"], "type": "car"} for v in veh},
                         "frames": frames}}
    p = d / "labels.json"
    p.write_text(json.dumps(doc))
    m = _map(d, length=400.0, lanes_right=1, lanes_left=1, x0=-100.0, y0=0.0, geo_reference=OL_GEO)
    return (lambda: convert("openlabel", [p], map_source=m)), samples(veh, "t"), ["labels.json"]


_XOSC: list = []


def _xosc_template() -> tuple[bytes, bytes]:
    """An exported OpenSCENARIO of two participants (N samples each) and its map."""
    if not _XOSC:
        import tempfile

        from aveas_format.converters import get_converter
        from helpers_common import small_recording

        with tempfile.TemporaryDirectory() as tmp:
            get_converter("openscenario", "export")(small_recording(n=2, steps=N), Path(tmp) / "s.xosc")
            _XOSC.append(((Path(tmp) / "s.xosc").read_bytes(), (Path(tmp) / "s.xodr").read_bytes()))
    return _XOSC[0]


def src_openscenario(d, case, heading=True):
    """``heading=False``: vertices without h (heading from the direction of motion)."""
    from lxml import etree

    xosc, xodr = _xosc_template()
    root = etree.fromstring(xosc)
    veh = []
    for k in range(2):
        poly = root.find(f".//Trajectory[@name='trajectory_p{k}']/Shape/Polyline")
        vs = poly.findall("Vertex")
        w = [v.find("Position/WorldPosition") for v in vs]
        veh.append(dict(id=k, t=np.array([float(v.get("time")) for v in vs]),
                        x=np.array([float(e.get("x")) for e in w]),
                        y=np.array([float(e.get("y")) for e in w]),
                        h=np.array([float(e.get("h")) for e in w])))
    kept = degrade(veh, case, {"t": 1.0})
    by_id = {v["id"]: v for v in kept}
    for k in range(2):
        if k not in by_id:   # the track is gone: its entity, init and manoeuvre too
            for xp in (f".//ScenarioObject[@name='p{k}']", f".//Private[@entityRef='p{k}']",
                       f".//ManeuverGroup[@name='mg_p{k}']"):
                for e in root.findall(xp):
                    e.getparent().remove(e)
            continue
        v = by_id[k]
        poly = root.find(f".//Trajectory[@name='trajectory_p{k}']/Shape/Polyline")
        for e in poly.findall("Vertex"):
            poly.remove(e)
        for i in range(len(v["t"])):
            vert = etree.SubElement(poly, "Vertex", time=repr(float(v["t"][i])))
            wp = etree.SubElement(etree.SubElement(vert, "Position"), "WorldPosition",
                                  x=repr(float(v["x"][i])), y=repr(float(v["y"][i])), z="0.0")
            if heading:
                wp.set("h", repr(float(v["h"][i])))
    if not heading:
        for wp in root.iterfind(".//Init//WorldPosition"):
            wp.attrib.pop("h", None)
    (d / "s.xodr").write_bytes(xodr)
    p = d / "s.xosc"
    p.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return (lambda: convert("openscenario", [p])), samples(kept, "t"), ["s.xosc"]


def src_ros2_mcap(d, case):
    pytest.importorskip("mcap_ros2")
    import test_ros2_mcap as r

    t = np.arange(N) / r.RATE
    ego = dict(id="ego", t=t.copy(), x=r.ego_x(t))
    obj = dict(id="b", t=t.copy() + 0.02, x=80.0 + 25.0 * t)
    veh = degrade([ego, obj], case, {"t": 1.0})
    msgs = []
    for v in veh:
        for i in range(len(v["t"])):
            ti = float(v["t"][i])
            t_ns = r.T0 + int(round(ti * 1e9))
            if v["id"] == "ego":
                m = r.odometry(t_ns, ti)
                m["pose"]["pose"]["position"]["x"] = float(v["x"][i])
                msgs.append(("/localization/kinematic_state", "nav_msgs/msg/Odometry", m, t_ns))
            else:
                m = r.tracked(t_ns, ti)
                m["objects"] = m["objects"][1:]
                kin = m["objects"][0]["kinematics"]
                kin["pose_with_covariance"]["pose"]["position"]["x"] = float(v["x"][i])
                msgs.append(("/perception/object_recognition/tracking/objects",
                             "autoware_perception_msgs/msg/TrackedObjects", m, t_ns))
    p = r.write_mcap(d / "scene.mcap", msgs)
    m = _map(d, length=1000.0, lanes_right=3, x0=r.OFFSET[0], y0=r.OFFSET[1], hdg=r.YAW0,
             geo_reference=r.GEO)
    opts = {"frame_offset": list(r.OFFSET), "ego_center_offset": 1.4, "partner": "t"}
    return (lambda: convert("ros2-mcap", [p], map_source=m, options=opts)), samples(veh, "t"), \
        ["scene.mcap"]


SOURCES = {
    "highd": src_highd, "ind": src_ind, "exid": src_exid, "rotated-boxes": src_rotated_boxes,
    "driving-simulator": src_driving_simulator, "accident": src_accident,
    "infra-lwir": src_infra_lwir, "infra-lidar": src_infra_lidar,
    "infra-lidar(tum)": src_infra_lidar_tum, "osi": src_osi,
    "sumo-fcd": src_sumo_fcd, "openlabel": src_openlabel, "openscenario": src_openscenario,
    "openscenario(no h)": lambda d, case: src_openscenario(d, case, heading=False),
    "ros2-mcap": src_ros2_mcap,
}


def _located(msg: str, files: list[str]) -> bool:
    return any(f in msg for f in files) and any(w in msg.lower() for w in LOCATORS)


#: known bugs outside this test's reach (reported, not fixed here): (source, case) -> reason
KNOWN: dict[tuple[str, str], str] = {}
#: ... of the derivations, on a successful conversion
KNOWN_DERIVE: dict[tuple[str, str], str] = {}


#: sources whose generators use real data of ../shared (a LiDAR calibration, ROS 2 message definitions)
REALDATA_SOURCES = {"infra-lidar", "infra-lidar(tum)", "ros2-mcap"}


def _params(known: dict) -> list:
    return [pytest.param(name, case, id=f"{name}-{case}",
                         marks=([pytest.mark.xfail(reason=known[name, case], strict=False)]
                                if (name, case) in known else [])
                         + ([REALDATA] if name in REALDATA_SOURCES else []))
            for name in sorted(SOURCES) for case in CASES]


_RECORDINGS: dict[tuple[str, str], object] = {}


def _convert(tmp_path, name, case):
    """(recording or None, the error, input samples, warnings); the recording is kept for the
    derivation test."""
    run, n_in, files = SOURCES[name](tmp_path, case)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rec = run()
        except AveasError as e:
            assert _located(str(e), files), f"{name}/{case}: error not located: {e}"
            return None, e, n_in, []
    _RECORDINGS[name, case] = rec
    return rec, None, n_in, [str(w.message) for w in caught if issubclass(w.category, UserWarning)]


@pytest.mark.parametrize("name,case", _params(KNOWN))
def test_degenerate_source(tmp_path, name, case):
    """A recording that validates and keeps every sample (or drops repeats with a warning), or a
    located library error; never another exception."""
    rec, err, n_in, warned = _convert(tmp_path, name, case)
    if rec is None:
        return
    report = aveas_format.validate(rec)
    assert report.failures == [], f"{name}/{case}: validation tool failures {report.failures}"
    # the importer's output is well-formed (plausibility findings would be the data's own)
    structural = [r.code for r in report.results if r.count and r.severity.value == "error"
                  and not r.code.startswith("kinematics.")]
    assert structural == [], f"{name}/{case}: the converted recording is invalid: {structural}"
    n_out = rec.states.num_rows
    assert n_out == n_in or (n_out < n_in and warned), \
        f"{name}/{case}: {n_in} input samples, {n_out} states, warnings {warned}"


@pytest.mark.parametrize("name,case", _params(KNOWN_DERIVE))
def test_derive_on_degenerate_recording(tmp_path, name, case):
    """Every derivation runs on what the importer made of the degenerate source (issue 11: no
    rule divides by zero or loops on single samples, standing tracks, gaps)."""
    from aveas_format.derive import derive

    rec = _RECORDINGS.pop((name, case), None)
    if rec is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = _convert(tmp_path, name, case)[0]
            _RECORDINGS.pop((name, case), None)
    if rec is None:
        pytest.skip("the importer rejects this source (a located error)")
    try:
        derive(rec)
    except AveasError as e:   # a clear refusal is fine; a crash is not
        assert "derivation" in str(e) or "derive" in str(e), e


@pytest.mark.parametrize("name,match", [
    ("sumo-fcd", r"fcd\.xml: line 9: participant '1' sampled twice at time 1\.0$"),
    ("infra-lwir", r"gt\.txt: line 13: participant '2' sampled twice at time 0\.04$"),
    ("osi", r"run_gt\.osi: frame 1: participant '2' sampled twice at time 0\.05$"),
    ("highd", r"01_tracks\.csv: line 14: participant '2' sampled twice at time 0\.04$"),
])
@pytest.mark.filterwarnings("ignore:.*earlier than the previous message:UserWarning")  # OSI: sorted first
def test_repeated_time_names_track_and_place(tmp_path, name, match):
    """A track sampled twice at one time: the error (the one duplicates policy of the shared step,
    converters/common/boxes.py) names the file, the line (or frame) of the repeat, the track and
    the time."""
    run, _, _ = SOURCES[name](tmp_path, "dup_time")
    with pytest.raises(aveas_format.FormatError, match=match):
        run()


def test_openscenario_repeated_vertex_time_warns(tmp_path):
    run, n_in, _ = src_openscenario(tmp_path, "dup_time")
    with pytest.warns(UserWarning, match=r"s\.xosc: time 0\.1: 1 trajectory vertices of entity 'p1' "
                                         r"repeat a time \(first at 0\.1 s\) with another position"):
        rec = run()
    assert rec.states.num_rows == n_in - 1
    # the first vertex of the repeated time is kept
    from lxml import etree

    vs = etree.parse(str(tmp_path / "s.xosc")).findall(".//Trajectory[@name='trajectory_p1']//Vertex")
    assert vs[1].get("time") == vs[2].get("time")
    s = rec.states.filter(np.asarray(rec.states.column("participant_id").to_pylist()) == 1)
    assert s.column("x")[1].as_py() == float(vs[1].find("Position/WorldPosition").get("x"))
