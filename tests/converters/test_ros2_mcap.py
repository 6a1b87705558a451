"""ROS 2 MCAP -> recording, on MCAP files written here with ``mcap_ros2.writer`` and the real
message definitions in ../shared/data/ros2_msgdefs/ (an analytic scene: an ego at 20 m/s on a
straight 3-lane road, objects in the map frame, in base_link and in a lidar frame)."""

from __future__ import annotations

import math
import subprocess
import sys
import uuid

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.opendrive.builder import straight_highway

from helpers_common import realdata_fixture, shared

pytest.importorskip("mcap_ros2")
from mcap_ros2.writer import Writer  # noqa: E402

SEP = "=" * 80
# tf2_msgs/msg/TFMessage is not among the shared definitions: its full text, from the same
# geometry_msgs/std_msgs sources
TF_MSGDEF = "\n".join([
    "geometry_msgs/TransformStamped[] transforms", SEP, "MSG: geometry_msgs/TransformStamped",
    "std_msgs/Header header", "string child_frame_id", "Transform transform", SEP,
    "MSG: std_msgs/Header", "builtin_interfaces/Time stamp", "string frame_id", SEP,
    "MSG: builtin_interfaces/Time", "int32 sec", "uint32 nanosec", SEP,
    "MSG: geometry_msgs/Transform", "Vector3 translation", "Quaternion rotation", SEP,
    "MSG: geometry_msgs/Vector3", "float64 x", "float64 y", "float64 z", SEP,
    "MSG: geometry_msgs/Quaternion", "float64 x 0", "float64 y 0", "float64 z 0", "float64 w 1", ""])
TYPES = {
    "autoware_perception_msgs/msg/TrackedObjects": "autoware_perception_msgs__TrackedObjects.msg",
    "derived_object_msgs/msg/ObjectWithCovarianceArray": "derived_object_msgs__ObjectWithCovarianceArray.msg",
    "vision_msgs/msg/Detection3DArray": "vision_msgs__Detection3DArray.msg",
    "nav_msgs/msg/Odometry": "nav_msgs__Odometry.msg",
    "sensor_msgs/msg/NavSatFix": "sensor_msgs__NavSatFix.msg",
}

T0 = 1_700_000_000_000_000_000  # ns
RATE = 10.0
N = 30  # 3 s
YAW0 = math.radians(30.0)  # ROS map frame rotated by 30 degrees in the OpenDRIVE frame
OFFSET = (100.0, 50.0, YAW0)
GEO = "+proj=tmerc +lat_0=48.8 +lon_0=11.1 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
EGO_Y = -5.25
POSE_COV_A = np.array([[0.25, 0.05], [0.05, 0.04]])  # sx 0.5, sy 0.2, corr 0.5
EGO_COV = np.diag([0.01, 0.04, 0.0004])  # ego x, y, yaw


def write_mcap(path, messages, msgdefs=None):
    """messages: (topic, type, dict, log_ns)."""
    with open(path, "wb") as f:
        w = Writer(f)
        schemas = {}
        for topic, ty, msg, log in messages:
            if ty not in schemas:
                text = TF_MSGDEF if ty == "tf2_msgs/msg/TFMessage" else (
                    (msgdefs or {}).get(ty) or msgdef(TYPES[ty]))
                schemas[ty] = w.register_msgdef(ty, text)
            w.write_message(topic, schemas[ty], msg, log_time=log, publish_time=log)
        w.finish()
    return path


def msgdef(name: str) -> str:
    """A real ROS 2 message definition of ../shared/data/ros2_msgdefs (for a realdata test)."""
    return shared("data", "ros2_msgdefs", name).read_text()


def header(t_ns, frame):
    return {"stamp": {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}, "frame_id": frame}


def quat(yaw):
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def pose(x, y, z, yaw):
    return {"position": {"x": x, "y": y, "z": z}, "orientation": quat(yaw)}


def cov6(xy=None, yaw=0.0):
    c = np.zeros((6, 6))
    if xy is not None:
        c[:2, :2] = xy
    c[5, 5] = yaw
    return c.ravel().tolist()


def twist(vx, vy, wz=0.0):
    return {"linear": {"x": vx, "y": vy, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": wz}}


def ego_x(t):
    return 10.0 + 20.0 * t


def odometry(t_ns, t):
    c = np.zeros((6, 6))
    c[0, 0], c[1, 1], c[5, 5] = EGO_COV[0, 0], EGO_COV[1, 1], EGO_COV[2, 2]
    return {"header": header(t_ns, "map"), "child_frame_id": "base_link",
            "pose": {"pose": pose(ego_x(t), EGO_Y, 0.0, 0.0), "covariance": c.ravel().tolist()},
            "twist": {"twist": twist(20.0, 0.0), "covariance": cov6(np.diag([0.04, 0.01]))}}


UUID_A = uuid.UUID(int=0xA).bytes
UUID_B = uuid.UUID(int=0xB).bytes


def tracked(t_ns, t):
    zero = {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}

    def obj(uid, x, y, v, cls, dims, tcov):
        return {
            "object_id": {"uuid": list(uid)}, "existence_probability": 0.95,
            "classification": cls,
            "kinematics": {
                "pose_with_covariance": {"pose": pose(x, y, 0.75, 0.0), "covariance": cov6(POSE_COV_A, 0.01)},
                "twist_with_covariance": {"twist": twist(v, 0.0), "covariance": cov6(tcov)},
                "acceleration_with_covariance": {"accel": zero, "covariance": [0.0] * 36},
                "orientation_availability": 2, "is_stationary": False},
            "shape": {"type": 0, "footprint": {"points": []}, "dimensions": {"x": dims[0], "y": dims[1], "z": dims[2]}},
        }
    return {"header": header(t_ns, "map"), "objects": [
        obj(UUID_A, 40.0 + 22.0 * t, EGO_Y, 22.0, [{"label": 1, "probability": 0.8}, {"label": 12 - 10, "probability": 0.2}],
            (4.5, 1.8, 1.5), np.diag([0.09, 0.01])),
        obj(UUID_B, 80.0 + 25.0 * t, -8.75, 25.0, [{"label": 2, "probability": 1.0}], (12.0, 2.5, 3.8), np.diag([0.04, 0.04])),
    ]}


def _bad_pose(n, at, axis, value):
    """``n`` TrackedObjects messages, object 1's position ``axis`` set to ``value`` in message ``at``."""
    msgs = []
    for i in range(n):
        m = tracked(T0 + i * 100_000_000, i / 10)
        if i == at:
            m["objects"][1]["kinematics"]["pose_with_covariance"]["pose"]["position"][axis] = value
        msgs.append(("/objects", "autoware_perception_msgs/msg/TrackedObjects", m, T0 + i))
    return msgs


def derived(t_ns, mi, rel=(15.0, 3.5)):
    return {"header": header(t_ns, "base_link"), "objects": [{
        "header": header(t_ns, "base_link"), "id": 7, "detection_level": 1, "object_classified": True,
        "pose": {"pose": pose(rel[0], rel[1], 0.7, 0.0), "covariance": cov6(np.diag([0.09, 0.01]), 0.0025)},
        "twist": {"twist": twist(21.0, 0.0), "covariance": cov6(np.diag([0.25, 0.04]))},
        "accel": {"accel": twist(0.0, 0.0), "covariance": [0.0] * 36},
        "polygon": {"points": []},
        "shape": {"type": 1, "dimensions": [4.2, 1.8, 1.4], "covariance": []},
        "classification": 6, "classification_certainty": 204, "classification_age": mi}]}


@pytest.fixture(scope="module")
def road_map(tmp_path_factory):
    """The road along +x of the ROS map frame, i.e. at 30 degrees in the OpenDRIVE frame."""
    p = tmp_path_factory.mktemp("maps") / "road.xodr"
    c, s = math.cos(YAW0), math.sin(YAW0)
    x0, y0 = OFFSET[0], OFFSET[1]
    p.write_text(straight_highway(length=1000.0, lanes_right=3, x0=x0, y0=y0, hdg=YAW0,
                                  geo_reference=GEO))
    del c, s
    return p


def to_local(x, y):
    c, s = math.cos(YAW0), math.sin(YAW0)
    return OFFSET[0] + c * x - s * y, OFFSET[1] + s * x + c * y


@realdata_fixture(scope="module")
def scene_mcap(tmp_path_factory):
    rng = np.random.default_rng(1)
    msgs = []
    for i in range(N):
        t = i / RATE
        t_ns = T0 + int(round(t * 1e9))
        log = t_ns + int(rng.uniform(0.05, 0.3) * 1e9)  # log time != stamp
        msgs.append(("/localization/kinematic_state", "nav_msgs/msg/Odometry", odometry(t_ns, t), log))
        msgs.append(("/perception/object_recognition/tracking/objects",
                     "autoware_perception_msgs/msg/TrackedObjects", tracked(t_ns + 20_000_000, t + 0.02), log))
        msgs.append(("/radar/objects", "derived_object_msgs/msg/ObjectWithCovarianceArray",
                     derived(t_ns + 50_000_000, i), log))
    return write_mcap(tmp_path_factory.mktemp("mcap") / "scene.mcap", msgs)


def _opts(**kw):
    return {"frame_offset": list(OFFSET), "ego_center_offset": 1.4, "partner": "test", **kw}


def test_registered():
    assert "ros2-mcap" in load_converters()
    # the subpackage registers once (loading again imports nothing new), from the module whose
    # docstring docs/converters.md shows
    convs = load_converters()
    assert [k for k, c in convs.items() if c.name == "ros2-mcap"] == ["ros2-mcap"]
    assert convs["ros2-mcap"].fn.__module__ == "aveas_format.converters.ros2_mcap.converter"


def test_scene(scene_mcap, road_map, tmp_path):
    rec = convert("ros2-mcap", [scene_mcap], map_source=road_map, options=_opts())
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == ["ego", "0:" + UUID_A.hex(), "0:" + UUID_B.hex(), "1:7"]
    assert p.column("role").to_pylist() == ["recording_vehicle", "observed", "observed", "observed"]
    assert p.column("class").to_pylist() == ["car", "car", "truck", "car"]
    assert rec.meta.acquisition.method.value == "road_vehicle"
    assert rec.meta.start_time == "2023-11-14T22:13:20.000000000Z"  # header.stamp, not log time
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x, y = s.column("x").to_numpy(), s.column("y").to_numpy()
    # ego: base_link + 1.4 m ahead, in the local frame
    e = pid == 0
    ex, ey = to_local(ego_x(t[e]) + 1.4, np.full(e.sum(), EGO_Y))
    assert np.allclose(x[e], ex) and np.allclose(y[e], ey)
    assert np.allclose(s.column("heading").to_numpy()[e], YAW0)
    assert s.column("lane_id").to_numpy()[e].tolist() == [-2] * N
    # object A: map frame, stamps 20 ms after the ego's
    a = pid == 1
    assert t[a] == pytest.approx(np.arange(N) / RATE + 0.02)
    ax_, ay_ = to_local(40.0 + 22.0 * t[a], np.full(a.sum(), EGO_Y))
    assert np.allclose(x[a], ax_) and np.allclose(y[a], ay_)
    assert np.allclose(s.column("vx").to_numpy()[a], 22 * math.cos(YAW0))
    assert np.allclose(s.column("vy").to_numpy()[a], 22 * math.sin(YAW0))
    pmf = rec.participants.column("class_pmf").to_pylist()[1]
    assert pmf["car"] == pytest.approx(0.8) and pmf["truck"] == pytest.approx(0.2)
    assert p.column("length").to_pylist()[1:3] == pytest.approx([4.5, 12.0])
    out = rec.write(tmp_path / "scene.aveas")
    report = aveas_format.validate(out)
    assert report.counts["error"] == 0, report


def test_covariance_is_rotated(scene_mcap, road_map):
    """A known (x, y) covariance in the ROS map frame appears rotated by the frame's 30 degrees."""
    rec = convert("ros2-mcap", [scene_mcap], map_source=road_map, options=_opts())
    s = rec.states
    a = s.column("participant_id").to_numpy() == 1
    r = np.array([[math.cos(YAW0), -math.sin(YAW0)], [math.sin(YAW0), math.cos(YAW0)]])
    c = r @ POSE_COV_A @ r.T
    sx, sy = math.sqrt(c[0, 0]), math.sqrt(c[1, 1])
    assert s.column("x_std").to_numpy()[a] == pytest.approx(sx)
    assert s.column("y_std").to_numpy()[a] == pytest.approx(sy)
    assert s.column("xy_corr").to_numpy()[a] == pytest.approx(c[0, 1] / (sx * sy), abs=1e-6)
    assert s.column("heading_std").to_numpy()[a] == pytest.approx(0.1)
    # twist in the body frame: R V R^T + var(yaw) g g^T with g = d(R v)/d yaw = (-vy, vx)
    v = np.array([22 * math.cos(YAW0), 22 * math.sin(YAW0)])
    g = np.array([-v[1], v[0]])
    cv = r @ np.diag([0.09, 0.01]) @ r.T + 0.01 * np.outer(g, g)
    assert s.column("vx_std").to_numpy()[a] == pytest.approx(math.sqrt(cv[0, 0]))
    assert s.column("vy_std").to_numpy()[a] == pytest.approx(math.sqrt(cv[1, 1]))
    assert s.column("vxvy_corr").to_numpy()[a] == pytest.approx(
        cv[0, 1] / math.sqrt(cv[0, 0] * cv[1, 1]), abs=1e-6)


def test_objects_in_base_link_carry_the_ego_uncertainty(scene_mcap, road_map):
    """derived_object_msgs in base_link: position through the ego pose, covariance
    J_obj C J_obj^T + J_ego C_ego J_ego^T (lever arm 15 m ahead, 3.5 m left)."""
    rec = convert("ros2-mcap", [scene_mcap], map_source=road_map, options=_opts())
    s = rec.states
    b = s.column("participant_id").to_numpy() == 3
    t = s.column("time").to_numpy()[b]
    bx, by = to_local(ego_x(t) + 15.0, np.full(b.sum(), EGO_Y + 3.5))
    assert np.allclose(s.column("x").to_numpy()[b], bx)
    assert np.allclose(s.column("y").to_numpy()[b], by)
    # in the ROS map frame (ego yaw 0): C = diag(0.09, 0.01) + ego xy + yaw var * (-3.5, 15) outer
    lever = np.array([-3.5, 15.0])
    c_map = np.diag([0.09, 0.01]) + EGO_COV[:2, :2] + EGO_COV[2, 2] * np.outer(lever, lever)
    r = np.array([[math.cos(YAW0), -math.sin(YAW0)], [math.sin(YAW0), math.cos(YAW0)]])
    c = r @ c_map @ r.T
    assert s.column("x_std").to_numpy()[b] == pytest.approx(math.sqrt(c[0, 0]))
    assert s.column("y_std").to_numpy()[b] == pytest.approx(math.sqrt(c[1, 1]))
    assert s.column("xy_corr").to_numpy()[b] == pytest.approx(c[0, 1] / math.sqrt(c[0, 0] * c[1, 1]), abs=1e-6)
    assert s.column("heading_std").to_numpy()[b] == pytest.approx(math.sqrt(0.0025 + 0.0004))
    # absolute twist in the header frame, rotated by the frame's yaw
    assert np.allclose(s.column("vx").to_numpy()[b], 21 * math.cos(YAW0))
    pmf = rec.participants.column("class_pmf").to_pylist()[3]
    assert pmf["car"] == pytest.approx(0.8 + 0.2 / 13, abs=1e-6)
    assert rec.participants.column("length").to_pylist()[3] == pytest.approx(4.2)


def test_relative_velocity(scene_mcap, road_map):
    rec = convert("ros2-mcap", [scene_mcap], map_source=road_map,
                  options=_opts(relative_velocity=True, object_topics=["/radar/objects"]))
    s = rec.states
    b = s.column("participant_id").to_numpy() == 1
    assert np.allclose(s.column("vx").to_numpy()[b], 41 * math.cos(YAW0))


def navsatfix_messages(geo: str = GEO) -> list:
    """The ego as NavSatFix lon/lat (through ``geo``), a pedestrian 21 m ahead and 5 m left of it
    as vision_msgs detections in a lidar frame 1 m ahead of base_link (/tf_static)."""
    from aveas_format.crs import LocalFrame

    frame = LocalFrame(geo)
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": [{
        "header": header(T0, "base_link"), "child_frame_id": "lidar_top",
        "transform": {"translation": {"x": 1.0, "y": 0.0, "z": 1.8}, "rotation": quat(0.0)}}]}, T0)]
    for i in range(N):
        t = i / RATE
        t_ns = T0 + int(round(t * 1e9))
        lx, ly = to_local(ego_x(t), EGO_Y)
        lon, lat = frame.to_wgs84(np.array([lx]), np.array([ly]))
        msgs.append(("/fix", "sensor_msgs/msg/NavSatFix", {
            "header": header(t_ns, "gnss"), "status": {"status": 0, "service": 1},
            "latitude": float(lat[0]), "longitude": float(lon[0]), "altitude": 500.0,
            "position_covariance": [0.04, 0, 0, 0, 0.04, 0, 0, 0, 0.25], "position_covariance_type": 2}, t_ns))
        msgs.append(("/detections", "vision_msgs/msg/Detection3DArray", {
            "header": header(t_ns, "lidar_top"), "detections": [{
                "header": header(t_ns, "lidar_top"),
                "results": [{"hypothesis": {"class_id": "person", "score": 0.9},
                             "pose": {"pose": pose(0, 0, 0, 0), "covariance": cov6(np.diag([0.01, 0.01]))}},
                            {"hypothesis": {"class_id": "bicycle", "score": 0.1},
                             "pose": {"pose": pose(0, 0, 0, 0), "covariance": [0.0] * 36}}],
                "bbox": {"center": pose(20.0, 5.0, 0.0, 0.0), "size": {"x": 0.6, "y": 0.6, "z": 1.8}},
                "id": "ped1"}]}, t_ns))
    return msgs


@pytest.mark.realdata
def test_navsatfix_ego_and_tf_static(road_map, tmp_path):
    """No odometry: the ego from NavSatFix (heading from motion); vision_msgs detections in a lidar
    frame 1 m ahead of base_link (/tf_static); velocity from positions."""
    path = write_mcap(tmp_path / "fix.mcap", navsatfix_messages())
    rec = convert("ros2-mcap", [path], map_source=road_map, options=_opts(ego_center_offset=0.0))
    p, s = rec.participants, rec.states
    assert p.column("class").to_pylist() == ["car", "pedestrian"]
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    d = pid == 1
    px, py = to_local(ego_x(t[d]) + 21.0, np.full(d.sum(), EGO_Y + 5.0))
    assert np.allclose(s.column("x").to_numpy()[d], px, atol=1e-3)
    assert np.allclose(s.column("y").to_numpy()[d], py, atol=1e-3)
    assert np.allclose(s.column("vx").to_numpy()[d], 20 * math.cos(YAW0), atol=1e-3)
    e = pid == 0
    assert np.allclose(s.column("heading").to_numpy()[e], YAW0, atol=1e-5)
    assert np.allclose(s.column("x_std").to_numpy()[e], 0.2)
    pmf = p.column("class_pmf").to_pylist()[1]
    assert pmf["pedestrian"] == pytest.approx(0.9) and pmf["bicycle"] == pytest.approx(0.1)
    assert aveas_format.validate(rec.write(tmp_path / "fix.aveas")).counts["error"] == 0


def test_malformed_inputs_are_located(scene_mcap, road_map, tmp_path):
    txt = tmp_path / "not.mcap"
    txt.write_text("hello")
    with pytest.raises(aveas_format.FormatError, match=r"not.mcap: not a readable MCAP file"):
        convert("ros2-mcap", [txt], map_source=road_map)
    with pytest.raises(aveas_format.FormatError, match=r"object topic '/nope' not in the file"):
        convert("ros2-mcap", [scene_mcap], map_source=road_map, options={"object_topics": ["/nope"]})
    with pytest.raises(aveas_format.FormatError,
                       match=r"topic /radar/objects message 0: frame 'base_link' has no transform"):
        convert("ros2-mcap", [scene_mcap], map_source=road_map, options={"odometry_topic": ""})
    # a NaN position in message 2
    bad = write_mcap(tmp_path / "nan.mcap", _bad_pose(4, 2, "x", float("nan")))
    with pytest.raises(aveas_format.FormatError, match=r"nan.mcap: topic /objects message 2: object 1: "
                                                        r"pose is not finite"):
        convert("ros2-mcap", [bad], map_source=road_map)
    # a truncated file
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(scene_mcap.read_bytes()[:3000])
    with pytest.raises(aveas_format.FormatError, match=r"cut.mcap: "):
        convert("ros2-mcap", [cut], map_source=road_map)
    # a schema that does not match the message type name (message cannot be read as the type)
    wrong = {"autoware_perception_msgs/msg/TrackedObjects": msgdef("nav_msgs__Odometry.msg")}
    bad2 = write_mcap(tmp_path / "wrong.mcap", [("/objects", "autoware_perception_msgs/msg/TrackedObjects",
                                                 odometry(T0, 0.0), T0)], msgdefs=wrong)
    with pytest.raises(aveas_format.FormatError, match=r"wrong.mcap: topic /objects message 0: malformed"):
        convert("ros2-mcap", [bad2], map_source=road_map)


def test_cli(scene_mcap, road_map, tmp_path):
    out = tmp_path / "cli.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "ros2-mcap",
                          str(scene_mcap), "--map", str(road_map), "-o", str(out),
                          "-O", f"frame_offset={list(OFFSET)}", "-O", "partner=test", "-O",
                          "license=CC-BY-4.0"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert out.is_dir()


@pytest.mark.realdata
def test_barriers_and_signs_are_no_road_users(road_map, tmp_path):
    """derived_object_msgs classification 10 (BARRIER) is no road user: the track is skipped with
    a count, or kept with keep_non_road_users."""
    msgs = []
    for i in range(N):
        t = i / RATE
        t_ns = T0 + int(round(t * 1e9))
        msgs.append(("/localization/kinematic_state", "nav_msgs/msg/Odometry", odometry(t_ns, t), t_ns))
        d = derived(t_ns + 50_000_000, i)
        barrier = dict(d["objects"][0], id=9, classification=10)
        barrier["pose"] = {"pose": pose(30.0 - 20.0 * t, -5.0, 0.5, 0.0), "covariance": cov6(np.diag([0.09, 0.01]))}
        d["objects"].append(barrier)
        msgs.append(("/radar/objects", "derived_object_msgs/msg/ObjectWithCovarianceArray", d, t_ns))
    path = write_mcap(tmp_path / "barrier.mcap", msgs)
    with pytest.warns(UserWarning, match=r"skipped 1 tracks: 1 barrier \(no road user\)"):
        rec = convert("ros2-mcap", [path], map_source=road_map, options=_opts())
    assert rec.participants.column("source_id").to_pylist() == ["ego", "7"]
    rec = convert("ros2-mcap", [path], map_source=road_map, options=_opts(keep_non_road_users=True))
    assert rec.participants.column("source_id").to_pylist() == ["ego", "7", "9"]
    assert rec.participants.column("class").to_pylist()[2] == "other"


# --- which decoder reads a schema: rosbags, or mcap-ros2-support where rosbags refuses -------------

def _short_separators(text: str) -> str:
    """The definition with its separators written as ``===`` (mcap-ros2-support reads any run of
    three or more; rosbags' parser does not take them)."""
    return text.replace(SEP, "===")


def test_a_definition_rosbags_refuses_is_read_by_the_generic_decoder(scene_mcap, road_map, tmp_path,
                                                                     caplog):
    """A real input the fast path knows it does not take: the same recording from the other
    decoder, and the log says which read it and why."""
    ty = "nav_msgs/msg/Odometry"
    msgs = [("/localization/kinematic_state", ty, odometry(T0 + i * 100_000_000, i / RATE),
             T0 + i * 100_000_000) for i in range(N)]
    fast = write_mcap(tmp_path / "fast.mcap", msgs)
    slow = write_mcap(tmp_path / "slow.mcap", msgs, {ty: _short_separators(msgdef(TYPES[ty]))})
    a = convert("ros2-mcap", [fast], map_source=road_map, options=_opts())
    with caplog.at_level("INFO", logger="aveas_format.converters"):
        b = convert("ros2-mcap", [slow], map_source=road_map, options=_opts())
    assert a.states.equals(b.states) and a.participants.equals(b.participants)
    assert "slow.mcap: messages of nav_msgs/msg/Odometry: read by mcap-ros2-support (rosbags does " \
           "not take it: rosbags cannot parse the definition" in caplog.text


def test_a_bug_in_the_rosbags_path_propagates(scene_mcap, road_map, monkeypatch):
    """Anything but the declared refusal propagates: no silent switch to the slower decoder."""
    from aveas_format.converters.ros2_mcap import decode

    def broken(schema):
        raise KeyError("a bug")

    monkeypatch.setattr(decode.Decoders, "_rosbags", staticmethod(broken))
    monkeypatch.setattr(decode.Decoders, "_generic_decoder",
                        lambda *a: pytest.fail("the generic decoder was used"))
    with pytest.raises(KeyError, match="a bug"):
        convert("ros2-mcap", [scene_mcap], map_source=road_map, options=_opts())


def test_verbose_says_which_decoder_read_each_schema(scene_mcap, road_map, tmp_path):
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "ros2-mcap",
                          str(scene_mcap), "--map", str(road_map), "-O", "partner=test",
                          "-O", f"frame_offset={list(OFFSET)}", "-O", "license=CC0-1.0",
                          "-o", str(tmp_path / "v.aveas"), "--verbose"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert ("aveas-format: scene.mcap: messages of nav_msgs/msg/Odometry: read by rosbags"
            in res.stderr), res.stderr


# --- the import in bounded memory --------------------------------------------------------------------

def _busy_scene(path):
    """A longer scene: 40 TrackedObjects tracks in the map frame coming and going (some with an
    unavailable orientation), one message sent twice (repeated stamps), derived_object_msgs in
    base_link (the odometry's frame) with a car, a barrier (no road user) and a track first seen
    before the odometry starts (outside the transforms' span), a lidar frame on /tf_static."""
    m, msgs = 120, []
    for i in range(m):
        t = i / RATE
        t_ns = T0 + int(round(t * 1e9))
        msgs.append(("/localization/kinematic_state", "nav_msgs/msg/Odometry", odometry(t_ns, t), t_ns))
        if i == 0:
            msgs.append(("/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": [{
                "header": header(t_ns, "base_link"), "child_frame_id": "lidar",
                "transform": {"translation": {"x": 1.2, "y": 0.0, "z": 1.8}, "rotation": quat(0.05)}}]}, t_ns))
        tr = tracked(t_ns + 20_000_000, t + 0.02)
        a, b = tr["objects"]
        objs = []
        for k in range(40):
            if k * 2 <= i < k * 2 + 60:
                o = {**(a if k % 2 else b), "object_id": {"uuid": list(uuid.UUID(int=100 + k).bytes)}}
                kin = dict(o["kinematics"], orientation_availability=0 if k % 5 == 0 else 2)
                kin["pose_with_covariance"] = {"pose": pose(5.0 * k + 21.0 * t, -1.75 - 3.5 * (k % 3), 0.7, 0.01 * k),
                                               "covariance": cov6(POSE_COV_A, 0.01)}
                objs.append(dict(o, kinematics=kin))
        tr["objects"] = objs
        topic = "/perception/object_recognition/tracking/objects"
        msgs.append((topic, "autoware_perception_msgs/msg/TrackedObjects", tr, t_ns))
        if i == 30:
            msgs.append((topic, "autoware_perception_msgs/msg/TrackedObjects", tr, t_ns))
        d = derived(t_ns + 50_000_000, i)
        barrier = dict(d["objects"][0], id=9, classification=10)
        barrier["pose"] = {"pose": pose(30.0 - 20.0 * t, -5.0, 0.5, 0.0), "covariance": cov6(np.diag([0.09, 0.01]))}
        d["objects"].append(barrier)
        if i >= 50:
            d["objects"].append(dict(d["objects"][0], id=8))
        msgs.append(("/radar/objects", "derived_object_msgs/msg/ObjectWithCovarianceArray", d, t_ns))
    early = derived(T0 - 5_000_000_000, 0)
    early["objects"] = [dict(early["objects"][0], id=8)]
    msgs.insert(0, ("/radar/objects", "derived_object_msgs/msg/ObjectWithCovarianceArray", early, T0))
    return write_mcap(path, msgs)


@pytest.mark.realdata
def test_bounded_import_writes_the_recording_in_memory(tmp_path, road_map, monkeypatch):
    """``convert_to`` (the CLI's convert, validate FILE) holds the object rows in a StatesWriter
    spilled beyond its memory and writes the states a bucket of tracks at a time: with a memory of
    64 kB, buckets of 32 kB and rows flushed every 500 the recording is the one ``convert``
    makes, with the same warnings (one each, counted over all buckets)."""
    import warnings

    from aveas_format.converters import convert_to
    from aveas_format.converters.ros2_mcap import rows
    from aveas_format.io import resort
    from helpers_converters import assert_written_as_in_memory, count_buckets

    path = _busy_scene(tmp_path / "busy.mcap")
    opts = _opts(recording_id="busy", license="CC0-1.0")
    with warnings.catch_warnings(record=True) as said_whole:
        warnings.simplefilter("always")
        whole = convert("ros2-mcap", [path], map_source=road_map, options=opts)
    buckets = count_buckets(monkeypatch)
    monkeypatch.setattr(rows, "MEMORY", 64 << 10)
    monkeypatch.setattr(resort, "BUCKET_BYTES", 32 << 10)
    monkeypatch.setattr(rows, "FLUSH_ROWS", 500)
    with warnings.catch_warnings(record=True) as said_bounded:
        warnings.simplefilter("always")
        _, n, on_road = convert_to("ros2-mcap", [path], tmp_path / "b.aveas", map_source=road_map,
                                   options=opts)
    assert len(buckets) == 1 and len(buckets[0]) > 10  # (spilled, then made into many buckets)
    said = [sorted(str(w.message) for w in ws) for ws in (said_whole, said_bounded)]
    assert said[0] == said[1]
    assert any(s.startswith("1 object samples lie outside") for s in said[0])  # (track 8's first)
    assert any(s.startswith("busy.mcap: 16 sample(s) repeat") for s in said[0])  # (message 30 twice)
    assert any(s.startswith("skipped 1 tracks: 1 barrier") for s in said[0])
    assert whole.participants.num_rows == 43  # the ego, 40 tracks, the car 7 and track 8
    ids = whole.participants.column("source_id").to_pylist()
    assert ids[:3] == ["ego", "0:" + uuid.UUID(int=100).hex, "1:7"]
    # track 8 numbered where its first sample with a transform is (after the track of message 50)
    assert ids.index("1:8") == ids.index("0:" + uuid.UUID(int=125).hex) + 1
    assert_written_as_in_memory(tmp_path / "b.aveas", whole, n, on_road)


@pytest.mark.realdata
def test_bounded_import_names_the_message_as_in_memory(scene_mcap, road_map, tmp_path, monkeypatch):
    """The errors that name a message (a frame without transform, a pose that is not finite in a
    message read after several flushes) and a track without a length: ``convert_to`` raises what
    ``convert`` raises and leaves neither an output nor its spill behind."""
    from aveas_format.converters import convert_to
    from aveas_format.converters.ros2_mcap import rows
    from aveas_format.io import resort

    (tmp_path / "in").mkdir()
    (tmp_path / "out").mkdir()
    nan = write_mcap(tmp_path / "in" / "nan.mcap", _bad_pose(40, 33, "y", float("inf")))
    msgs = []
    for i in range(40):
        m = tracked(T0 + i * 100_000_000, i / 10)
        # track B (the second) without a size, track A (the first) without a width: the length
        # is checked first
        m["objects"][1]["shape"]["dimensions"] = {"x": 0.0, "y": 0.0, "z": 0.0}
        m["objects"][0]["shape"]["dimensions"]["y"] = 0.0
        msgs.append(("/objects", "autoware_perception_msgs/msg/TrackedObjects", m, T0 + i))
    sizeless = write_mcap(tmp_path / "in" / "sizeless.mcap", msgs)
    monkeypatch.setattr(rows, "MEMORY", 4 << 10)
    monkeypatch.setattr(resort, "BUCKET_BYTES", 2 << 10)
    monkeypatch.setattr(rows, "FLUSH_ROWS", 10)
    for path, opts, what in ((scene_mcap, {"odometry_topic": ""}, "message 0: frame 'base_link' has no transform"),
                             (nan, {}, "message 33: object 1: pose is not finite"),
                             (sizeless, {}, f"participant {UUID_B.hex()!r} has no positive length")):
        with pytest.raises(aveas_format.FormatError) as whole:
            convert("ros2-mcap", [path], map_source=road_map, options=opts)
        with pytest.raises(aveas_format.FormatError) as bounded:
            convert_to("ros2-mcap", [path], tmp_path / "out" / "o.aveas", map_source=road_map,
                       options=opts)
        assert str(bounded.value) == str(whole.value) and what in str(whole.value)
        assert list((tmp_path / "out").iterdir()) == []
