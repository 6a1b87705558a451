"""OpenLABEL (AVEAS profile) export and import: schema, aveas-openlabel, lossless round trip,
files written by aveas-openlabel itself and generic ASAM cuboid files."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys

import jsonschema
import numpy as np
import pyarrow.compute as pc
import pytest

import aveas_format
from aveas_format.converters import convert, get_converter
from aveas_format.opendrive.builder import straight_highway

from helpers_converters import assert_recordings_equal, assert_tables_equal

STRAIGHT = aveas_format.__path__[0] + "/../tests/data/straight.xodr"
SITE = "+proj=tmerc +lat_0=48.9 +lon_0=8.35 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _export(rec, tmp_path, name="rec.json", **opts):
    paths = get_converter("openlabel", "export")(rec, tmp_path / name, options=opts)
    return paths


def test_export_validates_and_loads_in_aveas_openlabel(rich, tmp_path, openlabel_schema):
    aveas_openlabel = pytest.importorskip("aveas_openlabel")
    paths = _export(rich, tmp_path)
    assert [p.name for p in paths] == ["rec.json", "rec.xodr"]
    assert paths[1].read_bytes() == rich.map_source
    doc = json.loads(paths[0].read_text())
    jsonschema.validate(doc, openlabel_schema)
    ol = aveas_openlabel.AveasOpenLabel.from_dict(doc)
    md = doc["openlabel"]["metadata"]
    assert md["acquisition_method"] == "aerial" and md["opendrive"] == "rec.xodr"
    assert md["projection_string"] == rich.meta.crs
    assert md["threshold_gttc"] == 3.0 and md["threshold_pret"] == 1.5 and md["threshold_thw"] == 1.0
    assert md["acquisition_date"] == "2024-05-13T08:15:00.000Z"
    assert len(ol.objects) == rich.participants.num_rows
    assert len(ol.frames) == len(np.unique(rich.states.column("time").to_numpy()))
    # profile content of one object and one state
    p0 = rich.participants.to_pylist()[0]
    obj = doc["openlabel"]["objects"][str(p0["participant_id"])]
    assert obj["type"] == {"car": "vehicle/car", "truck": "vehicle/truck", "van": "vehicle/van"}[p0["class"]]
    vec = {v["name"]: v["val"] for v in obj["object_data"]["vec"]}
    assert vec["dimensions/size"][:2] == [p0["length"], p0["width"]]
    assert sum(vec["classification/uncertainties"]) == pytest.approx(1.0, abs=1e-12)
    s0 = rich.states.slice(0, 1).to_pylist()[0]
    t = np.unique(rich.states.column("time").to_numpy())
    frame = str(int(np.searchsorted(t, s0["time"])))
    od = doc["openlabel"]["frames"][frame]["objects"][str(s0["participant_id"])]["object_data"]
    box = od["cuboid"][0]["val"]
    assert box[0] == s0["x"] and box[1] == s0["y"] and box[5] == s0["heading"]
    v = {x["name"]: x["val"] for x in od["vec"]}
    c, s = math.cos(s0["heading"]), math.sin(s0["heading"])
    assert v["velocity"][0] == pytest.approx(c * s0["vx"] + s * s0["vy"])  # forward
    assert v["velocity"][1] == pytest.approx(-s * s0["vx"] + c * s0["vy"])  # left
    assert v["open_drive/local_road_coordinates"] == [s0["road_s"], s0["road_t"]]
    text = {x["name"]: x["val"] for x in od["text"]}
    assert text["used_road_link"] == s0["road_id"] and text["open_drive/lane_id"] == str(s0["lane_id"])
    num = {x["name"]: x["val"] for x in od["num"]}
    assert num["road/number_lanes/right/physical"] == 3
    assert -0.5 <= num["open_drive/lane_position"] <= 0.5
    # impact attributes below the thresholds, events and contexts
    impacts = [x for f in doc["openlabel"]["frames"].values() for o in f["objects"].values()
               for x in o["object_data"]["vec"] if x["name"] == "impact/gttc/values"]
    assert impacts and all(v < 3.0 for x in impacts for v in x["val"])
    assert {e["type"] for e in doc["openlabel"]["events"].values()} == {"lane change", "following"}
    ctx = [c["name"] for c in doc["openlabel"]["contexts"].values()]
    assert ctx.count("environment_context") == 3 and "scenario_context" in ctx


def test_lossless_round_trip(rich, tmp_path):
    paths = _export(rich, tmp_path)
    back = convert("openlabel", [paths[0]])  # the map is found next to the file
    assert_recordings_equal(rich, back)
    assert_tables_equal(rich.derived["interactions"], back.derived.get("interactions"), "interactions")
    assert back.meta.derived == rich.meta.derived
    assert back.meta.source.converter == "openlabel"
    assert aveas_format.validate(back).counts["error"] == 0


def test_profile_only_export_still_imports(rich, tmp_path, openlabel_schema):
    paths = _export(rich, tmp_path, extension=False)
    doc = json.loads(paths[0].read_text())
    jsonschema.validate(doc, openlabel_schema)
    assert "aveas_format" not in json.dumps(doc)
    back = convert("openlabel", [paths[0]])
    assert back.participants.num_rows == rich.participants.num_rows
    assert np.allclose(back.states.column("x").to_numpy(), rich.states.column("x").to_numpy())
    assert np.allclose(back.states.column("vx").to_numpy(), rich.states.column("vx").to_numpy())
    assert back.meta.acquisition.method.value == "aerial"
    # interior from the profile (the quirk: lateral under the longitudinal name)
    it = back.interior
    assert it is not None and set(it.column("automation_longitudinal_p").to_pylist()) == {1.0}
    assert set(it.column("automation_lateral_p").to_pylist()) == {0.0}
    assert aveas_format.validate(back).counts["error"] == 0


def _aveas_generated(tmp_path):
    """A file written by aveas-openlabel's own classes (to_dict(exclude_none=True))."""
    pytest.importorskip("aveas_openlabel")
    from aveas_openlabel import AveasOpenLabel
    from aveas_openlabel.attributes.dimension import Dimensions__Size
    from aveas_openlabel.attributes.general import (
        Acceleration, BoundingBox, Classification__Uncertainties, IsRecorder, Velocity)
    from aveas_openlabel.attributes.interior import (
        Interior__AutomatedControl__Lateral, Interior__AutomatedControl__Longitudinal)
    from aveas_openlabel.attributes.lights import Lights__Brake
    from aveas_openlabel.attributes.open_drive import (
        OpenDrive__LaneId, OpenDrive__LanePosition, OpenDrive__LocalRoadCoordinates, OpenDrive__RoadId)
    from aveas_openlabel.attributes.road import (
        Road__Classification, Road__ClassificationValue, Road__NumberLanes__Left__Legal,
        Road__NumberLanes__Left__Physical, Road__NumberLanes__Right__Legal,
        Road__NumberLanes__Right__Physical)
    from aveas_openlabel.attributes.summary import (
        Summary__Accel__Max, Summary__Accel__Min, Summary__SteeringAngle__Max,
        Summary__SteeringAngle__Min, Summary__Speed__Max, Summary__Speed__Min)
    from aveas_openlabel.classifications.car import Car, CarInFrame
    from aveas_openlabel.classifications.truck import Truck, TruckInFrame
    from aveas_openlabel.contexts.environment_context import EnvironmentContext, EnvironmentContextData
    from aveas_openlabel.contexts.environment_context_data import (
        Environment__LightingConditions, Environment__LightingConditionsValue, Environment__Temperature)
    from aveas_openlabel.event import Event, EventData, EventTypeValue, RoleAParticipantID, RoleBParticipantIDs
    from aveas_openlabel.frame import Frame, FrameProperties
    from aveas_openlabel.metadata import AcquisitionMethod, Metadata, RightOfUse
    from aveas_openlabel.object_data.unattached import ObjectData__Unattached
    from aveas_openlabel.object_in_frame_data.no_rider import ObjectInFrameData__NoRider
    from uai_openlabel import FrameInterval

    def static(size, pmf):
        return ObjectData__Unattached(
            boolean=[IsRecorder(val=False)],
            num=[Summary__Speed__Max(val=30.0), Summary__Speed__Min(val=20.0), Summary__Accel__Max(val=0.0),
                 Summary__Accel__Min(val=0.0), Summary__SteeringAngle__Max(val=0.0),
                 Summary__SteeringAngle__Min(val=0.0)],
            text=[], vec=[Dimensions__Size(val=size), Classification__Uncertainties(val=pmf)])

    car_pmf = (0, 0, 0, 0.9, 0, 0, 0, 0, 0, 0, 0, 0, 0.1)
    truck_pmf = (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.0, 0)
    objects = {"0": Car(name="car-a", object_data=static((4.5, 1.8, 1.5), car_pmf)),
               "1": Truck(name="truck-b", object_data=static((12.0, 2.5, 3.5), truck_pmf))}
    frames = {}
    for k in range(5):
        objs = {}
        for uid, cls, x, v, lane, t_ in (("0", CarInFrame, 50.0, 30.0, "-2", -5.25),
                                         ("1", TruckInFrame, 20.0, 20.0, "-1", -1.75)):
            xx = x + v * 0.1 * k
            objs[uid] = cls(object_data=ObjectInFrameData__NoRider(
                boolean=[Interior__AutomatedControl__Longitudinal(val=True),
                         Interior__AutomatedControl__Lateral(val=False), Lights__Brake(val=k == 4)],
                cuboid=[BoundingBox(val=(xx, t_, 0.75, 0, 0, 0.0, 4.5, 1.8, 1.5))],
                num=[Road__NumberLanes__Left__Legal(val=0), Road__NumberLanes__Left__Physical(val=0),
                     Road__NumberLanes__Right__Legal(val=3), Road__NumberLanes__Right__Physical(val=3),
                     OpenDrive__LanePosition(val=0.0)],
                text=[OpenDrive__RoadId(val="1"), OpenDrive__LaneId(val=lane),
                      Road__Classification(val=Road__ClassificationValue.STRAIGHT)],
                vec=[Velocity(val=(v, 0, 0, 0, 0, 0)), Acceleration(val=(0, 0, 0, 0, 0, 0)),
                     OpenDrive__LocalRoadCoordinates(val=(xx, t_))]))
        frames[str(k)] = Frame(frame_properties=FrameProperties(timestamp=k * 0.1), objects=objs)
    env = EnvironmentContext(context_data=EnvironmentContextData(
        num=[Environment__Temperature(val=12)],
        text=[Environment__LightingConditions(val=Environment__LightingConditionsValue.DAY)], vec=[]))
    ev = Event(name="lane change0", type=EventTypeValue.LANE_CHANGE,
               frame_intervals=[FrameInterval(frame_start=2, frame_end=2)],
               event_data=EventData(text=[RoleAParticipantID(val="0")], vec=[RoleBParticipantIDs(val=[])]))
    ol = AveasOpenLabel(
        metadata=Metadata(right_of_use=RightOfUse.RESEARCH_ONLY, acquisition_method=AcquisitionMethod.IN_VEHICLE,
                          acquisition_partner="partner institute", acquisition_date="2024-03-01T10:00:00.250+01:00",
                          opendrive="straight.xodr", projection_string=SITE, threshold_gttc=1.0,
                          threshold_pret=1.0, threshold_thw=3.0),
        objects=objects, frames=frames, contexts={"0": env}, events={"0": ev})
    path = tmp_path / "partner.json"
    path.write_text(json.dumps(ol.to_dict(exclude_none=True)))
    shutil.copy(STRAIGHT, tmp_path / "straight.xodr")
    return path


def test_aveas_openlabel_generated_file(tmp_path, openlabel_schema):
    from aveas_openlabel import AveasOpenLabel

    path = _aveas_generated(tmp_path)
    raw = path.read_text()
    assert "Road__ClassificationValue.STRAIGHT" in raw and "used_road_link" in raw  # the quirks
    rec = convert("openlabel", [path])
    assert aveas_format.validate(rec).counts["error"] == 0
    m = rec.meta
    assert m.acquisition.method.value == "road_vehicle" and m.acquisition.partner == "partner institute"
    assert m.start_time == "2024-03-01T09:00:00.250Z"
    assert m.thresholds.thw_s == 3.0 and m.conditions.temperature_c == 12.0
    assert m.conditions.lighting.day == 1.0
    p = rec.participants
    assert p.column("class").to_pylist() == ["car", "truck"]
    assert p.column("source_id").to_pylist() == ["car-a", "truck-b"]
    s = rec.states
    assert s.num_rows == 10
    assert s.column("lane_id").to_pylist() == [-2] * 5 + [-1] * 5
    assert s.column("road_id").to_pylist() == ["1"] * 10
    assert np.allclose(s.column("vx").to_numpy(), [30.0] * 5 + [20.0] * 5)
    assert np.allclose(s.column("x").to_numpy()[:5], 50 + 3.0 * np.arange(5))
    assert s.column("light_brake_p").to_pylist() == [0, 0, 0, 0, 1] * 2
    it = rec.interior
    assert it.column("automation_longitudinal_p").to_pylist() == [1.0] * 10
    assert it.column("automation_lateral_p").to_pylist() == [0.0] * 10  # second "longitudinal"
    ev = rec.events.to_pylist()
    assert ev[0]["kind"] == "lane_change" and ev[0]["time_start"] == pytest.approx(0.2)
    # -> OpenLABEL again: valid, and aveas-openlabel loads it
    out = tmp_path / "again.json"
    get_converter("openlabel", "export")(rec, out)
    doc = json.loads(out.read_text())
    jsonschema.validate(doc, openlabel_schema)
    again = AveasOpenLabel.from_dict(doc)
    assert set(again.objects) == {"0", "1"} and len(again.frames) == 5
    assert doc["openlabel"]["metadata"]["acquisition_method"] == "in-vehicle"


def test_minimum_example_with_map(tmp_path, openlabel_data):
    from aveas_openlabel import AveasOpenLabel

    rec = convert("openlabel", [openlabel_data / "aveas__minimum_openlabel_example.json"],
                  map_source=STRAIGHT)
    assert rec.participants.num_rows == 0 and rec.states.num_rows == 0
    assert rec.meta.acquisition.partner == "understand.ai"
    assert rec.meta.crs.startswith("+proj=tmerc")  # "dummy projection string" -> the map's
    out = tmp_path / "min.json"
    get_converter("openlabel", "export")(rec, out)
    AveasOpenLabel.from_dict(json.loads(out.read_text()))


def test_static_cuboids_without_frames_are_a_clear_error(openlabel_data):
    """VCD's test file labels two cars with cuboids in object_data and no frames: no time, so no
    trajectory; the error says why."""
    with pytest.raises(aveas_format.FormatError, match=r"2 object\(s\) carry a static cuboid"):
        convert("openlabel", [openlabel_data / "vcd__openlabel100_test_cuboids.json"],
                map_source=STRAIGHT)


def test_minimum_example_without_map_is_a_clear_error(openlabel_data):
    with pytest.raises(aveas_format.FormatError, match="no map: pass --map"):
        convert("openlabel", [openlabel_data / "aveas__minimum_openlabel_example.json"])


def test_generic_asam_cuboids_with_utm_transforms(tmp_path, openlabel_data):
    """ASAM spec example 7.13.1: cuboids in vehicle-iso8855, per-frame odometry to UTM 30T."""
    import pyproj

    src = openlabel_data / "asam_spec__openlabel100_example_cuboids.json"
    doc = json.loads(src.read_text())["openlabel"]
    f0 = doc["frames"]["538"]["frame_properties"]["transforms"]["vehicle-iso8855_to_utm-30t"]
    q = f0["transform_src_to_dst"]["quaternion"]
    tx, ty = f0["transform_src_to_dst"]["translation"][:2]
    yaw = 2 * math.atan2(q[2], q[3])
    lon, lat = pyproj.Transformer.from_crs("EPSG:32630", "EPSG:4326", always_xy=True).transform(tx, ty)
    geo = f"+proj=tmerc +lat_0={lat} +lon_0={lon} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
    xodr = straight_highway(length=400.0, lanes_right=3, lanes_left=3, x0=-100 * math.cos(yaw),
                            y0=-100 * math.sin(yaw), hdg=yaw, geo_reference=geo)
    with pytest.warns(UserWarning, match="repeat a"):
        rec = convert("openlabel", [src], map_source=xodr.encode())
    report = aveas_format.validate(rec)
    # real detections: plausibility findings (kinematics.*) are the data's, not the importer's
    structural = [r.code for r in report.results if r.count and r.severity.value == "error"
                  and not r.code.startswith("kinematics.")]
    assert structural == []
    p = rec.participants
    assert p.num_rows == 8
    ego = p.filter(np.asarray(p.column("role").to_pylist()) == "recording_vehicle")
    assert ego.num_rows == 1 and ego.column("source_id").to_pylist() == ["2"]
    s = rec.states
    assert rec.meta.start_time.startswith("2020-12-18T")
    assert s.column("time").to_numpy().min() == 0.0
    e = s.filter(pc.equal(s.column("participant_id"), ego.column("participant_id")[0]))
    # the ego's box centre is 0.15 m ahead of its odometry origin: near (0, 0) of the map at t = 0
    assert math.hypot(e.column("x")[0].as_py(), e.column("y")[0].as_py()) < 0.5
    # heading = odometry yaw (the map road's direction) + the box's own yaw in the vehicle frame
    # (the example's boxes point backwards: quaternion z = -0.9996, w = 0.028)
    h = e.column("heading").to_numpy()
    assert abs(math.remainder(h[0] - (yaw + 2 * math.atan2(-0.9996073, 0.0280223)), 2 * math.pi)) < 0.05
    # ... and the ego moves along the odometry's yaw, i.e. along the map road
    d = np.diff(np.c_[e.column("x").to_numpy(), e.column("y").to_numpy()][:15], axis=0).sum(0)
    assert abs(math.remainder(math.atan2(d[1], d[0]) - yaw, 2 * math.pi)) < 0.2
    assert np.hypot(*d) > 5
    assert s.column("road_id").null_count < s.num_rows  # referenced through the map


def test_cli_export_and_convert(rich, tmp_path):
    rec_path = rich.write(tmp_path / "rich.aveas")
    out = tmp_path / "out" / "rich.json"
    out.parent.mkdir()
    res = subprocess.run([sys.executable, "-m", "aveas_format", "export", "--to", "openlabel",
                          str(rec_path), "-o", str(out)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert out.is_file() and (out.parent / "rich.xodr").is_file()
    back = tmp_path / "back.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "openlabel",
                          str(out), "-o", str(back)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr + res.stdout
    assert_recordings_equal(rich, aveas_format.open(back))


def test_poses_and_utm_names(openlabel_data):
    """The VCD pose example gives one camera as a matrix and its twin as Euler angles."""
    from aveas_format.converters.common.coordinate_systems import pose, utm_crs

    cs = json.loads((openlabel_data / "vcd__openlabel100_test_poses.json").read_text())
    cs = cs["openlabel"]["coordinate_systems"]
    a, b = pose(cs["CAM_1"]["pose_wrt_parent"]), pose(cs["CAM_2"]["pose_wrt_parent"])
    assert np.allclose(a, b)
    assert utm_crs("utm-30t") == "EPSG:32630"
    assert utm_crs("UTM32N") == "EPSG:32632"
    assert utm_crs("utm-56h") == "EPSG:32756"
    assert utm_crs("vehicle-iso8855") is None


@pytest.mark.parametrize("tf", [{"matrix4x4": [1.0] * 17}, {"quaternion": [0, 0, 1]}, {"euler_angles": "ab"},
                                {"matrix4x4": [float("nan")] * 16}, "identity"])
def test_an_unreadable_pose_is_a_located_error(tf):
    """A pose that is no 4x4 matrix (a number too many after a flipped byte, a short quaternion,
    NaN): a FormatError naming the coordinate system, not a traceback (found by the fuzz tests)."""
    from aveas_format.converters.common.coordinate_systems import CoordinateSystems
    from aveas_format.errors import FormatError

    with pytest.raises(FormatError, match="pose_wrt_parent of coordinate system lidar"):
        CoordinateSystems({"lidar": {"type": "sensor_cs", "parent": "odom", "pose_wrt_parent": tf}})


def _crossing_scene():
    """Two cars along a lane and a third crossing it: all four derived tables, one PET below the
    threshold and one undefined (null) PET."""
    from aveas_format.mapref.build import build_recording
    from aveas_format.sample import SITE_CRS

    t = np.arange(61) * 0.1
    actors = [(10.0, -5.25, 10.0, 0.0, 4.5, 1.8), (-5.0, -5.25, 10.0, 0.0, 4.5, 1.8),
              (30.0, -40.0, 0.0, 10.0, 4.0, 2.0)]
    cols: dict[str, list] = {k: [] for k in ("participant_id", "time", "x", "y", "heading", "vx", "vy")}
    for i, (x, y, vx, vy, _, _) in enumerate(actors):
        cols["participant_id"].append(np.full(len(t), i))
        cols["time"].append(t)
        cols["x"].append(x + vx * t)
        cols["y"].append(y + vy * t)
        cols["heading"].append(np.full(len(t), math.atan2(vy, vx)))
        cols["vx"].append(np.full(len(t), vx))
        cols["vy"].append(np.full(len(t), vy))
    states = {k: np.concatenate(v) for k, v in cols.items()}
    n = len(states["time"])
    for k in ("x_std", "y_std", "vx_std", "vy_std"):
        states[k] = np.full(n, 0.1)
    states["heading_std"] = np.full(n, 0.01)
    parts = {"participant_id": np.arange(3), "class": ["car"] * 3,
             "length": np.array([a[4] for a in actors]), "width": np.array([a[5] for a in actors]),
             "length_std": np.full(3, 0.05), "width_std": np.full(3, 0.05)}
    xodr = straight_highway(length=200.0, lanes_right=3, x0=-50.0, geo_reference=SITE_CRS)
    return build_recording(map_source=xodr, participants=parts, states=states, method="aerial",
                           partner="test")


@pytest.mark.parametrize("scene", ["highway", "crossing"])
def test_derived_tables_round_trip(scene, tmp_path, openlabel_schema):
    """recording -> OpenLABEL -> recording keeps every derived table (PET included), its
    recording.json ``derived`` entry and its provenance, so nothing is reported stale."""
    from aveas_openlabel import AveasOpenLabel

    from aveas_format.derive import DERIVED_KEY, derive, stale_derived
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=8, duration_s=4.0) if scene == "highway" else _crossing_scene()
    derive(rec)
    assert set(rec.derived) == {"kinematics", "interactions", "encroachments", "traffic",
                                "conflicts", "criticality_summary"}
    assert stale_derived(rec) == []
    paths = _export(rec, tmp_path)
    doc = json.loads(paths[0].read_text())
    jsonschema.validate(doc, openlabel_schema)
    AveasOpenLabel.from_dict(doc)
    carried = doc["openlabel"]["metadata"]["aveas_format"]["derived"]
    assert set(carried) == set(rec.derived)
    assert all(isinstance(v, list) for t in carried.values() for v in t["columns"].values())  # columnar
    back = convert("openlabel", [paths[0]])
    assert_recordings_equal(rec, back)
    assert set(back.derived) == set(rec.derived)
    for name, table in rec.derived.items():
        assert_tables_equal(table, back.derived[name], f"derived/{name}")
        assert back.derived[name].schema.metadata[DERIVED_KEY] == table.schema.metadata[DERIVED_KEY]
    dump = [e.model_dump(mode="json") for e in rec.meta.derived]
    assert [e.model_dump(mode="json") for e in back.meta.derived] == dump
    assert back.events.schema.metadata[DERIVED_KEY] == rec.events.schema.metadata[DERIVED_KEY]
    # the states come back bit for bit: the recorded input hashes still match
    assert stale_derived(back) == []
    assert aveas_format.validate(back).counts["error"] == 0
    if scene == "crossing":
        pet = back.derived["encroachments"].column("pet").to_pylist()
        assert pet[0] == pytest.approx(0.86) and pet[1] is None
        prets = [x["val"] for f in doc["openlabel"]["frames"].values() for o in f["objects"].values()
                 for x in o["object_data"]["vec"] if x["name"] == "impact/pret/values"]
        assert prets == [[pytest.approx(0.86)]]
    # written and opened again: still fresh
    back.write(tmp_path / "back.aveas")
    assert stale_derived(aveas_format.open(tmp_path / "back.aveas")) == []


def test_table_json_keeps_nonfinite_values():
    import pyarrow as pa

    from aveas_format.converters.openlabel import table_from_json, table_to_json

    t = pa.table({"participant_id": [0, 0, 1, 1], "time": [0.0, 0.1, 0.0, 0.1],
                  "other_id": [1, 1, 0, 0], "relation": ["leader"] * 4,
                  "ttc": [1.5, math.nan, math.inf, None], "thw": [-math.inf, 0.5, None, 1.0]})
    obj = json.loads(json.dumps(table_to_json(t), allow_nan=False))
    back = table_from_json(obj, "derived/interactions")
    assert back.column("ttc").null_count == 1 and back.column("thw").null_count == 1
    ttc = back.column("ttc").to_pylist()
    assert ttc[0] == 1.5 and math.isnan(ttc[1]) and ttc[2] == math.inf and ttc[3] is None
    assert back.column("thw").to_pylist()[0] == -math.inf
