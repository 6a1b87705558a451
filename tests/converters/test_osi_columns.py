"""The OSI import's columnar decoder (converters/osi_columns.py, _protowire.walk) against the
betterosi path it replaces: the same samples, statics, host ids and frame on the real traces, on
messages with every optional part present or absent (made by the bindings), and on wire layouts
the bindings do not write (fields out of order, unknown fields, long varints); what it does not
take goes to betterosi with the same result, and broken bytes give betterosi's located error."""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest

from aveas_format.converters import _protowire as pw
from aveas_format.converters import convert, osi, osi_export
from aveas_format.converters.common.fastpath import FastPathUnsupported
from aveas_format.errors import FormatError
from aveas_format.io.resort import StatesWriter
from aveas_format.opendrive.builder import straight_highway
from helpers_realdata import real_files

b = pytest.importorskip("betterosi")

GEO = "+proj=tmerc +lat_0=49.0 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _write(path, raws):
    with open(path, "wb") as f:
        for data in raws:
            f.write(struct.pack("<I", len(data)) + data)
    return path


def _decoded(decode, path, options):
    """A decoder's samples as one block: ``(floats, object ids, message indices, statics, host
    ids, proj, findings)``."""
    with StatesWriter(memory=None, key="oid") as w:
        static, hosts, proj, found, _ = decode([path], options, osi._Sink(w))
        t = next(w.buckets(), None)
    if t is None:
        return np.zeros((0, len(osi._FLOAT_COLS))), np.zeros(0, np.int64), np.zeros(0, np.int64), \
            static, hosts, proj, found
    f = np.column_stack([t.column(k).to_numpy() for k in osi._FLOAT_COLS])
    return f, t.column("oid").to_numpy(), t.column("msg").to_numpy(), static, hosts, proj, found


def _same_decoding(path, **opts):
    """Both decoders on one trace: everything they give is equal (NaN where NaN)."""
    options = osi.OsiOptions(**opts)
    cols = _decoded(osi._decode_columns, path, options)  # (FastPathUnsupported: not taken)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        objs = _decoded(osi._decode_objects, path, options)
    np.testing.assert_array_equal(cols[0], objs[0])  # floats, NaN at the same places
    assert cols[1].tolist() == list(objs[1]) and cols[2].tolist() == list(objs[2])
    assert cols[3].keys() == objs[3].keys()
    for k, d in cols[3].items():
        e = objs[3][k]
        assert {q: d[q] for q in ("class", "length", "width", "height", "osi_type", "lanes")} == \
            {q: e[q] for q in ("class", "length", "width", "height", "osi_type", "lanes")}
    assert cols[4] == objs[4] and cols[5] == objs[5]
    return cols


def _betterosi_only(monkeypatch):
    def off(*a, **k):
        raise FastPathUnsupported("test: the betterosi path")

    monkeypatch.setattr(osi, "_decode_columns", off)


MAPS = {"alks_cut-in.osi": "straight_500m.xodr", "acc-test.osi": "straight_500m.xodr"}


@pytest.mark.parametrize("path", real_files("real/**/*.osi"))
def test_real_traces_decode_the_same(path, monkeypatch):
    _same_decoding(path)
    name = MAPS.get(path.name)
    if name is None:
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fast = convert("osi", [path], map_source=path.parent / name)
        _betterosi_only(monkeypatch)
        slow = convert("osi", [path], map_source=path.parent / name)
    assert fast.states.equals(slow.states) and fast.participants.equals(slow.participants)
    assert fast.meta.crs == slow.meta.crs


def _random_messages(rng, n_msg=12, sensor_view=False):
    """GroundTruths whose moving objects have each optional part present or not at random (their
    first sample complete: a missing size or type is a finding, made by the betterosi path)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        L = b.MovingObjectVehicleClassificationLightState
        for i in range(n_msg):
            mos = []
            for oid in (7, 300, 2**40 + 5):
                first = i == 0
                r = rng.random(12) < 0.5
                kw = {}
                base = {"dimension": b.Dimension3d(length=4.5, width=1.8,
                                                   **({} if r[0] else {"height": 1.4}))}
                if first or r[1]:
                    base["position"] = b.Vector3d(x=rng.normal() * 1e3, y=-rng.random(),
                                                  **({} if r[2] else {"z": 0.7}))
                if first or r[3]:
                    base["orientation"] = b.Orientation3d(yaw=rng.normal(), roll=0.1)
                if r[4]:
                    base["velocity"] = b.Vector3d(x=rng.normal() * 30)
                if r[5]:
                    base["acceleration"] = b.Vector3d(y=rng.normal())
                if r[6]:
                    base["orientation_rate"] = b.Orientation3d(yaw=rng.normal() * 0.1)
                if oid == 300:
                    kw["type"] = b.MovingObjectType.PEDESTRIAN
                else:
                    kw["type"] = b.MovingObjectType.VEHICLE
                    if first or r[7]:
                        ls = {}
                        if r[8]:
                            ls["indicator_state"] = L.IndicatorState(int(rng.integers(0, 6)))
                        if r[9]:
                            ls["brake_light_state"] = L.BrakeLightState(int(rng.integers(0, 5)))
                        vc = {"type": b.MovingObjectVehicleClassificationType.BUS}
                        if r[10]:
                            vc["light_state"] = L(**ls)
                        kw["vehicle_classification"] = b.MovingObjectVehicleClassification(**vc)
                if r[11]:
                    kw["assigned_lane_id"] = [b.Identifier(value=int(v))
                                              for v in rng.integers(0, 2**33, 2)]
                mos.append(b.MovingObject(id=b.Identifier(value=oid), base=b.BaseMoving(**base),
                                          **kw))
            gt = b.GroundTruth(
                timestamp=b.Timestamp(seconds=1000 + i, nanos=int(rng.integers(0, 10**9))),
                moving_object=mos, **({"host_vehicle_id": b.Identifier(value=7)} if i % 3 else {}),
                **({"proj_string": GEO, "proj_frame_offset": b.GroundTruthProjFrameOffset(
                    position=b.Vector3d(x=12.5, y=-3.0), yaw=0.0)} if i == 2 else {}))
            yield (b.SensorView(global_ground_truth=gt) if sensor_view else gt).to_binary()


@pytest.mark.parametrize("seed", range(6))
def test_optional_parts_decode_the_same(tmp_path, seed):
    rng = np.random.default_rng(seed)
    sv = seed % 2 == 1
    trace = _write(tmp_path / ("t_sv_.osi" if sv else "t_gt_.osi"), _random_messages(rng, sensor_view=sv))
    cols = _same_decoding(trace)
    assert len(cols[0]) == 36 and cols[5][0] == GEO and cols[5][1][:2] == (12.5, -3.0)


def _field(number: int, wire: int, payload: bytes) -> bytes:
    if wire == pw.LEN:
        payload = pw.varint_bytes(len(payload)) + payload
    return pw.key(number, wire) + payload


def _d(number: int, v: float) -> bytes:
    return _field(number, pw.I64, struct.pack("<d", v))


def _v(number: int, value: int) -> bytes:
    return _field(number, pw.VARINT, pw.varint_bytes(value))


def _msg(number: int, *parts: bytes) -> bytes:
    return _field(number, pw.LEN, b"".join(parts))


def _object(oid: int, x: float, *, shuffled: bool) -> bytes:
    pos = [_d(3, 0.5), _d(1, x), _d(2, -2.0)] if shuffled else [_d(1, x), _d(2, -2.0), _d(3, 0.5)]
    base = [_msg(2, *pos), _msg(1, _d(2, 1.9), _d(1, 4.6)), _msg(3, _d(3, 0.25)),
            _msg(4, _d(1, 20.0)), _msg(9, _d(1, 1.0))]  # 9: bounding_box_section, not read
    parts = [_msg(2, *base), _v(3, 2), _msg(6, _v(1, 4), _msg(2, _v(7, 3), _v(1, 4))),
             _msg(1, _v(1, oid)), _msg(4, _v(1, 9)) if shuffled else b"",
             _msg(7, b"model.glb"), _field(1000, pw.VARINT, pw.varint_bytes(5))]
    return b"".join(parts[::-1] if shuffled else parts)


@pytest.mark.parametrize("shuffled", [False, True])
def test_wire_layouts_the_bindings_do_not_write(tmp_path, shuffled):
    """Fields in any order, unknown and skipped fields (also with multi-byte keys), ids and
    timestamps as long varints: read as the bindings read them."""
    raws = [b"".join([_msg(5, _object(2**62 + 1, 10.0 * i, shuffled=shuffled)),
                      _msg(5, _object(3, -1.0 * i, shuffled=shuffled)),
                      _msg(2, _v(2, 999_999_999), _v(1, 2**40 + i)), _msg(3, _v(1, 3)),
                      _msg(10, b"\x08\x01" * 40)])  # lane, not read
            for i in range(4)]
    cols = _same_decoding(_write(tmp_path / "x_gt_.osi", raws))
    assert cols[0][:, 1].tolist() == [0.0, -0.0, 10.0, -1.0, 20.0, -2.0, 30.0, -3.0]
    assert cols[3][3]["lanes"] == ({9} if shuffled else set())


def test_what_it_does_not_take_goes_to_betterosi(tmp_path, monkeypatch):
    """A singular sub-message twice (protobuf merges them) or another wire type for a field the
    import reads: the columnar decoder declines and the betterosi path gives the recording."""
    road = tmp_path / "road.xodr"
    road.write_text(straight_highway(length=600.0, lanes_right=2, lanes_left=1, geo_reference=GEO))
    obj = _object(3, 50.0, shuffled=False)
    twice = obj + _msg(2, _msg(2, _d(2, -1.0)))  # base.position again: y merged in
    for extra in (twice, obj + _d(3, 2.0)):
        raws = [_msg(5, extra) + _msg(2, _v(1, 100 + i)) for i in range(3)]
        trace = _write(tmp_path / "d_gt_.osi", raws)
        with pytest.raises(FastPathUnsupported):
            _decoded(osi._decode_columns, trace, osi.OsiOptions())
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = convert("osi", [trace], map_source=road)
        assert rec.states.num_rows == 3
    assert rec.states["y"].to_pylist() == pytest.approx([-2.0] * 3)


@pytest.mark.parametrize("bad", [b"\x2a\x05\x08", b"\x2a\x02\xff\xff", b"\x2b\x00", b"\x00\x01",
                                 b"\x08" + b"\xff" * 11])
def test_broken_bytes_give_betterosis_located_error(tmp_path, bad):
    """Truncated sub-messages, unterminated varints, groups, field number 0: the error is the one
    of the betterosi path, naming the message."""
    good = _msg(5, _object(3, 1.0, shuffled=False)) + _msg(2, _v(1, 1))
    trace = _write(tmp_path / "b_gt_.osi", [good, good + bad])
    with pytest.raises(FastPathUnsupported):
        _decoded(osi._decode_columns, trace, osi.OsiOptions())
    with pytest.raises(FormatError, match="OSI message 1"):
        convert("osi", [trace], map_source=tmp_path / "none.xodr")


def test_walk_locates_the_broken_field():
    buf = pw.padded(b"\x08\x01\x12\x05ab" + b"\x08\x01")
    with pytest.raises(pw.WireError) as e:
        pw.walk(buf, np.array([0, 6]), np.array([6, 8]))
    assert (e.value.span, e.value.offset) == (0, 2) and "ends 3 bytes after" in e.value.reason
    F = pw.walk(buf, np.array([6, 0]), np.array([8, 2]))
    assert F.span.tolist() == [0, 1] and F.value.tolist() == [1, 1]


def test_chunks_give_the_same_samples(tmp_path, monkeypatch):
    from aveas_format.converters import osi_columns

    trace = _write(tmp_path / "c_gt_.osi", _random_messages(np.random.default_rng(9), 30))
    whole = _decoded(osi._decode_columns, trace, osi.OsiOptions())
    monkeypatch.setattr(osi_columns, "CHUNK_BYTES", 100)
    chunked = _decoded(osi._decode_columns, trace, osi.OsiOptions())
    np.testing.assert_array_equal(whole[0], chunked[0])
    assert whole[2].tolist() == chunked[2].tolist() and whole[3] == chunked[3]


@pytest.mark.parametrize("sensor_view", [False, True])
def test_mcap_traces_decode_the_same(tmp_path, sensor_view):
    """An MCAP trace (the messages as betterosi's reader yields them): the same decoding."""
    trace = tmp_path / "t.mcap"
    msgs = _random_messages(np.random.default_rng(4), sensor_view=sensor_view)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        proto = b.SensorView() if sensor_view else b.GroundTruth()
        with b.Writer(trace) as w:
            for k, raw in enumerate(msgs):
                w.add(osi_export._Encoded(raw, proto), log_time=k * 10**8)
    cols = _same_decoding(trace)
    assert len(cols[0]) == 36


def test_bytes_it_knows_it_does_not_take_go_to_betterosi(tmp_path, caplog):
    """A proj_string that is not UTF-8: the columnar decoder refuses it by name, the betterosi
    path reads the trace and reports it, located; the log says which path read the file and
    why."""
    good = _msg(5, _object(3, 1.0, shuffled=False)) + _msg(2, _v(1, 1))
    trace = _write(tmp_path / "u_gt_.osi", [good + _field(14, pw.LEN, b"\xff\xfe")])
    with pytest.raises(FastPathUnsupported, match="message 0: proj_string is not UTF-8"):
        _decoded(osi._decode_columns, trace, osi.OsiOptions())
    with caplog.at_level("INFO", logger="aveas_format.converters"), \
            pytest.raises(FormatError, match="OSI message 0"):
        convert("osi", [trace], map_source=tmp_path / "none.xodr")
    assert ("u_gt_.osi: read by betterosi (the columnar decoder does not take it: message 0: "
            "proj_string is not UTF-8 text)") in caplog.text


def test_a_bug_in_the_columnar_decoder_propagates(tmp_path, monkeypatch):
    """Anything but a declared refusal propagates from the fast path: a defect there is an
    error, not a silent switch to the slower decoder."""
    from aveas_format.converters import osi_columns

    raws = [_msg(5, _object(3, 50.0, shuffled=False)) + _msg(2, _v(1, 100 + i)) for i in range(3)]
    trace = _write(tmp_path / "g_gt_.osi", raws)
    road = tmp_path / "road.xodr"
    road.write_text(straight_highway(length=600.0, lanes_right=2, lanes_left=1, geo_reference=GEO))

    def broken(*a, **k):
        raise KeyError("a bug")

    monkeypatch.setattr(osi_columns, "decode_chunk", broken)
    called = []
    monkeypatch.setattr(osi, "_decode_objects", lambda *a, **k: called.append(1))
    with pytest.raises(KeyError, match="a bug"):
        convert("osi", [trace], map_source=road)
    assert called == []


def test_the_log_names_the_path_that_read_the_trace(tmp_path, caplog):
    raws = [_msg(5, _object(3, 50.0, shuffled=False)) + _msg(2, _v(1, 100 + i)) for i in range(3)]
    trace = _write(tmp_path / "l_gt_.osi", raws)
    road = tmp_path / "road.xodr"
    road.write_text(straight_highway(length=600.0, lanes_right=2, lanes_left=1, geo_reference=GEO))
    with caplog.at_level("INFO", logger="aveas_format.converters"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        convert("osi", [trace], map_source=road)
    assert "l_gt_.osi: read by the columnar decoder" in caplog.text
