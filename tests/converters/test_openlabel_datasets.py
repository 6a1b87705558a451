"""OpenLABEL as dataset converters write it: timestamps of any unit, ignore-type and sentinel
objects, labels that are no road users, cuboids in camera frames, per-frame transforms, TUM's
deviations. Small files written here isolate each class of defect; tests/realdata/test_openlabel.py
runs the real files."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.compute as pc
import pytest

import aveas_format
from aveas_format.converters import convert
from aveas_format.converters.common.timestamps import resolve_timestamps
from aveas_format.converters.labels import label_kind

from helpers_common import STRAIGHT_MAP
from helpers_converters import kitti_box, kitti_doc

def write(tmp_path, doc, name="labels.json"):
    p = tmp_path / name
    p.write_text(json.dumps({"openlabel": doc}))
    return p


def by_source(rec, source_id):
    p = rec.participants
    pid = p.filter(pc.equal(p.column("source_id"), source_id)).column("participant_id")[0]
    return rec.states.filter(pc.equal(rec.states.column("participant_id"), pid))


def test_camera_frame_cuboids_sizes_and_ground(tmp_path):
    """Sizes along the camera's axes (y down) come out as length/width/height, boxes stand on the
    ground (z = 0 of the ego's frame), headings follow ry, DontCare never reaches a participant,
    and the ego's static cuboid in vehicle-iso8855 follows the per-frame odometry."""
    src = write(tmp_path, kitti_doc())
    with pytest.warns(UserWarning, match=r"skipped 1 objects: 1 DontCare \(ignore-type label"):
        rec = convert("openlabel", [src], map_source=STRAIGHT_MAP)
    p = {r["source_id"]: r for r in rec.participants.to_pylist()}
    assert set(p) == {"Pedestrian0", "Car1", "Egocar"}
    ped, car, ego = p["Pedestrian0"], p["Car1"], p["Egocar"]
    assert (ped["class"], ped["length"], ped["width"], ped["height"]) == ("pedestrian", 0.8, 0.6, 1.75)
    assert (car["class"], car["length"], car["width"], car["height"]) == ("car", 4.2, 1.7, 1.5)
    assert ego["role"] == "recording_vehicle" and (ego["length"], ego["width"]) == (4.765, 1.82)
    for sid in ("Pedestrian0", "Car1"):
        s = by_source(rec, sid)
        assert np.allclose(s.column("z").to_numpy(), 0.0, atol=1e-9), sid  # on the ground
    s = by_source(rec, "Car1")
    # ry = -pi/2 in the camera frame: the car points along the ego's x axis
    assert np.allclose(s.column("heading").to_numpy(), 0.0, atol=1e-9)
    assert np.allclose(s.column("x").to_numpy(), 20.0 + 1.5 * np.arange(20), atol=1e-9)
    assert np.allclose(s.column("y").to_numpy(), -3.5, atol=1e-9)
    e = by_source(rec, "Egocar")
    assert e.num_rows == 20 and np.allclose(e.column("x").to_numpy(), 1.35 + np.arange(20))
    assert np.allclose(e.column("z").to_numpy(), 0.736 - 1.47 / 2)


def test_timestamps_epoch_microseconds_as_strings(tmp_path):
    """The issue's file: epoch microseconds as strings ended in 'year 53872825 is out of range';
    now the unit is inferred, the start time set, and the choice recorded in the source block."""
    stamps = [str(1_700_000_000_000_000 + 100_000 * k) for k in range(20)]
    with pytest.warns(UserWarning):
        rec = convert("openlabel", [write(tmp_path, kitti_doc(stamps=stamps))], map_source=STRAIGHT_MAP)
    t = np.unique(rec.states.column("time").to_numpy())
    assert np.allclose(t, 0.1 * np.arange(20))
    assert rec.meta.start_time.startswith("2023-11-14T22:13:20")
    opts = rec.meta.source.options
    assert opts["timestamp_unit"] == "us" and "microseconds since the Unix epoch" in opts["timestamps"]


@pytest.mark.parametrize("stamps, unit, epoch, dt", [
    ([1.7e9 + 0.1 * k for k in range(5)], "s", True, 0.1),
    ([1_700_000_000_000 + 100 * k for k in range(5)], "ms", True, 0.1),
    ([str(1_700_000_000_000_000_000 + 33_333_333 * k) for k in range(5)], "ns", True, 0.033333333),
    ([0.05 * k for k in range(5)], "s", False, 0.05),
    ([1000 + 100 * k for k in range(5)], "ms", False, 0.1),  # ms since the start
    ([f"2024-05-01T10:00:0{k}.5+02:00" for k in range(5)], "iso8601", True, 1.0),
])
def test_timestamp_units_inferred(stamps, unit, epoch, dt):
    ts = resolve_timestamps(stamps)
    assert (ts.unit, ts.epoch) == (unit, epoch)
    # exact for integers; epoch seconds as floats carry float64's ~0.2 us
    assert np.allclose(np.diff(ts.seconds), dt, rtol=0, atol=1e-6 if isinstance(stamps[0], float) else 1e-12)
    if unit == "iso8601":
        assert ts.start_time == "2024-05-01T08:00:00.500000000Z"


def test_decimal_epoch_seconds_keep_their_nanoseconds(tmp_path):
    """Epoch seconds written as decimal text with nine digits (a rail dataset's
    ``"1631441453.299504123"``) kept exact: the start time to the nanosecond (a float64 of the
    epoch value is off by up to 119 ns), the frame times exact differences."""
    stamps = [f"1631441453.{299504123 + 100_000_007 * k:09d}" for k in range(7)]
    ts = resolve_timestamps(stamps)
    assert (ts.unit, ts.epoch, ts.start_ns) == ("s", True, 1631441453_299504123)
    assert ts.start_time == "2021-09-12T10:10:53.299504123Z"
    assert np.array_equal(ts.seconds, [k * 0.100000007 for k in range(7)])
    with pytest.warns(UserWarning):
        rec = convert("openlabel", [write(tmp_path, kitti_doc(n=7, stamps=stamps))],
                      map_source=STRAIGHT_MAP)
    assert rec.meta.start_time.startswith("2021-09-12T10:10:53.299504123")


def test_timestamp_unit_option_overrides(tmp_path):
    """1000, 1100, ... read as microseconds since the start when told so (auto: milliseconds)."""
    stamps = [1000 + 100 * k for k in range(20)]
    src = write(tmp_path, kitti_doc(stamps=stamps))
    with pytest.warns(UserWarning):
        rec = convert("openlabel", [src], map_source=STRAIGHT_MAP, options={"timestamp_unit": "us"})
    assert np.allclose(np.unique(rec.states.column("time").to_numpy()), 1e-4 * np.arange(20))
    assert rec.meta.source.options["timestamp_unit"] == "us"
    assert "given" in rec.meta.source.options["timestamps"]
    with pytest.raises(aveas_format.UsageError, match="timestamp_unit"):
        convert("openlabel", [src], map_source=STRAIGHT_MAP, options={"timestamp_unit": "minutes"})


def test_unreadable_timestamps_are_no_internal_error(tmp_path):
    """Texts that are no time, and numbers mixed with ISO texts: a clear error or frame numbers,
    never a traceback."""
    stamps = ["soon"] * 20
    with pytest.warns(UserWarning):
        rec = convert("openlabel", [write(tmp_path, kitti_doc(stamps=stamps))], map_source=STRAIGHT_MAP)
    assert "frame numbers at rate_hz 10" in rec.meta.source.options["timestamps"]
    mixed = ["2024-05-01T10:00:00Z"] + [1.7e9 + k for k in range(1, 20)]
    with pytest.raises(aveas_format.FormatError, match="mix ISO 8601"):
        convert("openlabel", [write(tmp_path, kitti_doc(stamps=mixed), "m.json")], map_source=STRAIGHT_MAP)


def test_sentinel_sizes_never_reach_a_participant(tmp_path):
    """A road user's boxes with sentinel sizes are dropped; an object left without boxes too."""
    doc = kitti_doc(n=5)
    doc["objects"]["7"] = {"name": "Car7", "type": "Car"}
    for k in range(5):
        doc["frames"][str(k)]["objects"]["7"] = {"object_data": {"cuboid": [
            {"name": "box3D", "coordinate_system": "CAM_LEFT", "val": [1, 1, 30, 0, 0, 0, -1, -1, -1]}]}}
    doc["frames"]["2"]["objects"]["1"]["object_data"]["cuboid"][0]["val"][6:9] = [0.0, 1.5, 1.7]
    with pytest.warns(UserWarning) as warned:
        rec = convert("openlabel", [write(tmp_path, doc)], map_source=STRAIGHT_MAP)
    said = [str(w.message) for w in warned]
    assert any("dropped 6 boxes with a sentinel or impossible size" in m for m in said), said
    assert any("skipped 1 objects: 1 DontCare" in m for m in said), said
    p = rec.participants
    assert "Car7" not in p.column("source_id").to_pylist()
    assert (p.column("length").to_numpy() > 0).all() and (p.column("width").to_numpy() > 0).all()
    assert by_source(rec, "Car1").num_rows == 4


def test_non_road_users_skipped_or_kept(tmp_path):
    """nuScenes' barrier and traffic cone are no road users: skipped with a count, or kept with
    keep_non_road_users; a nuScenes vehicle.bus.rigid is a bus."""
    doc = kitti_doc(n=5)
    doc["objects"]["0"]["type"] = "movable_object.barrier"
    doc["objects"]["1"]["type"] = "vehicle.bus.rigid"
    doc["objects"]["-1"]["type"] = "movable_object.trafficcone"
    for k in range(5):  # a cone with a real size this time
        doc["frames"][str(k)]["objects"]["-1"]["object_data"]["cuboid"] = [kitti_box(8, 1, 0, 0, 0.4, 0.7, 0.4)]
    with pytest.warns(UserWarning, match=r"skipped 2 objects: 1 movable_object.barrier, 1 "
                                         r"movable_object.trafficcone \(no road user\); option "
                                         r"keep_non_road_users=true"):
        rec = convert("openlabel", [write(tmp_path, doc)], map_source=STRAIGHT_MAP)
    assert sorted(rec.participants.column("class").to_pylist()) == ["bus", "car"]
    rec = convert("openlabel", [write(tmp_path, doc)], map_source=STRAIGHT_MAP,
                  options={"keep_non_road_users": True})
    assert sorted(rec.participants.column("class").to_pylist()) == ["bus", "car", "other", "other"]
    assert rec.meta.source.options["keep_non_road_users"] is True


def test_tum_deviations_single_cuboid_and_type_in_object_data(tmp_path):
    """TUM Traffic writes ``cuboid`` as one object and ``type`` inside object_data (no top-level
    objects): both read, with the quaternion form and epoch-second timestamps."""
    frames = {}
    for k in range(10):
        frames[str(k)] = {"frame_properties": {"timestamp": 1646667310.044372 + 0.1 * k}, "objects": {
            "a1": {"object_data": {"name": "CAR-1", "type": "CAR", "cuboid": {
                "name": "shape3D", "val": [10.0 + k, -1.75, 0.75, 0, 0, 0, 1, 4.5, 1.9, 1.5]}}},
            "a2": {"object_data": {"name": "PED-2", "type": "PEDESTRIAN", "cuboid": {
                "name": "shape3D", "val": [30.0, 5.0 - 0.1 * k, 0.9, 0, 0, -0.7071068, 0.7071068, 0.6,
                                           0.6, 1.8]}}}}}
    doc = {"metadata": {"schema_version": "1.0.0"}, "frames": frames}
    rec = convert("openlabel", [write(tmp_path, doc)], map_source=STRAIGHT_MAP)
    p = {r["source_id"]: r for r in rec.participants.to_pylist()}
    assert p["a1"]["class"] == "car" and p["a2"]["class"] == "pedestrian"
    assert (p["a2"]["length"], p["a2"]["width"], p["a2"]["height"]) == (0.6, 0.6, 1.8)
    s = by_source(rec, "a2")
    assert np.allclose(s.column("heading").to_numpy(), -math.pi / 2, atol=1e-6)
    assert np.allclose(s.column("z").to_numpy(), 0.0, atol=1e-9)
    assert rec.meta.start_time.startswith("2022-03-07T15:35:10.04")
    assert rec.meta.source.options["timestamp_unit"] == "s"


@pytest.mark.parametrize("label, cls, kind", [
    ("DontCare", "other", "ignore"), ("Person_sitting", "pedestrian", "not_road_user"),
    ("Cyclist", "bicycle", "road_user"), ("human.pedestrian.wheelchair", "mobility_device", "road_user"),
    ("static_object.bicycle_rack", "other", "not_road_user"), ("TYPE_SIGN", "other", "not_road_user"),
    ("VanSUV", "van", "road_user"), ("EMERGENCY_VEHICLE", "car", "road_user"),
    ("storage-tank", "other", "not_road_user"), ("large-vehicle", "truck", "road_user"),
    ("vehicle/car", "car", "road_user"), ("a label nobody knows", "other", "road_user"),
])
def test_label_vocabularies(label, cls, kind):
    assert label_kind(label) == (cls, kind)


def test_cli_shows_the_note_as_one_warning_line(tmp_path):
    import subprocess
    import sys

    src = write(tmp_path, kitti_doc(n=5))
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "openlabel", str(src),
                          "--map", str(STRAIGHT_MAP), "-o", str(tmp_path / "k.aveas"), "--no-validate"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "labels.json: uid -1, json path $.openlabel.objects['-1'].type: OpenLABEL: skipped 1 objects: 1 DontCare" in res.stderr
    assert "UserWarning" not in res.stderr and "wrote " in res.stderr
