"""Comparison helpers and a rich recording for the interoperability tests of the converters
(OpenLABEL, OpenSCENARIO, MCAP export)."""

from __future__ import annotations

import math

import json

import numpy as np
import pyarrow as pa


def _norm(v):
    if isinstance(v, dict):
        return {k: _norm(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_norm(x) for x in v]
    return v


def assert_values_close(a, b, where: str, rtol: float = 1e-9, atol: float = 1e-6) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        assert set(a) == set(b), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            assert_values_close(a[k], b[k], f"{where}.{k}", rtol, atol)
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), f"{where}: length {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            assert_values_close(x, y, f"{where}[{i}]", rtol, atol)
    elif isinstance(a, float) or isinstance(b, float):
        assert a is not None and b is not None, f"{where}: {a!r} != {b!r}"
        if math.isnan(a) and math.isnan(b):
            return
        assert math.isclose(a, b, rel_tol=rtol, abs_tol=atol), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_tables_equal(a: pa.Table | None, b: pa.Table | None, name: str, atol: float = 1e-6) -> None:
    """Same columns, same rows (in order), values equal within float tolerance."""
    if a is None or b is None:
        assert a is None and b is None, f"{name}: one side is missing"
        return
    assert a.column_names == b.column_names, f"{name}: columns {a.column_names} != {b.column_names}"
    assert a.num_rows == b.num_rows, f"{name}: rows {a.num_rows} != {b.num_rows}"
    for c in a.column_names:
        ca, cb = a.column(c), b.column(c)
        if pa.types.is_dictionary(ca.type):
            ca = ca.cast(ca.type.value_type)
        if pa.types.is_dictionary(cb.type):
            cb = cb.cast(cb.type.value_type)
        if pa.types.is_floating(ca.type) and pa.types.is_floating(cb.type):
            xa = ca.to_numpy(zero_copy_only=False).astype(float)
            xb = cb.to_numpy(zero_copy_only=False).astype(float)
            assert np.array_equal(np.isnan(xa), np.isnan(xb)), f"{name}.{c}: null pattern differs"
            ok = np.isclose(xa, xb, rtol=1e-9, atol=atol, equal_nan=True)
            if c in ("heading",):  # angles: compare on the circle
                ok |= np.isclose(np.abs(np.angle(np.exp(1j * (xa - xb)))), 0, atol=atol)
            assert ok.all(), f"{name}.{c}: max diff {np.nanmax(np.abs(xa - xb))}"
        else:
            assert_values_close(_norm(ca.to_pylist()), _norm(cb.to_pylist()), f"{name}.{c}", atol=atol)


def assert_recordings_equal(a, b, *, ignore_meta=("source", "tables", "derived", "map")) -> None:
    ma = a.meta.model_dump(mode="json", exclude_none=True)
    mb = b.meta.model_dump(mode="json", exclude_none=True)
    for k in ignore_meta:
        ma.pop(k, None)
        mb.pop(k, None)
    assert_values_close(ma, mb, "meta")
    for name in ("participants", "states", "unobserved", "events", "environment", "interior"):
        assert_tables_equal(getattr(a, name), getattr(b, name), name)


def rich_recording(n_vehicles: int = 6, duration_s: float = 3.0):
    """The sample highway scene plus everything the format has and OpenLABEL lacks or keeps:
    lights, accelerations, z, yaw rate, a recording vehicle, a trailer attached to a truck,
    events of profile and non-profile kinds, time-varying environment, interior signals and a
    derived interactions table."""
    from aveas_format.io.writer import prepare_table
    from aveas_format.sample import highway_scene
    from aveas_format.schema.metadata import DerivedEntry
    from aveas_format.schema.tables import TABLES

    rec = highway_scene(n_vehicles=n_vehicles, duration_s=duration_s, rate_hz=10.0)
    s = rec.states
    n = s.num_rows
    rng = np.random.default_rng(3)
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    s = s.append_column("z", pa.array(np.where(np.arange(n) % 7 == 0, np.nan, rng.normal(0.1, 0.01, n)),
                                      from_pandas=True))
    s = s.append_column("ax", pa.array(rng.normal(0, 0.3, n)))
    s = s.append_column("ay", pa.array(rng.normal(0, 0.1, n)))
    s = s.append_column("ax_std", pa.array(np.full(n, 0.2)))
    s = s.append_column("ay_std", pa.array(np.full(n, 0.25)))
    s = s.append_column("yaw_rate", pa.array(rng.normal(0, 0.01, n)))
    s = s.append_column("vxvy_corr", pa.array(rng.uniform(-0.3, 0.3, n).astype(np.float32)))
    s = s.append_column("light_brake_p", pa.array(rng.uniform(0, 1, n).astype(np.float32)))
    s = s.append_column("light_indicator_left_p", pa.array(
        np.where(np.arange(n) % 3 == 0, None, rng.uniform(0, 1, n).astype(np.float32)).tolist(),
        pa.float32()))
    s = s.append_column("visible_fraction", pa.array(rng.uniform(0.5, 1, n).astype(np.float32)))
    p = rec.participants
    m = p.num_rows
    first = int(pid.min())
    roles = ["recording_vehicle" if q == first else "observed" for q in p.column("participant_id").to_pylist()]
    p = p.set_column(p.column_names.index("role"), "role", pa.array(roles))
    p = p.append_column("attached_to", pa.array([None] * (m - 1) + [first], pa.int64()))
    p = p.append_column("attributes", pa.array([json.dumps({"axles": 2 + i % 2}) for i in range(m)]))
    ids = sorted(set(pid.tolist()))
    events = {
        "event_id": [0, 1, 2], "kind": ["lane_change", "near_miss", "following"],
        "time_start": [0.5, 1.0, 0.0], "time_end": [0.5, 1.4, 2.0],
        "participant_ids": [[ids[0]], [ids[0], ids[1]], [ids[1], ids[0]]],
        "roles": [["actor"], ["first", "second"], ["follower", "leader"]],
        "confidence": pa.array([0.9, 0.6, 1.0], pa.float32()), "origin": ["annotated", "derived", "annotated"],
        "attributes": [None, json.dumps({"metric": "ttc", "threshold": 3.0}), None],
    }
    environment = {
        "time_start": [0.0, 1.5], "time_end": [1.5, t.max()],
        "lighting": pa.array([{"day": 0.8, "twilight": 0.2, "darkness_lit": 0.0, "darkness_unlit": 0.0},
                              {"day": 1.0, "twilight": 0.0, "darkness_lit": 0.0, "darkness_unlit": 0.0}]),
        "temperature_c": [14.3, 14.6], "wind_speed_m_s": [3.0, 4.2],
    }
    ego = pid == ids[0]
    interior = {
        "participant_id": pid[ego], "time": t[ego],
        "steering_angle": rng.normal(0, 0.01, ego.sum()), "steering_angle_std": np.full(ego.sum(), 0.002),
        "brake_pedal": rng.uniform(0, 0.2, ego.sum()), "gear": pa.array(np.full(ego.sum(), 5), pa.int8()),
        "automation_longitudinal_p": pa.array(np.full(ego.sum(), 0.9), pa.float32()),
        "automation_lateral_p": pa.array(np.full(ego.sum(), 0.1), pa.float32()),
    }
    rec.replace_tables({
        "states": prepare_table(s, TABLES["states"]), "participants": prepare_table(p, TABLES["participants"]),
        "events": prepare_table(pa.table(events), TABLES["events"]),
        "environment": prepare_table(pa.table(environment), TABLES["environment"]),
        "interior": prepare_table(pa.table(interior), TABLES["interior"]),
    })
    # a derived interactions table: participant 1 follows 0 closely at every common time
    both = np.intersect1d(t[pid == ids[0]], t[pid == ids[1]])
    rec.derived["interactions"] = prepare_table(pa.table({
        "participant_id": np.full(len(both), ids[1], np.int64), "time": both,
        "other_id": np.full(len(both), ids[0], np.int64), "relation": ["leader"] * len(both),
        "ttc": np.linspace(5.0, 1.0, len(both)), "thw": np.full(len(both), 0.8)}),
        TABLES["derived/interactions"])
    # documented in recording.json `derived` as `derive` would, so the recording is valid
    rec.meta.derived = [DerivedEntry(table="derived/interactions", method="hand_made", version="0",
                                     parameters={"scene": "rich"}, created="2024-05-13T08:15:00Z")]
    return rec


def _tables(rec) -> dict:
    out = {name: getattr(rec, name) for name in ("participants", "states", "events", "unobserved",
                                                 "environment", "interior")}
    out.update({f"derived/{k}": v for k, v in rec.derived.items()})
    return out


def assert_identical(a, b) -> None:
    """Two recordings with the same tables (schemas and values) and metadata."""
    ta, tb = _tables(a), _tables(b)
    assert ta.keys() == tb.keys()
    for name, t in ta.items():
        u = tb[name]
        if t is None or u is None:
            assert t is None and u is None, name
            continue
        assert t.schema.equals(u.schema), name
        assert t.equals(u), name
    # (a generic file has no recording id: each import draws one)
    assert a.meta.model_dump(exclude={"recording_id"}) == b.meta.model_dump(exclude={"recording_id"})
    assert a.map_source == b.map_source


# -- OpenLABEL as KITTI / VCD write it ------------------------------------------------------------

# KITTI's rectified left camera, 1.65 m above the ground, looking along the vehicle's x axis:
# camera x = -vehicle y, camera y = -vehicle z, camera z = vehicle x
CAM = [0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.65, 0.0, 0.0, 0.0, 1.0]
CS = {"odom": {"type": "scene_cs", "parent": "", "children": ["vehicle-iso8855"]},
      "vehicle-iso8855": {"type": "local_cs", "parent": "odom", "children": ["CAM_LEFT"]},
      "CAM_LEFT": {"type": "sensor_cs", "parent": "vehicle-iso8855", "children": [],
                   "pose_wrt_parent": {"matrix4x4": CAM}}}


def kitti_box(x_fwd, y_left, ground_z, ry, length, height, width):
    """A KITTI-style cuboid (VCD's OpenLABEL form): the box centre in CAM_LEFT, rotation ry about
    the camera's y axis, sizes along the camera axes (x: length, y: height, z: width)."""
    centre_cam = [-y_left, 1.65 - (ground_z + height / 2), x_fwd]
    return {"name": "box3D", "coordinate_system": "CAM_LEFT",
            "val": [*centre_cam, 0, ry, 0, length, height, width]}


def kitti_doc(n=20, stamps=None, ego_step=1.0):
    """A pedestrian walking across 10 m ahead, a car driving ahead, KITTI's DontCare with sentinel
    sizes, and the ego car as a static cuboid in vehicle-iso8855 moved by per-frame odometry."""
    objects = {"0": {"name": "Pedestrian0", "type": "Pedestrian"}, "1": {"name": "Car1", "type": "Car"},
               "-1": {"name": "DontCare", "type": "DontCare"},
               "-2": {"name": "Egocar", "type": "Egocar", "object_data": {"cuboid": [
                   {"name": "box3D", "coordinate_system": "vehicle-iso8855",
                    "val": [1.35, 0.0, 0.736, 0.0, 0.0, 0.0, 4.765, 1.82, 1.47]}]}}}
    frames = {}
    for k in range(n):
        odo = np.eye(4)
        odo[0, 3] = ego_step * k  # the ego drives along x of odom
        fp = {"transforms": {"vehicle-iso8855_to_odom": {
            "src": "vehicle-iso8855", "dst": "odom",
            "transform_src_to_dst": {"matrix4x4": odo.ravel().tolist()}}}}
        if stamps is not None:
            fp["timestamp"] = stamps[k]
        frames[str(k)] = {"frame_properties": fp, "objects": {
            # walking along -y (to the right) at 1 m/frame... of 0.1 s = 1.4 m/s: 0.14 m per frame
            "0": {"object_data": {"cuboid": [kitti_box(10.0, 3.0 - 0.14 * k, 0.0, 0.0, 0.8, 1.75, 0.6)]}},
            "1": {"object_data": {"cuboid": [kitti_box(20.0 + 0.5 * k, -3.5, 0.0, -math.pi / 2, 4.2, 1.5,
                                                       1.7)]}},
            "-1": {"object_data": {"cuboid": [{"name": "box3D", "coordinate_system": "CAM_LEFT",
                                               "val": [-10, 499, -1, 0, -1, 0, -1000, -1000, -1000]}]}}}}
    return {"metadata": {"schema_version": "1.0.0"}, "coordinate_systems": CS, "objects": objects,
            "frames": frames}


def openlabel_blocks(directory, *, n_vehicles: int, duration_s: float, seed: int, size: int) -> list[bytes]:
    """The blocks of frames of a sample highway's OpenLABEL export written into ``directory``, as
    the import cuts them (``size``: the bytes a block is cut at), each ``{...}``."""
    from aveas_format.converters import get_converter
    from aveas_format.converters.openlabel import stream
    from aveas_format.safeio import scan_json_member
    from aveas_format.sample import highway_scene

    path = directory / "rec.json"
    get_converter("openlabel", "export")(highway_scene(n_vehicles=n_vehicles, duration_s=duration_s, seed=seed),
                                         path)
    with open(path, "rb") as f:
        _, span, _ = scan_json_member(f, "openlabel", "frames")
        f.seek(span[0] + 1)
        return [b"{" + cut + b"}" for _, cut in stream._cut_blocks(f, span, size)]


def count_buckets(monkeypatch) -> list:
    """The bucket numbers of each spill a StatesWriter distributes (a list filled as it goes)."""
    from aveas_format.io import resort

    buckets: list = []
    distribute = resort.StatesWriter._distribute

    def counted(self, key_map):
        buckets.append(distribute(self, key_map))
        return buckets[-1]

    monkeypatch.setattr(resort.StatesWriter, "_distribute", counted)
    return buckets


def assert_written_as_in_memory(path, whole, n: int, on_road: int) -> None:
    """The recording an import wrote in bounded memory at ``path`` (``convert_to``'s ``n`` states,
    ``on_road`` of them on the map) is ``whole``, the import in memory: states and participants
    equal, recording.json equal but for the tables' entries and the location (a mean summed bucket
    by bucket: to 1e-12 degrees); no spill left next to it."""
    import pytest

    from aveas_format.io import open_recording

    assert [p.name for p in path.parent.iterdir() if p.name.startswith(".")] == []
    back = open_recording(path)
    assert n == whole.states.num_rows and on_road == n - whole.states["road_id"].null_count
    assert back.states.equals(whole.states) and back.participants.equals(whole.participants)
    a, b = back.meta.model_dump(), whole.meta.model_dump()
    loc_a, loc_b = a.pop("location"), b.pop("location")
    assert a == b | {"tables": a["tables"]} and a["tables"]["states"]["rows"] == n
    assert loc_a.pop("alt") == loc_b.pop("alt") and loc_a == pytest.approx(loc_b, abs=1e-12, rel=0)
