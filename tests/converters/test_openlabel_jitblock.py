"""The compiled reader of OpenLABEL blocks (issue 22, converters/openlabel/_jitblock.py): a
validating parser of the profile's box layout. It gives the same columns, extension columns,
findings, frames and nesting depth as Arrow's reader of the same blocks; it refuses (status 1:
the other paths read the block or name the error) every syntax error and everything outside the
layout; numbers come back exactly as a JSON parser reads them."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
pytest.importorskip("orjson")

import aveas_format.converters.openlabel.fastblock as fb  # noqa: E402
from aveas_format.converters import get_converter  # noqa: E402
from aveas_format.converters.openlabel import _jitblock as jb  # noqa: E402
from aveas_format.converters.openlabel import stream  # noqa: E402
from aveas_format.converters.openlabel.columns import _MISSING, ext_chunk  # noqa: E402
from aveas_format.sample import highway_scene  # noqa: E402

from helpers_common import kernel  # noqa: E402
from helpers_converters import openlabel_blocks  # noqa: E402


@pytest.fixture(scope="module")
def blocks(tmp_path_factory):
    """The blocks of frames of a sample export, as the import cuts them (~50 frames each)."""
    return openlabel_blocks(tmp_path_factory.mktemp("jitblock"), n_vehicles=8, duration_s=6.0, seed=2,
                            size=40_000)


@pytest.fixture(autouse=True)
def _numba():
    with kernel("numba"):
        yield


def _parse(buf: bytes):
    return fb.compiled_parser()(fb.padded(buf))


def _jit(buf: bytes):
    return fb._read_block_jit(fb.padded(buf), fb.compiled_parser())


def _same(a, b) -> None:
    """Two FastBlocks hold the same frames, columns, extension columns, findings and depth."""
    assert a.frames == b.frames and a.depth == b.depth and a.found == b.found
    assert a.cols.keys() == b.cols.keys()
    for k in a.cols:
        x, y = a.cols[k], b.cols[k]
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), k
        else:  # (object columns: the Python types too, 1 == 1.0 == True)
            assert [(type(v), v) for v in x.tolist()] == [(type(v), v) for v in y.tolist()], k
    assert a.ext.keys() == b.ext.keys()
    for k in a.ext:
        assert _rep(a.ext[k]) == _rep(b.ext[k]), k


def _rep(r: tuple) -> tuple:
    """An extension column, comparable (NaN as None, the types of the values kept)."""
    out = [r[0]]
    for v in r[1:]:
        if v.dtype.kind == "f":
            out.append([None if np.isnan(x) else x for x in v.tolist()])
        else:
            out.append([(type(x).__name__, x) if x is not _MISSING else "missing" for x in v.tolist()])
    return tuple(out)


def test_the_sample_export_reads_as_arrow_reads_it(blocks):
    assert len(blocks) > 3
    for buf in blocks:
        got = _jit(buf)
        assert got is not None
        _same(got, fb._read_block(buf))


def test_pretty_printed_and_reordered_blocks_too(blocks):
    """Whitespace everywhere and the members of boxes and items in another order: the same."""
    buf = blocks[1]
    doc = json.loads(buf)
    for fr in doc.values():
        for box in fr["objects"].values():
            od = box["object_data"]
            box["object_data"] = {k: [dict(reversed(list(it.items()))) for it in od[k]] for k in reversed(list(od))}
    pretty = json.dumps(doc, indent=3).encode()
    got = _jit(pretty)
    assert got is not None
    _same(got, fb._read_block(pretty))
    _same(got, _jit(buf))


def _with_box(box: str, frame_extra: str = "") -> bytes:
    """A block of one frame holding ``box`` (JSON text) as its only object."""
    return ('{"0":{"frame_properties":{"timestamp":0.0%s},"objects":{"7":%s}}}' % (frame_extra, box)).encode()


#: a box of the profile's layout, with {VAL} where the tests put a velocity's values
_BOX = ('{"object_data":{"cuboid":[{"name":"bounding_box","val":[1.5,2.5,0.75,0.0,0.0,0.1,4.5,1.8,1.5],'
        '"aveas_format":{"vx":12.5,"interpolated":false,"source_frame":3,"note":"x"}}],'
        '"vec":[{"name":"velocity","val":{VAL}},{"name":"open_drive/local_road_coordinates","val":[10.0,-1.5]}],"num":[{"name":"open_drive/lane_position","val":0.25}],'
        '"text":[{"name":"used_road_link","val":"1"},{"name":"open_drive/lane_id","val":"-2"}],'
        '"boolean":[{"name":"lights/brake","val":true}]}}')


def _box(val: str = "[12.5,0.5,0,0,0,0.01]") -> str:
    return _BOX.replace("{VAL}", val)


def test_a_box_reads_as_a_json_parser_reads_it():
    buf = _with_box(_box("[-0,1E+2,0.5e-3,-12.25,3]"))
    got = _jit(buf)
    assert got is not None
    assert got.frames == [("0", {"frame_properties": {"timestamp": 0.0}, "objects": {"7": 0}})]
    assert got.cols["px"].tolist() == [1.5] and got.cols["dl"].tolist() == [4.5]
    assert got.cols["pz"].tolist() == [0.0] and got.cols["yaw"].tolist() == [0.1]
    assert got.cols["road_id"].tolist() == ["1"] and got.cols["lane_id"].tolist() == [-2]
    assert got.cols["road_s"].tolist() == [10.0] and got.cols["road_t"].tolist() == [-1.5]
    assert got.cols["lane_position"].tolist() == [0.25] and got.cols["light_brake_p"].tolist() == [1.0]
    # the extension item as a JSON parser gives it: floats "f", an int, a bool and a text as objects
    want = ext_chunk([json.loads(buf)["0"]["objects"]["7"]["object_data"]["cuboid"][0]["aveas_format"]])
    assert {k: _rep(v) for k, v in got.ext.items()} == {k: _rep(v) for k, v in want.items()}
    assert got.ext["vx"][0] == "f" and got.ext["source_frame"][1].tolist() == [3]
    assert type(got.ext["source_frame"][1][0]) is int and got.ext["interpolated"][1].tolist() == [False]
    _same(got, fb._read_block(buf))


@pytest.mark.parametrize("val", [
    "[1,,2]", "[1 2]", "[1,]", "[01]", "[1.]", "[.5]", "[-]", "[1e]", "[+1]", "[NaN]", "[Infinity]",
    "[1", "[null]", '["1"]', "[tru]", "[1]]", "{}", "[1}", "[0x10]", "[1.5.2]"])
def test_broken_or_other_values_are_refused(val):
    """Syntax errors and values of another type in a box: status 1 (the other paths decide)."""
    assert _parse(_with_box(_box(val)))[0] == 1


@pytest.mark.parametrize("box", [
    _box().replace('"val":"1"', '"val":"1\\"x"'),  # an escape in a text
    _box().replace('"val":"1"', '"val":"a\tb"'),  # a control character in a string
    _box().replace('"val":"1"', '"val":"a\\qb"'),  # an invalid escape
    _box().replace('"name":"velocity",', '"name":"velocity","name":"velocity",'),  # a repeated member
    _box().replace('"vx":12.5,', '"vx":12.5,"vx":1.5,'),  # a repeated key in the extension item
    _box().replace('"vx":12.5', '"vx":null'),  # a null
    _box().replace('"vx":12.5', '"vx":[1]'),  # a list in the extension item
    _box().replace('"x"}}],"vec"', '"x"}},{"name":"bounding_box","val":[1,2,3,0,0,0,1,1,1]}],"vec"'),  # 2 cuboids
    _box().replace('"name":"bounding_box",', '"name":"bounding_box","coordinate_system":"odom",'),
    _box().replace('"name":"bounding_box"', '"name":"box"'),
    _box().replace('0.0,0.0,0.1,4.5', '0.0,0.1,4.5'),  # 8 values
    _box().replace('{"object_data":', '{"name":"car","object_data":'),  # another member of the box
    _box().replace('"boolean":', '"point2d":'),  # another kind
    _box().replace('"num":[{"name":"open_drive/lane_position","val":0.25}]', '"num":[{"val":0.25}]'),
    _box().replace('"val":true', '"val":1'),
    _box().replace('"object_data":{', '"object_data":{"text":[],'),  # a kind twice
    '{"object_data":{}}', '[]', '{"object_data":{"cuboid":[]}}'])
def test_what_is_outside_the_layout_is_refused(box):
    buf = _with_box(box)
    assert box != _box()
    try:
        assert _parse(buf)[0] == 1 or _jit(buf) is None
    except fb._NotFast:  # (found in the parser's arrays: a key twice in the extension item)
        pass


#: attribute items as the profile's reader takes them: the first of a name in a box, of the
#: earliest kind (boolean, num, text, vec); PMFs and mandatory attributes checked on those
_ITEMS = [
    ('"vec":[{"name":"velocity","val":[1,2,0,0,0,0.5]},{"name":"velocity","val":[9,9,0,0,0,9]},'
     '{"name":"acceleration","val":[0.5,0.25]}]'),  # a name twice; a short vector
    ('"vec":[{"name":"classification/uncertainties","val":[0.5,0.4]},{"name":"velocity","val":[3]}],'
     '"num":[{"name":"classification/uncertainties","val":1}]'),  # a PMF in two kinds; no acceleration
    ('"vec":[{"name":"classification/uncertainties","val":[0.5,0.5]},{"name":"acceleration","val":[1,1]}],'
     '"text":[{"name":"used_road_link","val":"4"},{"name":"used_road_link","val":"5"}]'),  # no velocity
    ('"vec":[{"name":"velocity","val":[1,2,0,0,0,0.5]},{"name":"acceleration","val":[0,0]}],'
     '"boolean":[{"name":"lights/brake","val":false},{"name":"lights/front","val":true}]'),
]


def _items_box(items: str) -> str:
    return ('{"object_data":{"cuboid":[{"name":"bounding_box","val":[1.5,2.5,0.75,0.0,0.0,0.1,4.5,1.8,1.5]}],'
            + items + '}}')


def test_attribute_items_are_taken_by_name_as_the_profile_reads_them():
    buf = ('{"0":{"frame_properties":{"timestamp":0.0},"objects":{%s}}}'
           % ",".join('"%d":%s' % (k, _items_box(it)) for k, it in enumerate(_ITEMS))).encode()
    got, want = _jit(buf), fb._read_block(buf)
    assert got is not None and want is not None
    _same(got, want)
    np.testing.assert_array_equal(got.cols["vu"], [1.0, 3.0, np.nan, 1.0])
    np.testing.assert_array_equal(got.cols["yr"], [0.5, np.nan, np.nan, 0.5])
    np.testing.assert_array_equal(got.cols["au"], [0.5, np.nan, 1.0, 0.0])
    np.testing.assert_array_equal(got.cols["light_brake_p"], [np.nan, np.nan, np.nan, 0.0])
    assert sorted(c for c, *_ in got.found) == ["source.openlabel.missing_attribute"] * 2 + [
        "source.openlabel.pmf_sum"]


def _refused_or_read_as_arrow_reads_it(buf: bytes, escaped: bool) -> None:
    """``buf`` refused by the compiled reader where a name or key in it has an escape, else read
    as Arrow's reader reads it."""
    got = _jit(buf)
    if escaped:
        assert got is None
        return
    assert got is not None
    _same(got, fb._read_block(buf))


#: the items of the first box: the name after "acceleration" in the parser's table is "velocity"
_FIRST = '{"name":"acceleration","val":[0.5,0.25]},{"name":"velocity","val":[1,2,0,0,0,0.5]}'


@pytest.mark.parametrize("items", [
    '{"name":"velocity/ustddev","val":[0.2]}',  # begins as the name expected
    '{"name":"velocit","val":[1]},{"name":"velocityy","val":[2]},{"name":"velocity","val":[5]}',
    '{"name":"velocity","val":[3,4,0,0,0,0]},{"name":"acceleration","val":[1,1]}',
    '{"n\\u0061me":"velocity","val":[1]}',  # a key with an escape: not "name"
    '{"name":"velocit\\u0079","val":[1]}',  # the name expected, escaped
    '{"name":"velocity","v\\u0061l":[1]}',
    '{"val":[2],"name":"velocity"},{"name":"velocity/ustddev","val":[0.3]}'])
def test_names_read_the_short_way_are_read_as_json_reads_them(items):
    """The parser takes an item's name by comparing the bytes with the name it expects (the one
    after the item before in its table), a member's key with the word it expects: a name that only
    begins or ends like it, or one written with an escape, reads as Arrow's reader reads it, or
    is refused (the other paths read it)."""
    first = _items_box('"vec":[%s]' % _FIRST)
    second = _items_box('"vec":[{"name":"acceleration","val":[0,0]},%s]' % items)
    buf = ('{"0":{"frame_properties":{"timestamp":0.0},"objects":{"1":%s,"2":%s,"3":%s}}}'
           % (first, second, first)).encode()
    _refused_or_read_as_arrow_reads_it(buf, escaped="\\u" in items)


@pytest.mark.parametrize("box", [
    _box().replace('"vx":12.5,"interpolated"', '"vx":12.5,"vxx":1.5,"interpolated"'),
    _box().replace('"vx":12.5,"interpolated":false', '"vx":12.5,"interpolatedx":true,"interpolated":false'),
    _box().replace('"object_data":{"cuboid"', '"object_dat\\u0061":{"cuboid"'),
    _box().replace('"vec":[', '"ve\\u0063":['),
    _box().replace('"name":"bounding_box"', '"name":"bounding_bo\\u0078"')])
def test_keys_read_the_short_way_are_read_as_json_reads_them(box):
    """The same for the extension item's keys and the layout's words."""
    buf = ('{"0":{"frame_properties":{"timestamp":0.0},"objects":{"1":%s,"2":%s}}}' % (_box(), box)).encode()
    _refused_or_read_as_arrow_reads_it(buf, escaped="\\u" in box)


@pytest.mark.parametrize("extra", ['"num":[{"name":"velocity","val":1}]',
                                   '"text":[{"name":"acceleration","val":"x"}]',
                                   '"num":[{"name":"lights/high_beam","val":0.5}]'])
def test_an_attribute_the_import_reads_in_another_kind_is_refused(extra):
    """(As by Arrow's reader: the generic path reads that block.)"""
    buf = _with_box(_items_box('"vec":[{"name":"velocity","val":[1,2,0,0,0,0]}],' + extra))
    with pytest.raises(fb._NotFast):
        _jit(buf)
    with pytest.raises(fb._NotFast):
        fb._read_block(buf)
    assert fb.read_block(buf) is None


@pytest.mark.parametrize("block", [
    b'{"0":{"objects":{"7":' + _box().encode() + b'}},}',  # a trailing comma
    b'{"0":{"objects":{"7":' + _box().encode() + b'}}} x',  # something after the block
    b'{"0":{"objects":{"7":' + _box().encode() + b'}}',  # unclosed
    b'{"0":{"objects":{"7" ' + _box().encode() + b'}}}',  # no colon
    b'{"0":{"frame_properties":{"a":[1,}]},"objects":{"7":' + _box().encode() + b'}}}',
    b'{"0":{"frame_properties":{"a":' + b"[" * 80 + b"]" * 80 + b'},"objects":{"7":' + _box().encode() + b'}}}',
    b'{"0":{"objects":[]}}'])
def test_broken_frames_are_refused(block):
    assert _parse(block)[0] == 1


def test_other_members_of_items_and_frames_are_skipped_with_their_depth():
    """Members the import does not read (an item's ``attributes``, a stream in the frame's
    properties) are skipped, syntax checked; the block's depth counts them as Arrow's path does."""
    box = _box().replace('"name":"velocity",', '"name":"velocity","attributes":{"a":[[{"b":"}"}]]},')
    buf = _with_box(box, ',"streams":{"cam":{"stream_properties":{"sync":[{"x":[[]]}]}}}')
    got = _jit(buf)
    assert got is not None and got.depth == fb.block_depth(buf) == 11
    _same(got, fb._read_block(buf))


_json = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False, allow_infinity=False) | st.integers()
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=4),
    max_leaves=20)


@settings(max_examples=150, deadline=None)
@given(_json, st.booleans())
def test_any_json_value_in_a_skipped_member_is_skipped(value, pretty):
    """Any JSON value where the parser skips (a frame's property, an item's other member): read,
    with the depth :func:`.fastblock.block_depth` gives."""
    text = json.dumps(value, indent=1 if pretty else None, ensure_ascii=False)
    box = _box().replace('"name":"velocity",', '"name":"velocity","extra":%s,' % text)
    buf = _with_box(box, ',"p":%s' % text)
    r = _parse(buf)
    assert r[0] == 0 and int(r[1]) == fb.block_depth(buf)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False) | st.integers(-2**53, 2**53),
                min_size=1, max_size=12))
def test_numbers_come_back_exactly(values):
    """Every float's shortest text and every integer: the value a JSON parser reads, bit for bit."""
    state = _parse(_with_box(_box(json.dumps(values))))
    assert state[0] == 0
    items = state[3]
    start, count = items[items[:, 1] == jb.K_VEC][0, 3:5].tolist()  # the velocity's numbers
    nums = fb.pc.cast(fb._packed(state[5], state[6]), fb.pa.float64()).to_numpy()[start:start + count]
    want = np.asarray([float(v) for v in json.loads(json.dumps(values))])
    assert np.array_equal(nums, want) and np.array_equal(np.signbit(nums), np.signbit(want))


def test_read_block_takes_the_compiled_reader_first(blocks, monkeypatch):
    """With numba the compiled reader reads the blocks; a block it refuses goes to Arrow's."""
    calls = []
    real = fb._read_block

    def arrow(buf, threads=True):
        calls.append(1)
        return real(buf, threads)

    monkeypatch.setattr(fb, "_read_block", arrow)
    with kernel("numba"):
        assert fb.read_block(blocks[0]) is not None and calls == []
        tricky = _with_box(_box().replace('"val":"1"', '"val":"1\\"x"'))
        assert fb.read_block(tricky) is not None and calls == [1]
    with kernel("numpy"):
        assert fb.read_block(blocks[0]) is not None and calls == [1, 1]


def test_scratch_arrays_are_reused_and_grown_without_leaking_into_results(blocks):
    """The parser's arrays are kept between blocks (grown for a larger one); what a block gives
    back does not change when the next block is read."""
    small = _jit(_with_box(_box()))
    big = b"{" + b",".join(b[1:-1] for b in blocks) + b"}"
    first = _jit(blocks[0])
    want = {k: v.copy() for k, v in first.cols.items()}
    assert _jit(big) is not None and _jit(blocks[1]) is not None
    for k, v in want.items():
        assert v.tolist() == first.cols[k].tolist() or np.array_equal(v, first.cols[k], equal_nan=True), k
    assert small.cols["px"].tolist() == [1.5]


def test_the_compiled_skeleton_is_the_python_one(blocks):
    for buf in blocks[:3] + [_with_box(_box())]:
        state = _parse(buf)
        boxes = state[2]
        assert len(boxes) >= 1
        want = fb._skeleton_bytes(buf, boxes[:, 0].tolist(), boxes[:, 1].tolist())
        assert jb.skeleton(fb.padded(buf)[:-1], boxes).tobytes() == want


def test_files_from_a_size_on_go_through_the_compiled_reader(tmp_path, monkeypatch):
    """Below ``_COMPILED_MIN`` (loading numba costs more than it saves) Arrow's reader reads the
    blocks; from it on the compiled one; the same recording either way."""
    from aveas_format.converters import convert

    from helpers_converters import assert_identical

    path = tmp_path / "rec.json"
    get_converter("openlabel", "export")(highway_scene(n_vehicles=4, duration_s=3.0, seed=1), path)
    used = []
    real = fb._read_block_jit
    monkeypatch.setattr(fb, "_read_block_jit", lambda b, parse: used.append(1) or real(b, parse))
    recs = []
    for limit in (1 << 40, 0):
        monkeypatch.setattr(stream, "_COMPILED_MIN", limit)
        used.clear()
        recs.append(convert("openlabel", [path], options={"workers": 1}))
        assert bool(used) == (limit == 0)
    assert_identical(*recs)


_SMALL = _with_box(_box()).replace(b'"7":', b'"7":' + _box().encode() + b',"8":', 1)


@settings(max_examples=int(os.environ.get("AVEAS_FUZZ_EXAMPLES", "400")), deadline=None,
          derandomize=not os.environ.get("AVEAS_FUZZ_EXAMPLES"))  # (make fuzz: more, random)
@given(st.lists(st.tuples(st.sampled_from(["flip", "drop", "insert"]), st.integers(0, len(_SMALL) - 1),
                          st.sampled_from(list(b'{}[]",:.-+eE0123456789 \\tnul\x00\x80'))),
                min_size=1, max_size=3))
def test_a_damaged_block_is_refused_or_read_as_json_reads_it(ops):
    """Byte flips, drops and insertions anywhere in a block: the compiled reader refuses it, or
    the block is valid JSON and reads as Arrow's reader reads it (where that one takes it)."""
    import orjson

    buf = bytearray(_SMALL)
    for op, at, c in ops:
        at = min(at, len(buf) - 1)
        if op == "flip":
            buf[at] = c
        elif op == "drop":
            del buf[at]
        else:
            buf.insert(at, c)
    buf = bytes(buf)
    try:
        got = _jit(buf)
    except (fb._NotFast, ValueError, KeyError, IndexError, TypeError, fb.pa.ArrowInvalid):
        got = None
    if got is None:
        return
    doc = orjson.loads(buf)  # (accepted: must be JSON)
    boxes = [box for fr in doc.values() for box in (fr.get("objects") or {}).values()]
    assert len(boxes) == len(got.cols["px"])
    # the extension item as a JSON parser gives it (Arrow's reader promotes a key's ints to floats
    # where another box has a float: the same recording in the end, another intermediate form)
    want_ext = ext_chunk([b["object_data"]["cuboid"][0].get("aveas_format") for b in boxes])
    assert {k: _rep(v) for k, v in got.ext.items()} == {k: _rep(v) for k, v in want_ext.items()}
    try:
        want = fb._read_block(buf)
    except (fb.pa.ArrowInvalid, fb._NotFast, ValueError, KeyError, IndexError, TypeError):
        want = None
    if want is not None:
        want.ext = got.ext
        _same(got, want)


def test_one_compiled_reader_for_every_caller(blocks, tmp_path):
    """The reader's functions are compiled for one argument type (numba compiles, ~30 s, once per
    type): in a fresh process, the warm-up of :func:`.fastblock.compiled_parser`, a block given as
    bytes and a block read into a worker's buffer (``stream._read_cut``) use the same one."""
    import subprocess
    import sys

    inner = blocks[1][1:-1]
    (tmp_path / "frames").write_bytes(inner)
    (tmp_path / "block").write_bytes(blocks[0])
    code = f"""
import json
from pathlib import Path
from aveas_format.converters.openlabel import fastblock as fb, _jitblock as jb, stream
fb.compiled_parser()
assert fb.padded(b"{{}}").flags.writeable
assert fb.read_block(Path({str(tmp_path / "block")!r}).read_bytes()) is not None
assert stream._read_cut((0, (0, {len(inner)})), threads=False, path={str(tmp_path / "frames")!r}) is not None
print(json.dumps([len(f.signatures) for f in (jb.parse_block, jb.skeleton, jb.first_items)]))
"""
    env = {**os.environ, "AVEAS_FORMAT_KERNEL": "numba"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == [1, 1, 1]


_FIRST_USE = r"""
import json, sys, time
t = time.time()
from aveas_format.converters.openlabel import fastblock as fb, _jitblock as jb
fb.compiled_parser()
s = jb.parse_block.stats
print(json.dumps({"misses": sum(s.cache_misses.values()), "hits": sum(s.cache_hits.values()),
                  "s": time.time() - t}))
"""


@pytest.mark.slow
def test_processes_starting_together_compile_the_reader_once(tmp_path):
    """Two processes that need the reader at once on a fresh install (an empty numba cache): one
    compiles it and caches it, the other waits and loads it (instead of two compiles at once,
    ~900 MB each)."""
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "AVEAS_FORMAT_KERNEL": "numba"}
    procs = [subprocess.Popen([sys.executable, "-c", _FIRST_USE], env=env, stdout=subprocess.PIPE, text=True)
             for _ in range(2)]
    got = [json.loads(p.communicate(timeout=600)[0]) for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert sorted((g["misses"], g["hits"]) for g in got) == [(0, 1), (1, 0)], got
