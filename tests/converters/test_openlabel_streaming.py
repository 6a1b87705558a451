"""The OpenLABEL import of a file (its frames read in blocks) gives the recording of the document as
``json.loads`` reads it, in any frame order; broken, non-UTF-8, oversized and deeply nested files
give a clear FormatError naming the file; memory stays bounded by a small multiple of the file."""

from __future__ import annotations

import json
import random
import tracemalloc
import warnings

import pytest

import aveas_format
from aveas_format.converters import convert, get_converter
from aveas_format.converters.openlabel import openlabel_to_recording
from aveas_format.sample import highway_scene

from helpers_converters import assert_identical


STRAIGHT = aveas_format.__path__[0] + "/../tests/data/straight.xodr"


def _export(rec, path):
    get_converter("openlabel", "export")(rec, path)
    return path


def _dict_path(path, map_source=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ol = json.loads(path.read_bytes())
        mb = open(map_source, "rb").read() if map_source else path.with_suffix(".xodr").read_bytes()
        return openlabel_to_recording(ol, mb, path=path)


def _streamed(path, map_source=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return convert("openlabel", [path], map_source=map_source)


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    rec = highway_scene(n_vehicles=8, duration_s=6, seed=3)
    return _export(rec, tmp_path_factory.mktemp("ol") / "scene.json")


def test_streamed_equals_dict_path(rich, scene_file, tmp_path):
    for path in (_export(rich, tmp_path / "rich.json"), scene_file):
        assert_identical(_streamed(path), _dict_path(path))


def test_shuffled_frame_order_gives_the_same_recording(scene_file, tmp_path):
    doc = json.loads(scene_file.read_bytes())
    frames = doc["openlabel"]["frames"]
    keys = list(frames)
    random.Random(7).shuffle(keys)
    doc["openlabel"]["frames"] = {k: frames[k] for k in keys}
    # objects before the frames and frames last: the streamed reader takes any member order
    doc["openlabel"] = {k: doc["openlabel"][k] for k in sorted(doc["openlabel"], reverse=True)}
    (tmp_path / "scene.xodr").write_bytes(scene_file.with_suffix(".xodr").read_bytes())
    shuffled = tmp_path / "shuffled.json"
    shuffled.write_text(json.dumps(doc, indent=1))
    a = _streamed(shuffled, tmp_path / "scene.xodr")
    assert_identical(a, _dict_path(shuffled, tmp_path / "scene.xodr"))
    b = _streamed(scene_file)
    assert a.states.equals(b.states) and a.participants.equals(b.participants)


def test_generic_files_streamed_equal_dict_path(tmp_path, openlabel_data):
    for name in ("asam_spec__openlabel100_example_cuboids.json",
                 "asam_spec__openlabel100_test_bbox_simple.json",
                 "vcd__openlabel100_test_cuboids.json", "aveas__minimum_openlabel_example.json"):
        src = openlabel_data / name
        try:
            expected = _dict_path(src, STRAIGHT)
        except aveas_format.AveasError as e:
            with pytest.raises(type(e)):
                _streamed(src, STRAIGHT)
            continue
        assert_identical(_streamed(src, STRAIGHT), expected)


def _generic_doc(frames: str) -> bytes:
    return ('{"openlabel": {"metadata": {"schema_version": "1.0.0"}, "frames": ' + frames +
            ', "objects": {"7": {"name": "car7", "type": "car"}}}}').encode()


def _box(x: float, ts: float) -> str:
    return json.dumps({"frame_properties": {"timestamp": ts}, "objects": {"7": {"object_data": {
        "cuboid": [{"name": "bounding_box", "val": [x, 0.0, 0.75, 0, 0, 0, 4.0, 2.0, 1.5]}]}}}})


def test_duplicates_and_repeated_frame_keys_as_the_dict_path(tmp_path):
    # frame "2" repeats a timestamp (the later box is dropped), key "1" appears twice (json.loads
    # keeps the last one), keys arrive out of order
    frames = ('{"10": ' + _box(5.0, 1.0) + ', "2": ' + _box(3.0, 0.1) + ', "1": ' + _box(1.0, 0.0)
              + ', "3": ' + _box(4.0, 0.1) + ', "1": ' + _box(2.0, 0.0) + '}')
    p = tmp_path / "dup.json"
    p.write_bytes(_generic_doc(frames))
    with pytest.warns(UserWarning, match="1 boxes repeat"):
        a = convert("openlabel", [p], map_source=STRAIGHT)
    assert_identical(a, _dict_path(p, STRAIGHT))
    assert a.states.column("time").to_pylist() == [0.0, 0.1, 1.0]


# --- clear errors ---------------------------------------------------------------------------------

def _err(path, match):
    with pytest.raises(aveas_format.FormatError, match=match) as ei:
        convert("openlabel", [path], map_source=STRAIGHT)
    assert str(path) in str(ei.value)
    return ei.value


def test_truncated_and_broken_json(scene_file, tmp_path):
    data = scene_file.read_bytes()
    p = tmp_path / "cut.json"
    p.write_bytes(data[: len(data) // 2])
    _err(p, "broken JSON")
    p.write_bytes(data.replace(b'"objects":', b'"objects" ', 1))
    e = _err(p, "broken JSON")
    assert "byte" in str(e)
    p.write_bytes(data[:-1] + b"} trailing")
    _err(p, "broken JSON")
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + ', "2": {"objects": [1, 2,]}}'))
    _err(p, "broken JSON")
    p.write_bytes(b"")
    _err(p, "broken JSON|Expecting value")


def test_not_utf8(tmp_path):
    p = tmp_path / "latin1.json"
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + '}').replace(b"bounding_box", b"bounding_b\xf6x"))
    _err(p, "not UTF-8")
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + '}').replace(b'"car7"', b'"car\xff"'))
    _err(p, "not UTF-8")


def test_size_limit(scene_file, monkeypatch):
    import aveas_format.converters.openlabel.source as ol

    monkeypatch.setattr(ol, "MAX_STREAMED_JSON_BYTES", 1000)
    _err(scene_file, "exceeds the limit of 1,000")


def test_a_streamed_file_may_be_larger_than_a_file_read_whole(scene_file, tmp_path, monkeypatch):
    """The 1-hour file (~10 GB) is over the limit of JSON read whole (4 GiB): streamed, its memory
    grows with its states, not its text; a file that has to be read whole keeps that limit."""
    import aveas_format.converters.openlabel.source as ol

    want = _streamed(scene_file)
    monkeypatch.setattr(ol, "MAX_BULK_JSON_BYTES", 1000)
    assert_identical(_streamed(scene_file), want)
    nan = tmp_path / "nan.json"  # (NaN: the decoder refuses it, the file is read whole)
    nan.write_bytes(scene_file.read_bytes().replace(b'"timestamp":0.0', b'"timestamp":NaN', 1))
    _err(nan, "exceeds the limit of 1,000")


def test_deep_nesting(tmp_path):
    """What the structural pre-scan reads (the members before and after the frames; the whole of a
    file smaller than its first chunk) is held to the 64 levels of load_json; in the frames of a
    larger file, a member the import does not read is skipped by the decoder, which refuses
    nesting beyond Python's recursion limit: a clear error, never a crash."""
    deep = "[" * 200 + "]" * 200
    p = tmp_path / "deep.json"
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + '}').replace(
        b'"schema_version": "1.0.0"', b'"x": ' + deep.encode()))
    _err(p, "nested deeper than 64")
    p.write_bytes(_generic_doc('{"1": {"objects": {}, "x": ' + deep + '}}'))
    _err(p, "nested deeper than 64")
    filler = ", ".join(f'"{k}": ' + _box(1.0 + k, 0.1 * k) for k in range(2, 12000))
    deeper = "[" * 5000 + "]" * 5000
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + ', ' + filler + ', "99999": {"objects": {}, "x": '
                               + deeper + '}}'))
    assert p.stat().st_size > 2 << 20  # (beyond the pre-scan's first chunk)
    _err(p, "nested too deep")


def test_not_openlabel(tmp_path):
    p = tmp_path / "other.json"
    p.write_bytes(b'{"frames": {}}')
    _err(p, "not an OpenLABEL file")
    p.write_bytes(b'[1, 2]')
    _err(p, "not an OpenLABEL file")


# --- memory ---------------------------------------------------------------------------------------

def test_memory_is_bounded(tmp_path):
    rec = highway_scene(n_vehicles=30, duration_s=40, seed=2)
    path = _export(rec, tmp_path / "big.json")
    size = path.stat().st_size
    assert size > 8_000_000
    del rec
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        out = _streamed(path)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert out.states.num_rows > 5000
    assert peak < 3 * size, f"peak {peak:,} for a file of {size:,} bytes"


# --- the structural pre-scan ----------------------------------------------------------------------

_TRICKY = ['frames', '"frames"', 'openlabel', '\\', '\\"', '"openlabel": {', 'a"b', '{[', ']}', 'ü',
           '\\\\"frames\\\\"']


def _random_value(rng, d=0):
    r = rng.random()
    if d > 5 or r < 0.3:
        return rng.choice([1, 2.5, None, True, rng.choice(_TRICKY) + rng.choice(_TRICKY)])
    if r < 0.6:
        return [_random_value(rng, d + 1) for _ in range(rng.randint(0, 3))]
    return {rng.choice([*_TRICKY, "x", "frames"]): _random_value(rng, d + 1)
            for _ in range(rng.randint(0, 3))}


def _depth(o):
    if isinstance(o, dict):
        return 1 + max((_depth(v) for v in o.values()), default=0)
    if isinstance(o, list):
        return 1 + max((_depth(v) for v in o), default=0)
    return 0


def test_scan_finds_the_frames_and_the_depth_exactly():
    """Keys and brackets inside strings (escaped quotes, backslash runs), "frames" members at other
    levels, any chunk boundary: the span holds exactly doc["openlabel"]["frames"]."""
    import io

    from aveas_format.safeio import scan_json_member

    rng = random.Random(5)
    for _ in range(600):
        ol = {k: _random_value(rng, 1) for k in rng.sample(["metadata", "objects", "x", "frames",
                                                            "openlabel"], rng.randint(0, 5))}
        if rng.random() < 0.7:
            ol["frames"] = {str(i): _random_value(rng, 3) for i in range(rng.randint(0, 4))}
        doc = {k: _random_value(rng, 1) for k in rng.sample(["a", "frames", "b"], rng.randint(0, 2))}
        doc["openlabel"] = ol
        items = list(doc.items())
        rng.shuffle(items)
        text = json.dumps(dict(items), indent=rng.choice([None, 1]),
                          ensure_ascii=rng.random() < 0.5).encode()
        depth, span, ok = scan_json_member(io.BytesIO(text), "openlabel", "frames",
                                           chunk=rng.choice([1, 3, 7, 64, 1 << 20]))
        assert ok and depth == _depth(doc), text
        if isinstance(ol.get("frames"), dict):
            assert json.loads(text[span[0]:span[1]]) == ol["frames"], text
        else:
            assert span is None, text


def test_repeated_frames_member_is_read_whole_as_json_does(tmp_path):
    p = tmp_path / "twice.json"
    p.write_bytes(('{"openlabel": {"frames": {"1": ' + _box(9.0, 0.0) + '}, "objects": {"7": {"name": '
                   '"car7", "type": "car"}}, "frames": {"1": ' + _box(1.0, 0.0) + ', "2": '
                   + _box(2.0, 0.1) + '}}}').encode())
    a = convert("openlabel", [p], map_source=STRAIGHT)
    assert_identical(a, _dict_path(p, STRAIGHT))
    assert a.states.num_rows == 2


def test_nan_and_infinity_as_json_loads_reads_them(tmp_path):
    """Python's JSON extensions (aveas-openlabel writes them with json.dumps' defaults): the
    decoder refuses them, the import then reads the file whole."""
    p = tmp_path / "nan.json"
    p.write_bytes(_generic_doc('{"1": ' + _box(1.0, 0.0) + ', "2": ' + _box(2.0, 0.1).replace(
        '"objects"', '"x": NaN, "y": -Infinity, "objects"') + '}'))
    assert_identical(convert("openlabel", [p], map_source=STRAIGHT), _dict_path(p, STRAIGHT))


def _parts_export(rec, path, **kw):
    from aveas_format.converters.openlabel.write import openlabel_chunks
    from aveas_format.safeio import write_chunks_atomic

    return write_chunks_atomic(path, openlabel_chunks(rec, chunk_rows=300, **kw)).read_bytes()


@pytest.mark.parametrize("workers,part_rows", [(2, 200_000), (3, 200_000), (2, 1_000), (3, 1_000)])
def test_frames_encoded_in_forked_parts_give_the_same_file(tmp_path, monkeypatch, workers, part_rows):
    """The frames of a large export in parts (one round, or many: parts of ~1,000 rows dealt in
    turn; safeio/parts.py), those of the forked processes encoded into files next to the output
    and copied in by the kernel: the same bytes as in one process (the participants' extremes
    merged), no part file left. A process that fails at once, or after its first part, has its
    parts (the rest) encoded here instead."""
    import os

    from aveas_format.safeio import parts
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=12, duration_s=20.0, seed=4)
    monkeypatch.setattr(parts, "PARTS_MIN_ROWS", 0)
    monkeypatch.setattr(parts, "PART_ROWS", part_rows)
    one = _parts_export(rec, tmp_path / "one.json")
    out = tmp_path / "parts"
    out.mkdir()
    assert _parts_export(rec, out / "rec.json", workers=workers, spill_dir=out) == one
    assert [p.name for p in out.iterdir()] == ["rec.json"]
    real = parts._write_parts
    for i, fails in enumerate([lambda *a: os._exit(3),  # (at once)
                               lambda enc, st, ps, conn: real(enc, st, ps[:1], conn) or os._exit(3)]):
        monkeypatch.setattr(parts, "_write_parts", fails)
        assert _parts_export(rec, out / f"again{i}.json", workers=workers, spill_dir=out) == one
        assert sorted(p.name for p in out.iterdir()) == sorted(["rec.json", *(f"again{k}.json" for k in range(i + 1))])


def test_the_export_takes_workers_and_writes_the_same_file(tmp_path, monkeypatch):
    from aveas_format.converters import get_converter
    from aveas_format.converters.openlabel import write
    from aveas_format.safeio import parts
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=12, duration_s=20.0, seed=4)
    monkeypatch.setattr(parts, "PARTS_MIN_ROWS", 0)
    monkeypatch.setattr(write, "CHUNK_ROWS", 300)
    from aveas_format.safeio import atomic

    copied = []  # (the parts copied in from the forked processes' files)
    real = atomic.GrowingSegment.copy_into
    monkeypatch.setattr(atomic.GrowingSegment, "copy_into", lambda seg, *a: copied.append(1) or real(seg, *a))
    ex = get_converter("openlabel", "export")
    opts = {"write_map": False, "map_file": "m.xodr"}
    a = ex(rec, tmp_path / "a.json", options={**opts, "workers": 1})[0].read_bytes()
    assert not copied
    b = ex(rec, tmp_path / "b.json", options={**opts, "workers": 2})[0].read_bytes()
    assert a == b and copied == [1]
