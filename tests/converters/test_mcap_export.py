"""MCAP for Foxglove: channels, schemas, message counts and a box pose read back."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

mcap_reader = pytest.importorskip("mcap.reader")
pytest.importorskip("foxglove_schemas_protobuf")

from aveas_format.converters import get_converter  # noqa: E402


def test_mcap_export(rich, tmp_path):
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from aveas_format.schema.metadata import timestamp_ns

    out = tmp_path / "rec.mcap"
    paths = get_converter("mcap", "export")(rich, out)
    assert paths == [out]
    with open(out, "rb") as f:
        reader = mcap_reader.make_reader(f)
        summary = reader.get_summary()
        schemas = {s.id: s for s in summary.schemas.values()}
        channels = {c.topic: c for c in summary.channels.values()}
        assert {"/scene", "/map", "/locations", "/origin", "/unobserved"} <= set(channels)
        assert schemas[channels["/scene"].schema_id].name == "foxglove.SceneUpdate"
        assert schemas[channels["/scene"].schema_id].encoding == "protobuf"
        assert schemas[channels["/locations"].schema_id].name == "foxglove.LocationFix"
        counts = {channels_id: n for channels_id, n in summary.statistics.channel_message_counts.items()}
        by_topic = {c.topic: counts.get(cid, 0) for cid, c in summary.channels.items()}
        s = rich.states
        times = np.unique(s.column("time").to_numpy())
        assert by_topic["/scene"] == len(times)
        assert by_topic["/map"] == 1 and by_topic["/origin"] == 1
        assert by_topic["/locations"] == s.num_rows
        assert by_topic["/unobserved"] == rich.unobserved.num_rows
        f.seek(0)
        reader = mcap_reader.make_reader(f)
        t0 = timestamp_ns(rich.meta.start_time)
        first_scene = lane_msg = first_fix = None
        for schema, channel, message in reader.iter_messages(topics=["/scene", "/map", "/locations"]):
            if channel.topic == "/scene" and first_scene is None:
                first_scene = (message, SceneUpdate.FromString(message.data))
            elif channel.topic == "/map":
                lane_msg = SceneUpdate.FromString(message.data)
            elif channel.topic == "/locations" and first_fix is None:
                first_fix = LocationFix.FromString(message.data)
    msg, scene = first_scene
    assert msg.log_time == t0 + int(round(times[0] * 1e9))
    first_rows = s.filter(s.column("time").to_numpy() == times[0]).to_pylist()
    assert len(scene.entities) == len(first_rows)
    row = first_rows[0]
    ent = next(e for e in scene.entities if e.id == f"participant/{row['participant_id']}")
    cube = ent.cubes[0]
    assert cube.pose.position.x == pytest.approx(row["x"]) and cube.pose.position.y == pytest.approx(row["y"])
    assert 2 * math.atan2(cube.pose.orientation.z, cube.pose.orientation.w) == pytest.approx(row["heading"])
    part = rich.participants.to_pylist()
    p = next(r for r in part if r["participant_id"] == row["participant_id"])
    assert cube.size.x == pytest.approx(p["length"]) and cube.size.y == pytest.approx(p["width"])
    assert ent.texts[0].text.startswith(str(row["participant_id"]))
    assert ent.frame_id == "map"
    lanes = lane_msg.entities[0]
    assert lanes.id == "map/lanes" and len(lanes.lines) == 3  # 3 lanes of the sample motorway
    assert first_fix.latitude == pytest.approx(48.9, abs=0.05)


def test_cli_export_mcap(rich, tmp_path):
    rec_path = rich.write(tmp_path / "r.aveas")
    out = tmp_path / "r.mcap"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "export", "--to", "mcap", str(rec_path),
                          "-o", str(out), "-O", "every=2", "-O", "locations=false"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    with open(out, "rb") as f:
        summary = mcap_reader.make_reader(f).get_summary()
    assert "/locations" not in {c.topic for c in summary.channels.values()}


def test_mcap_export_in_batches_writes_the_same_messages(rich, tmp_path, monkeypatch):
    """The boxes and locations are encoded in batches of states (bounded memory): any batch size
    gives the same messages, and each decodes with the Foxglove bindings."""
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from aveas_format.converters import mcap_export

    export = get_converter("mcap", "export")

    def messages(path):
        with open(path, "rb") as f:
            return [(c.topic, m.log_time, m.data) for _, c, m in
                    mcap_reader.make_reader(f).iter_messages()]

    export(rich, tmp_path / "whole.mcap")
    monkeypatch.setattr(mcap_export, "BATCH_STATES", 5)
    export(rich, tmp_path / "batched.mcap")
    whole = messages(tmp_path / "whole.mcap")
    assert whole == messages(tmp_path / "batched.mcap")
    scene = next(d for topic, _, d in whole if topic == "/scene")
    e = SceneUpdate.FromString(scene).entities[0]
    assert e.id.startswith("participant/") and e.frame_id == "map" and len(e.cubes) == 1
    assert e.metadata[0].key == "class" and e.texts[0].text.endswith(e.metadata[0].value)
    fix = LocationFix.FromString(next(d for topic, _, d in whole if topic == "/locations"))
    assert fix.frame_id.isdigit() and -90 <= fix.latitude <= 90 and fix.color.a > 0


def test_bulk_messages_write_the_file_add_message_writes(rich, tmp_path, monkeypatch):
    """``add_messages`` (records built with numpy, appended a chunk at a time) writes the bytes
    mcap's ``add_message`` one by one writes: chunks cut at the same messages, the same indexes
    and statistics — on random message sizes with small chunks, and on the whole export."""
    import functools
    import io

    import mcap.writer

    from aveas_format.converters import _protowire as pw
    from aveas_format.converters import mcap_export

    rng = np.random.default_rng(5)
    lengths = rng.integers(0, 700, 3000)
    data = pw.Ragged(rng.integers(0, 256, int(lengths.sum())).astype(np.uint8), lengths)
    times = np.cumsum(rng.integers(0, 3, 3000)) + 10**9

    def file(bulk: bool) -> bytes:
        buf = io.BytesIO()
        w = mcap.writer.Writer(buf, chunk_size=4096)
        w.start()
        ch = w.register_channel("/a", "protobuf", w.register_schema("a", "protobuf", b""))
        other = w.register_channel("/b", "protobuf", 0)
        w.add_message(other, 5, b"first", 5)  # a message of another channel in the same chunk
        for a, b in ((0, 1), (1, 1000), (1000, 3000)):
            if bulk:
                mcap_export.add_messages(w, ch, times[a:b], pw.Ragged(
                    data.data[data.offsets()[a]:data.offsets()[b]], lengths[a:b]))
            else:
                for t, d in zip(times[a:b].tolist(), data.tolist()[a:b]):
                    w.add_message(ch, t, d, t)
        w.finish()
        return buf.getvalue()

    assert file(True) == file(False)
    with io.BytesIO(file(True)) as f:
        got = [(m.log_time, m.data) for _, _, m in mcap_reader.make_reader(f).iter_messages()]
    assert got[1:] == list(zip(times.tolist(), data.tolist()))

    monkeypatch.setattr(mcap.writer, "Writer", functools.partial(mcap.writer.Writer, chunk_size=20000))
    get_converter("mcap", "export")(rich, tmp_path / "bulk.mcap")

    def one_by_one(w, channel, ts, d):
        for t, x in zip(np.asarray(ts).tolist(), d.tolist()):
            w.add_message(channel, t, x, t)

    monkeypatch.setattr(mcap_export, "add_messages", one_by_one)
    get_converter("mcap", "export")(rich, tmp_path / "single.mcap")
    assert (tmp_path / "bulk.mcap").read_bytes() == (tmp_path / "single.mcap").read_bytes()


def test_a_map_that_cannot_be_sampled_is_said_and_a_bug_propagates(rich, tmp_path, monkeypatch):
    """The lanes are left out with a warning where the map engine refuses the map (a MapError,
    a ValueError); anything else — a defect — propagates instead of silently dropping them."""
    net = type(rich.map)

    def refuses(self, *a, **k):
        raise ValueError("road 7: geometry ends before its length")

    monkeypatch.setattr(net, "lane_polygons", refuses)
    with pytest.warns(UserWarning, match="the map's lanes are left out: road 7"):
        get_converter("mcap", "export")(rich, tmp_path / "a.mcap")

    def broken(self, *a, **k):
        raise KeyError("a bug")

    monkeypatch.setattr(net, "lane_polygons", broken)
    with pytest.raises(KeyError, match="a bug"):
        get_converter("mcap", "export")(rich, tmp_path / "b.mcap")
