"""ASAM OSI traces (.osi and MCAP) -> recording, from GroundTruth messages made from an analytic
truth with the betterosi bindings."""

from __future__ import annotations

import json
import math
import struct
import warnings

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.opendrive.builder import straight_highway

b = pytest.importorskip("betterosi")

GEO = "+proj=tmerc +lat_0=49.0 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
DT = 0.05


@pytest.fixture(scope="module")
def road(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "road.xodr"
    p.write_text(straight_highway(length=600.0, lanes_right=2, lanes_left=1, geo_reference=GEO))
    return p


def truth(n: int = 60):
    t = 100.0 + np.arange(n) * DT   # simulation time does not start at 0
    s = t - t[0]
    ego = dict(id=1, x=20 + 30 * s + 0.5 * 2 * s ** 2, y=np.full(n, -1.75), yaw=np.zeros(n),
               vx=30 + 2 * s, vy=np.zeros(n), ax=np.full(n, 2.0), L=4.8, W=1.9, H=1.5,
               vtype="MEDIUM_CAR", lane=11)
    truck = dict(id=2, x=300 - 20 * s, y=np.full(n, 1.75), yaw=np.full(n, math.pi),
                 vx=np.full(n, -20.0), vy=np.zeros(n), ax=np.zeros(n), L=16.5, W=2.55, H=4.0,
                 vtype="HEAVY_TRUCK", lane=21)
    ped = dict(id=3, x=np.full(n, 100.0), y=-9 + 1.2 * s, yaw=np.full(n, math.pi / 2),
               vx=np.zeros(n), vy=np.full(n, 1.2), ax=np.zeros(n), L=0.5, W=0.6, H=1.8,
               vtype=None, lane=None)
    return t, [ego, truck, ped]


def messages(t, objs, sensor_view: bool = False):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for i, ti in enumerate(t):
            mos = []
            for o in objs:
                kw = {}
                if o["vtype"]:
                    ind = "RIGHT" if (o["id"] == 1 and i < 10) else "OFF"
                    brake = b.MovingObjectVehicleClassificationLightStateBrakeLightState.OFF
                    kw["vehicle_classification"] = b.MovingObjectVehicleClassification(
                        type=getattr(b.MovingObjectVehicleClassificationType, o["vtype"]),
                        light_state=b.MovingObjectVehicleClassificationLightState(
                            indicator_state=getattr(
                                b.MovingObjectVehicleClassificationLightStateIndicatorState, ind),
                            brake_light_state=brake))
                    kw["type"] = b.MovingObjectType.VEHICLE
                else:
                    kw["type"] = b.MovingObjectType.PEDESTRIAN
                if o["lane"]:
                    kw["assigned_lane_id"] = [b.Identifier(value=o["lane"])]
                mos.append(b.MovingObject(
                    id=b.Identifier(value=o["id"]),
                    base=b.BaseMoving(
                        dimension=b.Dimension3d(length=o["L"], width=o["W"], height=o["H"]),
                        position=b.Vector3d(x=float(o["x"][i]), y=float(o["y"][i]), z=o["H"] / 2),
                        orientation=b.Orientation3d(yaw=float(o["yaw"][i])),
                        velocity=b.Vector3d(x=float(o["vx"][i]), y=float(o["vy"][i]), z=0.0),
                        acceleration=b.Vector3d(x=float(o["ax"][i]), y=0.0, z=0.0)),
                    **kw))
            sec = int(ti)
            gt = b.GroundTruth(timestamp=b.Timestamp(seconds=sec, nanos=int(round((ti - sec) * 1e9))),
                               host_vehicle_id=b.Identifier(value=1), moving_object=mos)
            if sensor_view:
                yield b.SensorView(timestamp=gt.timestamp, host_vehicle_id=gt.host_vehicle_id,
                                   global_ground_truth=gt)
            else:
                yield gt


def write_osi(path, msgs):
    with open(path, "wb") as f:
        for m in msgs:
            data = m.to_binary()
            f.write(struct.pack("<I", len(data)))
            f.write(data)
    return path


def check(rec, t, objs):
    s, p = rec.states, rec.participants
    assert p.column("source_id").to_pylist() == ["1", "2", "3"]
    assert p.column("class").to_pylist() == ["car", "truck", "pedestrian"]
    assert p.column("role").to_pylist() == ["system_under_test", "simulated_agent", "simulated_agent"]
    assert p.column("length").to_pylist() == pytest.approx([4.8, 16.5, 0.5])
    pid = s.column("participant_id").to_numpy()
    for k, o in enumerate(objs):
        m = pid == k
        assert np.allclose(s.column("time").to_numpy()[m], t - t[0], atol=1e-9)
        assert np.allclose(s.column("x").to_numpy()[m], o["x"], atol=1e-9)
        assert np.allclose(s.column("y").to_numpy()[m], o["y"], atol=1e-9)
        dh = np.angle(np.exp(1j * (s.column("heading").to_numpy()[m] - o["yaw"])))
        assert np.abs(dh).max() < 1e-12
        assert np.allclose(s.column("vx").to_numpy()[m], o["vx"])
        assert np.allclose(s.column("ax").to_numpy()[m], o["ax"])
    ind = s.column("light_indicator_right_p").to_numpy()
    assert ind[pid == 0][:10].tolist() == [1.0] * 10 and ind[pid == 0][10] == 0.0
    lane = np.asarray(s.column("lane_id").to_pylist())
    assert (lane[pid == 0] == -1).all() and (lane[pid == 1] == 1).all()
    attrs = [json.loads(a) for a in p.column("attributes").to_pylist()]
    assert attrs[0]["osi_lanes"] == [11] and attrs[2]["osi_type"] == "PEDESTRIAN"
    assert rec.meta.provenance.value == "simulated"
    assert rec.meta.nominal_rate_hz == pytest.approx(1 / DT)


def test_registered():
    assert "osi" in load_converters()


def test_binary_osi_ground_truth(tmp_path, road):
    t, objs = truth()
    trace = write_osi(tmp_path / "run_gt.osi", messages(t, objs))
    rec = convert("osi", [trace], map_source=road)
    check(rec, t, objs)
    report = aveas_format.validate(rec.write(tmp_path / "osi.aveas"))
    assert report.counts["error"] == 0, report


def test_samples_in_blocks_give_the_same_recording(tmp_path, road, monkeypatch):
    """The import turns its samples into float blocks as it goes (bounded memory): any block
    size gives the same states."""
    from aveas_format.converters import osi

    t, objs = truth()
    trace = write_osi(tmp_path / "run_gt.osi", messages(t, objs))
    whole = convert("osi", [trace], map_source=road).states
    monkeypatch.setattr(osi, "_BLOCK", 3)
    assert convert("osi", [trace], map_source=road).states.equals(whole)


def test_binary_osi_sensor_view(tmp_path, road):
    t, objs = truth(20)
    trace = write_osi(tmp_path / "trace.osi", messages(t, objs, sensor_view=True))
    rec = convert("osi", [trace], map_source=road, options={"message_type": "SensorView"})
    assert rec.states.num_rows == 60


def test_mcap_trace(tmp_path, road):
    t, objs = truth()
    path = tmp_path / "run.mcap"
    with b.Writer(path, topic="ground_truth",
                  metadata={"zero_time": "2024-05-01T10:00:00Z", "description": "test"}) as w:
        for m in messages(t, objs):
            w.add(m)
    rec = convert("osi", [path], map_source=road)
    check(rec, t, objs)
    assert rec.meta.start_time.startswith("2024-05-01T10:01:40")


def test_truncated_trace_is_located(tmp_path, road):
    t, objs = truth(5)
    trace = write_osi(tmp_path / "cut_gt.osi", messages(t, objs))
    data = trace.read_bytes()
    trace.write_bytes(data[:-7])
    with pytest.raises(aveas_format.FormatError, match=r"cut_gt.osi: message 4 at byte \d+ declares"):
        convert("osi", [trace], map_source=road)
    trace.write_bytes(b"")
    with pytest.raises(aveas_format.FormatError, match="empty OSI trace"):
        convert("osi", [trace], map_source=road)
    junk = tmp_path / "junk_gt.osi"
    junk.write_bytes(struct.pack("<I", 6) + b"\xff\xff\xff\xff\xff\xff")
    with pytest.raises(aveas_format.FormatError, match=r"junk_gt.osi: cannot decode OSI message 0"):
        convert("osi", [junk], map_source=road)


# ---- export ------------------------------------------------------------------------------------

def _lit_recording():
    """The sample scene with brake and indicator light probabilities and a host vehicle."""
    import pyarrow as pa

    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=12, duration_s=6.0, seed=4)
    st = rec.states
    n = st.num_rows
    pid = st["participant_id"].to_numpy()
    brake = np.where(pid == 2, 0.9, 0.1).astype(np.float32)
    left = np.where(pid == 3, 0.8, 0.0).astype(np.float32)
    for name, v in (("light_brake_p", brake), ("light_indicator_left_p", left),
                    ("light_indicator_right_p", np.zeros(n, np.float32)),
                    ("light_hazard_p", np.zeros(n, np.float32))):
        st = st.append_column(name, pa.array(v))
    parts = rec.participants
    roles = parts["role"].to_pylist()
    roles[1] = "system_under_test"
    parts = parts.set_column(parts.schema.get_field_index("role"), "role",
                             pa.array(roles, parts.schema.field("role").type))
    rec.replace_tables({"states": st, "participants": parts})
    return rec


@pytest.mark.parametrize("suffix", [".osi", ".mcap"])
def test_export_round_trip(tmp_path, suffix):
    """Recording -> OSI trace -> recording: positions, heading, velocities, sizes, classes, lights,
    the host vehicle and (MCAP) the start time come back."""
    from aveas_format.converters import get_converter

    rec = _lit_recording()
    (tmp_path / "map.xodr").write_bytes(rec.map_source)
    out = tmp_path / f"trace{suffix}"
    # the map is written next to the trace (issue 18): what the re-import needs
    assert get_converter("osi", "export")(rec, out) == [out, tmp_path / "trace.xodr"]
    assert (tmp_path / "trace.xodr").read_bytes() == rec.map_source  # it has a geoReference
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["map.xodr", out.name, "trace.xodr"])  # no temp left
    back = convert("osi", [out], map_source=tmp_path / "map.xodr")
    a, c = rec.states, back.states
    assert c.num_rows == a.num_rows
    for k in ("x", "y", "vx", "vy", "heading"):
        np.testing.assert_allclose(c[k].to_numpy(), a[k].to_numpy(), atol=1e-9, err_msg=k)
    np.testing.assert_allclose(c["time"].to_numpy(), a["time"].to_numpy() - a["time"].to_numpy().min(),
                               atol=1e-9)
    assert back.participants["class"].to_pylist() == rec.participants["class"].to_pylist()
    np.testing.assert_allclose(back.participants["length"].to_numpy(), rec.participants["length"].to_numpy())
    assert back.participants["role"].to_pylist()[1] == "system_under_test"
    assert back.participants["role"].to_pylist().count("system_under_test") == 1
    pid = c["participant_id"].to_numpy()
    brake = c["light_brake_p"].to_numpy(zero_copy_only=False)
    assert (brake[pid == 2] == 1.0).all() and (brake[pid != 2] == 0.0).all()
    left = c["light_indicator_left_p"].to_numpy(zero_copy_only=False)
    assert (left[pid == 3] == 1.0).all() and (left[pid != 3] == 0.0).all()
    if suffix == ".mcap":
        assert back.meta.start_time.startswith(rec.meta.start_time.rstrip("Z"))
    assert aveas_format.validate(back).exit_code("error") == 0


def test_export_every_and_errors(tmp_path):
    from aveas_format.converters import get_converter
    from aveas_format.errors import FormatError

    rec = _lit_recording()
    export = get_converter("osi", "export")
    export(rec, tmp_path / "half.osi", options={"every": 2})
    n_times = len(np.unique(rec.states["time"].to_numpy()))
    from aveas_format.converters.osi import check_osi_framing

    assert check_osi_framing(tmp_path / "half.osi") == (n_times + 1) // 2
    with pytest.raises(FormatError, match=r"\.osi or \.mcap"):
        export(rec, tmp_path / "trace.bin")
    with pytest.raises(FormatError, match="host_id 999"):
        export(rec, tmp_path / "x.osi", options={"host_id": 999})


def test_export_cli(tmp_path):
    from aveas_format.cli import main
    from aveas_format.sample import highway_scene

    highway_scene(n_vehicles=5, duration_s=3.0).write(tmp_path / "r.aveas")
    with pytest.raises(SystemExit) as e:
        main(["export", "--to", "osi", str(tmp_path / "r.aveas"), "-o", str(tmp_path / "r.osi")])
    assert e.value.code == 0
    assert (tmp_path / "r.osi").stat().st_size > 1000


def test_export_takes_accelerations_from_derived_kinematics(tmp_path):
    """States without ax/ay: the export writes the smoothed accelerations of derived/kinematics."""
    from aveas_format.converters import get_converter
    from aveas_format.derive import derive
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=6, duration_s=4.0, seed=2)
    assert "ax" not in rec.states.column_names
    derive(rec, only="kinematics")
    (tmp_path / "map.xodr").write_bytes(rec.map_source)
    get_converter("osi", "export")(rec, tmp_path / "k.osi")
    back = convert("osi", [tmp_path / "k.osi"], map_source=tmp_path / "map.xodr")
    np.testing.assert_allclose(back.states["ax"].to_numpy(zero_copy_only=False),
                               rec.derived["kinematics"]["ax"].to_numpy(zero_copy_only=False), atol=1e-9)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_export_bytes_are_the_bindings_encoding(tmp_path):
    """The columnar encoder (converters/_protowire.py) writes, message for message, the bytes the
    bindings write for the same GroundTruth: built here with betterosi from the recording's first
    time step (lights, the host vehicle, a state without acceleration)."""
    from aveas_format.converters import get_converter
    from aveas_format.converters.osi_export import EXPORT_CLASS

    rec = _lit_recording()
    st = rec.states
    ax = st["ax"].to_numpy(zero_copy_only=False).astype(float) if "ax" in st.column_names else None
    out = tmp_path / "t.osi"
    get_converter("osi", "export")(rec, out, options={"write_map": False})
    raw = out.read_bytes()
    (k,) = struct.unpack_from("<I", raw, 0)
    first = raw[4:4 + k]
    t = st["time"].to_numpy()
    rows = np.flatnonzero(t == t.min())
    rows = rows[np.argsort(st["participant_id"].to_numpy()[rows])]
    info = {p["participant_id"]: p for p in rec.participants.to_pylist()}
    S = b.MovingObjectVehicleClassificationLightStateIndicatorState
    mos = []
    for i in rows:
        r = {c: st[c][int(i)].as_py() for c in st.column_names}
        p = info[r["participant_id"]]
        otype, vtype = EXPORT_CLASS[p["class"]]
        h = p["height"] or 1.5
        vc = b.MovingObjectVehicleClassification(
            type=getattr(b.MovingObjectVehicleClassificationType, vtype),
            light_state=b.MovingObjectVehicleClassificationLightState(
                indicator_state=S.LEFT if r["light_indicator_left_p"] >= 0.5 else S.OFF,
                brake_light_state=getattr(b.MovingObjectVehicleClassificationLightStateBrakeLightState,
                                          "NORMAL" if r["light_brake_p"] >= 0.5 else "OFF")))
        base = dict(dimension=b.Dimension3d(length=p["length"], width=p["width"], height=h),
                    position=b.Vector3d(x=r["x"], y=r["y"], z=h / 2),
                    orientation=b.Orientation3d(yaw=r["heading"]),
                    velocity=b.Vector3d(x=r["vx"], y=r["vy"], z=0.0))
        if ax is not None and np.isfinite(ax[i]):
            base["acceleration"] = b.Vector3d(x=r["ax"], y=r["ay"], z=0.0)
        mos.append(b.MovingObject(id=b.Identifier(value=r["participant_id"]),
                                  base=b.BaseMoving(**base), type=getattr(b.MovingObjectType, otype),
                                  vehicle_classification=vc))
    sec, nanos = divmod(round(float(t.min()) * 1e9), 10**9)
    gt = b.GroundTruth(timestamp=b.Timestamp(seconds=sec, nanos=nanos), moving_object=mos,
                       proj_string=rec.meta.crs, host_vehicle_id=b.Identifier(value=1))
    assert first == gt.to_binary()


def test_export_in_batches_writes_the_same_trace(tmp_path, monkeypatch):
    """The export encodes batches of time steps (bounded memory): any batch size, the same bytes."""
    from aveas_format.converters import get_converter, osi_export

    rec = _lit_recording()
    export = get_converter("osi", "export")
    export(rec, tmp_path / "whole.osi", options={"write_map": False})
    monkeypatch.setattr(osi_export, "BATCH_STATES", 7)
    export(rec, tmp_path / "batched.osi", options={"write_map": False})
    assert (tmp_path / "whole.osi").read_bytes() == (tmp_path / "batched.osi").read_bytes()


@pytest.mark.parametrize("suffix", [".osi", ".mcap"])
def test_bounded_import_writes_the_recording_in_memory(tmp_path, suffix, monkeypatch):
    """``convert_to`` (the CLI's convert, validate TRACE) holds the samples in a StatesWriter
    spilled beyond its memory and writes the states a bucket of objects at a time: with a memory
    of 64 kB and buckets of 32 kB (many buckets) the recording is the one ``convert`` makes."""
    from aveas_format.converters import convert_to, get_converter
    from aveas_format.converters.common import assemble
    from aveas_format.io import open_recording, resort
    from aveas_format.sample import highway_scene
    from helpers_converters import assert_written_as_in_memory, count_buckets

    rec = highway_scene(n_vehicles=40, duration_s=20.0, seed=2)
    trace = tmp_path / f"hw{suffix}"
    get_converter("osi", "export")(rec, trace)
    whole = convert("osi", [trace], options={"recording_id": "hw"})
    buckets = count_buckets(monkeypatch)
    monkeypatch.setattr(assemble, "IMPORT_MEMORY", 64 << 10)
    monkeypatch.setattr(resort, "BUCKET_BYTES", 32 << 10)
    _, n, on_road = convert_to("osi", [trace], tmp_path / "b.aveas", options={"recording_id": "hw"})
    assert len(buckets) == 1 and len(buckets[0]) > 10  # (spilled, then made into many buckets)
    assert_written_as_in_memory(tmp_path / "b.aveas", whole, n, on_road)
    back = open_recording(tmp_path / "b.aveas")
    assert aveas_format.validate(back).exit_code("error") == 0


def test_bounded_import_locates_a_repeated_time_as_in_memory(tmp_path, road):
    """A sample repeated at one time: ``convert_to`` names the file, the frame, the object and the
    time as ``convert`` does, and leaves neither an output nor its spill behind."""
    from aveas_format.converters import convert_to
    from aveas_format.errors import FormatError

    t, objs = truth(20)
    t[7] = t[6]
    trace = write_osi(tmp_path / "run_gt.osi", messages(t, objs))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the time going back)
        with pytest.raises(FormatError) as whole:
            convert("osi", [trace], map_source=road)
        with pytest.raises(FormatError) as bounded:
            convert_to("osi", [trace], tmp_path / "out.aveas", map_source=road)
    assert str(bounded.value) == str(whole.value) and "frame 7: participant '1' sampled twice" in str(whole.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run_gt.osi"]
