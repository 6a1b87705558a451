"""Infrastructure LiDAR -> recording: OpenLABEL labels in the TUM Traffic layout (one JSON per
frame, the real s110 LiDAR mount pose of ../shared/data/tum_traffic_calib/), the ASAM-conformant
form, a plain tracks table, and the ASAM spec's cuboid example; all generated from an analytic
truth in the base frame."""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pyarrow.compute as pc
import pytest
import shapely
from scipy.spatial.transform import Rotation

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.opendrive.builder import straight_highway

from helpers_common import realdata_fixture, shared

GEO = "+proj=tmerc +lat_0=48.24 +lon_0=11.64 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
T0 = 1646667310.044372
NF = 20
RATE = 10.0

# truth in the base frame: (uid, TUM type, x(t), y, heading, l, w, h, num_points)
TRUTH = [
    ("0b1c1c36-2d0b-4c6e-9a4b-000000000001", "CAR", lambda t: -40 + 20 * t, -1.75, 0.0, 4.5, 1.9, 1.5, 120),
    ("0b1c1c36-2d0b-4c6e-9a4b-000000000002", "TRUCK", lambda t: 80 - 15 * t, 5.25, math.pi, 12.0, 2.5, 3.8, 20),
    ("0b1c1c36-2d0b-4c6e-9a4b-000000000003", "PEDESTRIAN", lambda t: 0.0 * t + 5.0, 12.0, 1.0, 0.6, 0.6, 1.8, 5),
]


def calib():
    """The real s110 LiDAR calibration file (../shared; for a realdata test)."""
    return shared("data", "tum_traffic_calib", "s110_lidar_ouster_south.json")


def mount() -> np.ndarray:
    """The LiDAR -> base transformation of :func:`calib` (4x4)."""
    return _mount(calib())


@functools.lru_cache(maxsize=None)
def _mount(path) -> np.ndarray:
    m = np.asarray(json.loads(path.read_text())["transformation_matrix_s110_lidar_ouster_south_to_s110_base"])
    m.setflags(write=False)
    return m


def lidar_cuboid(x, y, heading, l, w, h):
    m_inv = np.linalg.inv(mount())
    c = m_inv @ np.array([x, y, h / 2, 1.0])
    r = m_inv[:3, :3] @ Rotation.from_euler("z", heading).as_matrix()
    q = Rotation.from_matrix(r).as_quat()
    return [*c[:3].tolist(), *q.tolist(), l, w, h]


def tum_frame(k, with_pose=True):
    t = k / RATE
    objects = {}
    for uid, typ, fx, y, hd, l, w, h, n in TRUTH:
        objects[uid] = {"object_data": {
            "name": f"{typ}-{uid[-1]}", "type": typ,
            "cuboid": {"name": "shape3D", "val": lidar_cuboid(fx(t), y, hd, l, w, h),
                       "attributes": {"text": [{"name": "occlusion_level", "val": "NOT_OCCLUDED"},
                                               {"name": "sensor_id", "val": "s110_lidar_ouster_south"}],
                                      "num": [{"name": "num_points", "val": n}]}}}}
    cs = {"s110_base": {"type": "scene_cs", "parent": "", "children": ["s110_lidar_ouster_south"]},
          "s110_lidar_ouster_south": {"type": "sensor_cs", "parent": "s110_base", "children": []}}
    if with_pose:
        cs["s110_lidar_ouster_south"]["pose_wrt_parent"] = {"matrix4x4": mount().ravel().tolist()}
    return {"openlabel": {
        "metadata": {"schema_version": "1.0.0"}, "coordinate_systems": cs,
        "frames": {str(k): {"frame_properties": {
            "timestamp": T0 + t, "point_cloud_file_names": [f"{k:06d}_s110_lidar_ouster_south.pcd"]},
            "objects": objects}}}}


@pytest.fixture(scope="module")
def site_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "site.xodr"
    p.write_text(straight_highway(length=300.0, lanes_right=2, lanes_left=2, x0=-100.0, y0=0.0,
                                  geo_reference=GEO))
    return p


@realdata_fixture(scope="module")
def tum_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("tum")
    out = []
    for k in range(NF):
        p = d / f"{k:06d}_s110_lidar_ouster_south.json"
        p.write_text(json.dumps(tum_frame(k)))
        out.append(p)
    return out


def truth_at(i, t):
    uid, typ, fx, y, hd, l, w, h, n = TRUTH[i]
    return fx(t), y, hd


def test_registered():
    assert "infra-lidar" in load_converters()


@pytest.mark.realdata
def test_tum_layout(tum_files, site_map, tmp_path):
    rec = convert("infra-lidar", tum_files, map_source=site_map, options={"fov_deg": 160.0,
                                                                          "fov_yaw_deg": -70.0})
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == [u for u, *_ in TRUTH]
    assert p.column("class").to_pylist() == ["car", "truck", "pedestrian"]
    assert p.column("length").to_pylist() == pytest.approx([4.5, 12.0, 0.6])
    assert p.column("height").to_pylist() == pytest.approx([1.5, 3.8, 1.8])
    assert rec.meta.start_time.startswith("2022-03-07T15:35:10.044")
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x, y, h = s.column("x").to_numpy(), s.column("y").to_numpy(), s.column("heading").to_numpy()
    for i in range(3):
        sel = pid == i
        assert t[sel] == pytest.approx(np.arange(NF) / RATE)
        tx, ty, th = truth_at(i, t[sel])
        assert x[sel] == pytest.approx(tx, abs=1e-6) and y[sel] == pytest.approx(ty, abs=1e-6)
        assert np.allclose(np.cos(h[sel] - th), 1.0)
    assert np.allclose(s.column("z").to_numpy(), 0.0, atol=1e-9)
    car = pid == 0
    assert s.column("vx").to_numpy()[car] == pytest.approx(20.0)
    assert s.column("vx").to_numpy()[pid == 1] == pytest.approx(-15.0)
    assert s.column("lane_id").to_numpy()[car].tolist() == [-1] * NF
    sensor = rec.meta.acquisition.sensors[0].pose
    assert (sensor.x, sensor.y, sensor.z) == pytest.approx(tuple(mount()[:3, 3]))
    report = aveas_format.validate(rec.write(tmp_path / "tum.aveas"))
    assert report.counts["error"] == 0, report


@pytest.mark.realdata
def test_uncertainty_model(tum_files, site_map):
    """sigma along the line of sight (0.05 + 0.002 r) f, across it (0.05 + 0.0015 r) f with
    f = sqrt(50 / 20) for the truck's 20 points, rotated by the bearing."""
    rec = convert("infra-lidar", tum_files, map_source=site_map)
    s = rec.states
    row = int(np.flatnonzero(s.column("participant_id").to_numpy() == 1)[3])
    x, y = s.column("x")[row].as_py(), s.column("y")[row].as_py()
    dx, dy = x - mount()[0, 3], y - mount()[1, 3]
    r, b = math.hypot(dx, dy), math.atan2(dy, dx)
    f = math.sqrt(50 / 20)
    sr, st = (0.05 + 0.002 * r) * f, (0.05 + 0.0015 * r) * f
    rot = np.array([[math.cos(b), -math.sin(b)], [math.sin(b), math.cos(b)]])
    c = rot @ np.diag([sr ** 2, st ** 2]) @ rot.T
    assert s.column("x_std")[row].as_py() == pytest.approx(math.sqrt(c[0, 0]))
    assert s.column("y_std")[row].as_py() == pytest.approx(math.sqrt(c[1, 1]))
    assert s.column("xy_corr")[row].as_py() == pytest.approx(c[0, 1] / math.sqrt(c[0, 0] * c[1, 1]), abs=1e-6)
    assert s.column("heading_std")[row].as_py() == pytest.approx(0.03 * f)
    car = np.flatnonzero(s.column("participant_id").to_numpy() == 0)
    assert np.all(s.column("heading_std").to_numpy()[car] == pytest.approx(0.03))  # 120 points
    assert np.all(s.column("vx_std").to_numpy()[car] > 0)


@pytest.mark.realdata
def test_unobserved_regions(tum_files, site_map):
    rec = convert("infra-lidar", tum_files, map_source=site_map,
                  options={"range_m": 80.0, "fov_deg": 180.0, "fov_yaw_deg": -77.6})
    u = rec.table("unobserved")
    kinds = u.column("kind").to_pylist()
    assert kinds[:2] == ["sensor_range", "field_of_view"]
    occ = [i for i, k in enumerate(kinds) if k == "occlusion"]
    assert len(occ) > 0
    assert set(u.column("occluder_id").to_numpy(zero_copy_only=False)[occ]) <= {0, 1, 2}
    geoms = shapely.from_wkb(u.column("geometry").to_pylist())
    assert shapely.is_valid(geoms).all()
    sx, sy, sh = mount()[:3, 3]
    # the car at t = 0: ground behind it (seen from the sensor) is hidden, ground in front is not
    row = next(i for i in occ if u.column("occluder_id")[i].as_py() == 0 and u.column("time_start")[i].as_py() == 0)
    cx, cy = -40.0, -1.75
    d = np.array([cx - sx, cy - sy])
    d /= np.linalg.norm(d)
    behind = shapely.Point(cx + d[0] * 3.0, cy + d[1] * 3.0)
    front = shapely.Point(cx - d[0] * 4.0, cy - d[1] * 4.0)
    assert geoms[row].contains(behind) and not geoms[row].contains(front)
    # its length: d * H / (H - h) for the far corner ~ the far corner's distance * 7.48 / 5.98
    assert u.column("time_end")[row].as_py() == pytest.approx(0.1)
    assert rec.meta.coverage.startswith("POLYGON")


@pytest.mark.realdata
def test_asam_form_and_sensor_pose_file(site_map, tmp_path):
    """One file per sequence, ASAM-conformant (cuboid lists, type in the top-level objects,
    coordinate_system in the cuboid), the cuboids' system has no pose: the real TUM calibration
    file is given as a further input."""
    frames, objects = {}, {}
    for k in range(NF):
        f = tum_frame(k, with_pose=False)["openlabel"]["frames"][str(k)]
        for uid, o in f["objects"].items():
            od = o["object_data"]
            objects[uid] = {"name": od.pop("name"), "type": od.pop("type").lower()}
            cub = od["cuboid"]
            cub["coordinate_system"] = "s110_lidar_ouster_south"
            od["cuboid"] = [cub]
        frames[str(k)] = f
    doc = {"openlabel": {"metadata": {"schema_version": "1.0.0"},
                         "coordinate_systems": tum_frame(0, with_pose=False)["openlabel"]["coordinate_systems"],
                         "objects": objects, "frames": frames}}
    seq = tmp_path / "sequence.json"
    seq.write_text(json.dumps(doc))
    rec = convert("infra-lidar", [seq, calib()], map_source=site_map)
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    tx, ty, _ = truth_at(1, t[pid == 1])
    assert s.column("x").to_numpy()[pid == 1] == pytest.approx(tx, abs=1e-6)
    assert s.column("y").to_numpy()[pid == 1] == pytest.approx(ty, abs=1e-6)
    assert rec.participants.column("class").to_pylist() == ["car", "truck", "pedestrian"]
    assert [i.file for i in rec.meta.source.inputs] == ["sequence.json", calib().name]


@pytest.mark.realdata
def test_tracks_table_with_frame_offset(site_map, tmp_path):
    """A tracker's CSV in the sensor frame + the calibration; frame_offset shifts the base frame."""
    lines = ["frame,track_id,class,x,y,z,yaw,length,width,height,num_points"]
    for k in range(NF):
        for j, (uid, typ, fx, y, hd, l, w, h, n) in enumerate(TRUTH):
            v = lidar_cuboid(fx(k / RATE) - 10.0, y, hd, l, w, h)
            yaw = math.atan2(*(Rotation.from_quat(v[3:7]).as_matrix()[[1, 0], 0]))
            lines.append(f"{k},{j},{typ.lower()},{v[0]},{v[1]},{v[2]},{yaw},{l},{w},{h},{n}")
    csv = tmp_path / "tracks.csv"
    csv.write_text("\n".join(lines) + "\n")
    rec = convert("infra-lidar", [csv], map_source=site_map,
                  options={"sensor_pose": str(calib()), "frame_offset": [10.0, 0.0, 0.0], "rate_hz": 10})
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    tx, ty, _ = truth_at(0, t[pid == 0])
    # the sensor's small pitch/roll tilt the yaw-only table boxes: centimetres at these ranges
    assert s.column("x").to_numpy()[pid == 0] == pytest.approx(tx, abs=0.1)
    assert s.column("y").to_numpy()[pid == 0] == pytest.approx(ty, abs=0.1)
    assert rec.participants.column("source_id").to_pylist() == ["0", "1", "2"]
    assert aveas_format.validate(rec.write(tmp_path / "t.aveas")).counts["error"] == 0


@pytest.mark.realdata
def test_asam_spec_cuboid_example_is_a_moving_sensor(tmp_path):
    """The ASAM spec's cuboid example puts its cuboids in vehicle-iso8855, which per-frame
    transforms carry into UTM: a sensor on a moving vehicle. infra-lidar used to read the boxes
    as if the vehicle stood still; it now refuses and names the converter that applies them."""
    asam_cuboids = shared("data", "openlabel", "asam_spec__openlabel100_example_cuboids.json")
    m = tmp_path / "m.xodr"
    m.write_text(straight_highway(length=400.0, lanes_right=3, lanes_left=3, x0=-200.0, geo_reference=GEO))
    with pytest.raises(aveas_format.FormatError,
                       match=r"frame_properties.transforms carry coordinate system 'vehicle-iso8855' "
                             r"into 'utm-30t' \(geo_utm\).*--from openlabel"):
        convert("infra-lidar", [asam_cuboids], map_source=m, options={"occlusion": False})


@pytest.mark.realdata
def test_frame_transforms_move_the_sensor(site_map, tmp_path):
    """A LiDAR whose pose in the base frame changes per frame (frame_properties.transforms, as a
    sensor on a slowly moving platform writes them): the boxes are placed through each frame's
    transform, and the field of view follows the sensor frame by frame."""
    files = []
    for k in range(NF):
        doc = tum_frame(k)
        shift = np.eye(4)
        shift[0, 3] = 2.0 * k  # the platform moves 2 m per frame along x
        # the cuboids were written for the static pose m; the frame's transform is shift @ m, so
        # express them in the moved sensor frame: c' = (shift m)^-1 m c
        moved = shift @ mount()
        inv = np.linalg.inv(moved) @ mount()
        for obj in doc["openlabel"]["frames"][str(k)]["objects"].values():
            v = obj["object_data"]["cuboid"]["val"]
            c = inv @ np.array([*v[:3], 1.0])
            r = inv[:3, :3] @ Rotation.from_quat(v[3:7]).as_matrix()
            obj["object_data"]["cuboid"]["val"] = [*c[:3].tolist(), *Rotation.from_matrix(r).as_quat().tolist(),
                                                   *v[7:]]
        doc["openlabel"]["frames"][str(k)]["frame_properties"]["transforms"] = {
            "lidar_to_base": {"src": "s110_lidar_ouster_south", "dst": "s110_base",
                              "transform_src_to_dst": {"matrix4x4": moved.ravel().tolist()}}}
        p = tmp_path / f"{k:06d}.json"
        p.write_text(json.dumps(doc))
        files.append(p)
    rec = convert("infra-lidar", files, map_source=site_map)
    s = rec.states
    for i in range(len(TRUTH)):
        one = s.filter(pc.equal(s.column("participant_id"), i))
        t = one.column("time").to_numpy()
        x_true = np.array([truth_at(i, tt)[0] for tt in t])
        assert np.allclose(one.column("x").to_numpy(), x_true, atol=1e-6)
    assert "moving" in rec.meta.acquisition.platform
    fov = rec.unobserved.filter(pc.equal(rec.unobserved.column("kind"), "sensor_range"))
    assert fov.num_rows == NF  # one range limit per frame, following the sensor
    assert rec.meta.source.options["timestamp_unit"] == "s"


@pytest.mark.realdata
def test_malformed_inputs_are_located(site_map, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"openlabel": {\n  "frames": {\n    "0": {,}\n}}}')
    with pytest.raises(aveas_format.FormatError, match=r"bad.json: line 3, column 11: broken JSON"):
        convert("infra-lidar", [bad], map_source=site_map)
    doc = tum_frame(0)
    uid = TRUTH[1][0]
    doc["openlabel"]["frames"]["0"]["objects"][uid]["object_data"]["cuboid"]["val"] = [1, 2, 3, 0, 0, 0, 1]
    short = tmp_path / "short.json"
    short.write_text(json.dumps(doc))
    with pytest.raises(aveas_format.FormatError,
                       match=rf"short.json: frame 0: object '{uid}': cuboid val has 7 values"):
        convert("infra-lidar", [short], map_source=site_map)
    csv = tmp_path / "t.csv"
    csv.write_text("time,id,class,x,y,z,yaw,l,w,h\n0,1,car,1,2,0,0,4,2,1.5\n0.1,1,car,abc,2,0,0,4,2,1.5\n")
    with pytest.raises(aveas_format.FormatError, match=r"t.csv: line 3: column 'x': 'abc' is not a number"):
        convert("infra-lidar", [csv, calib()], map_source=site_map)
    with pytest.raises(aveas_format.FormatError, match=r"t.csv: a tracks table needs a sensor pose"):
        csv.write_text("time,id,class,x,y,z,yaw,l,w,h\n0,1,car,1,2,0,0,4,2,1.5\n")
        convert("infra-lidar", [csv], map_source=site_map)
    csv.write_text("time,id,class,x,y,z,yaw,l,w,h\n0,1,car,1,2,0,0,4,2,1.5\n0.1,1,car,1,2,0,0,-4,2,1.5\n")
    with pytest.raises(aveas_format.FormatError, match=r"t.csv: line 3: column 'l': value must be positive"):
        convert("infra-lidar", [csv, calib()], map_source=site_map)
    pose = tmp_path / "pose.json"
    pose.write_text('{"projection": [[1, 2, 3, 4]]}')
    csv.write_text("time,id,class,x,y,z,yaw,l,w,h\n0,1,car,1,2,0,0,4,2,1.5\n")
    with pytest.raises(aveas_format.FormatError, match=r"pose.json: no 4x4 transform found"):
        convert("infra-lidar", [csv, pose], map_source=site_map)


@pytest.mark.realdata
def test_timestamp_units_and_non_road_users(site_map, tmp_path):
    """Epoch microseconds as strings (inferred, recorded in the source block); a DontCare track
    and a barrier are skipped with a note; keep_non_road_users keeps the barrier."""
    files = []
    for k in range(NF):
        doc = tum_frame(k)
        fr = doc["openlabel"]["frames"][str(k)]
        fr["frame_properties"]["timestamp"] = str(int(round((T0 + k / RATE) * 1e6)))
        cub = dict(next(iter(fr["objects"].values()))["object_data"]["cuboid"])
        fr["objects"]["dc"] = {"object_data": {"type": "DontCare", "cuboid": {
            **cub, "val": cub["val"][:7] + [-1000.0, -1000.0, -1000.0]}}}
        fr["objects"]["b"] = {"object_data": {"type": "barrier", "cuboid": {
            **cub, "val": cub["val"][:7] + [2.0, 0.3, 1.0]}}}
        p = tmp_path / f"{k:06d}.json"
        p.write_text(json.dumps(doc))
        files.append(p)
    with pytest.warns(UserWarning, match=r"skipped 2 tracks: 1 barrier \(no road user\); 1 DontCare"):
        rec = convert("infra-lidar", files, map_source=site_map)
    assert rec.participants.num_rows == len(TRUTH)
    assert np.allclose(np.unique(rec.states.column("time").to_numpy()), np.arange(NF) / RATE)
    assert rec.meta.start_time.startswith("2022-03-07T15:35:10.044372")
    assert rec.meta.source.options["timestamp_unit"] == "us"
    with pytest.warns(UserWarning, match=r"skipped 1 tracks: 1 DontCare"):
        rec = convert("infra-lidar", files, map_source=site_map, options={"keep_non_road_users": True})
    assert rec.participants.num_rows == len(TRUTH) + 1
