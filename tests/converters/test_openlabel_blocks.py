"""The OpenLABEL import reads its frames in blocks (converters/openlabel/source.py, decode.py): the
recording and the located findings are those of the same document parsed by ``json.loads``
(:func:`openlabel_to_recording`), whatever the blocks (their size, cut before a frame head or by
structure, a cut that proves wrong, read here or by worker processes), the layout (pretty printed,
the frame properties after the objects, attributes of other names or types) and the damage (the
JSON error, or the file read whole where ``json.loads`` reads what the decoder refuses); a box's
attributes decode as a JSON parser reads them."""

from __future__ import annotations

import itertools
import json
import logging
import math
import os
import warnings

import numpy as np
import pytest

from aveas_format.converters import convert, get_converter
from aveas_format.converters.openlabel import openlabel_to_recording, read, source
from aveas_format.errors import FormatError, collect_source_findings
from aveas_format.sample import highway_scene

from helpers_converters import assert_identical


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("blocks")
    rec = highway_scene(n_vehicles=6, duration_s=4.0, seed=5)
    path = tmp / "rec.json"
    get_converter("openlabel", "export")(rec, path)
    return path


def _found(fn):
    with collect_source_findings() as found, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = fn()
    return rec, [(f.code, f.location, f.count) for f in found]


def _import(path, **options):
    return _found(lambda: convert("openlabel", [path], options=options))


def _reference(path):
    """The document as json.loads reads it, imported."""
    mb = (path.parent / "rec.xodr").read_bytes()
    return _found(lambda: openlabel_to_recording(json.loads(path.read_bytes()), mb, path=path))


def _outcome(fn):
    try:
        return fn()
    except FormatError as e:
        return e.message, None


def _same_as_json(path, **options):
    """The import of ``path`` gives the recording and findings of the document json.loads reads,
    or its error."""
    got, f_got = _outcome(lambda: _import(path, **options))
    want, f_want = _outcome(lambda: _reference(path))
    if isinstance(want, str):
        assert got == want
    else:
        assert_identical(got, want)
        assert f_got == f_want
    return f_got


@pytest.fixture
def many_blocks(monkeypatch):
    """Blocks of ~3 kB (a frame or less each), read by worker processes from any file size."""
    monkeypatch.setattr(source, "BLOCK", 3000)
    monkeypatch.setattr(read, "SMALL", 0)


def _edited(exported, tmp_path, edit, name="edited.json", indent=None):
    doc = json.loads(exported.read_bytes())
    edit(doc["openlabel"])
    p = tmp_path / name
    p.write_bytes(json.dumps(doc, separators=None if indent else (",", ":"), indent=indent).encode())
    (p.parent / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    return p


def _boxes(ol, at=(0,)):
    frames = list(ol["frames"].values())
    return [next(iter(frames[i]["objects"].values()))["object_data"] for i in at]


def _rotate(ol):
    _boxes(ol)[0]["cuboid"][0]["val"][3] = 0.01


def _null_ext(ol):
    _boxes(ol)[0]["cuboid"][0]["aveas_format"]["lane_offset"] = None


def _tricky_text(ol):
    _boxes(ol)[0]["text"].append({"name": "note", "val": 'a "{[}]" \\ b,"9":{"frame_properties"'})


def _interior(ol):
    _boxes(ol)[0]["num"].append({"name": "interior/steering_angle", "val": 0.1})


def _pmf(ol):
    _boxes(ol)[0]["vec"].append({"name": "classification/uncertainties", "val": [0.5, 0.4]})


def _velocity_as_text(ol):
    _boxes(ol)[0]["vec"][0]["val"] = ["1", "2"]


def _missing_velocity(ol):
    vec = _boxes(ol)[0]["vec"]
    vec[:] = [v for v in vec if v["name"] != "velocity"]


def _properties_last(ol):  # (KITTI's layout: no frame starts with its properties)
    ol["frames"] = {k: {"objects": fr["objects"], "frame_properties": fr["frame_properties"]}
                    for k, fr in ol["frames"].items()}


def _mixed(ol):
    """A PMF not summing to 1, a missing velocity and a rotated box in frames after the first."""
    a, b, c = _boxes(ol, (3, 7, 12))
    a["vec"].append({"name": "classification/uncertainties", "val": [0.5, 0.4]})
    b["vec"][:] = [v for v in b["vec"] if v["name"] != "velocity"]
    c["cuboid"][0]["val"][3] = 0.01


@pytest.mark.parametrize("edit", [None, _rotate, _null_ext, _tricky_text, _interior, _pmf, _velocity_as_text,
                                  _missing_velocity, _properties_last, _mixed])
@pytest.mark.parametrize("indent", [None, 2])
def test_the_document_as_json_reads_it(exported, tmp_path, many_blocks, edit, indent):
    """A rotated box (placed through its rotation), a null extension member, escaped quotes,
    brackets and a frame head in a text, interior signals, a PMF not summing to 1, a vector of
    texts, a missing mandatory attribute, the frames' properties after their objects; compact or
    pretty printed; in many blocks read by two worker processes."""
    p = _edited(exported, tmp_path, edit or (lambda ol: None), indent=indent)
    found = _same_as_json(p, workers=2)
    if edit is _pmf:
        assert [c for c, *_ in found] == ["source.openlabel.pmf_sum"] and found[0][1]["frame"] == "0"
    if edit is _mixed:
        assert sorted(c for c, *_ in found) == ["source.openlabel.missing_attribute", "source.openlabel.pmf_sum"]


@pytest.mark.parametrize("block", [1 << 23, 20_000, 3000, 50])
@pytest.mark.parametrize("workers", [1, 2])
def test_any_block_size(exported, monkeypatch, block, workers):
    """One block, a few frames each, a frame each, less than a frame (a block grows to whole
    frames); here or in worker processes that read their own bytes."""
    monkeypatch.setattr(source, "BLOCK", block)
    monkeypatch.setattr(read, "SMALL", 0)
    _same_as_json(exported, workers=workers)


def test_a_uid_twice_in_a_frame_keeps_the_last(exported, tmp_path):
    raw = exported.read_bytes()
    i = raw.index(b'"objects":{') + len(b'"objects":{')  # the first box of the first frame
    depth, end = 0, None
    for k in range(raw.index(b"{", i), len(raw)):
        depth += (raw[k:k + 1] == b"{") - (raw[k:k + 1] == b"}")
        if depth == 0:
            end = k + 1
            break
    p = tmp_path / "dup.json"
    p.write_bytes(raw[:end] + b"," + raw[i:end] + raw[end:])
    (p.parent / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    found = _same_as_json(p)
    assert "source.openlabel.duplicate_state" not in [c for c, *_ in found]


def test_a_cut_inside_a_frame_is_found_and_cut_again_by_structure(exported, tmp_path, many_blocks, caplog):
    """A frame holding an object laid out like a frame head (``"k":{"frame_properties"``): a
    block cut there does not decode, the reader cuts again by structure from that block on (and
    says so in the log): the same recording."""
    def nested(ol):
        for fr in ol["frames"].values():  # (the last object of every frame: no box)
            fr["objects"]["99"] = {"frame_properties": {"timestamp": 9.0}, "note": "no cuboid"}

    p = _edited(exported, tmp_path, nested)
    with caplog.at_level(logging.INFO, logger="aveas_format.converters.openlabel.read"):
        _same_as_json(p, workers=2)
    assert any("cut by structure" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("size, window", [(3000, 3000), (3000, 400), (20_000, 1 << 18)])
def test_lazy_cuts_give_the_blocks_of_a_full_read(exported, monkeypatch, size, window):
    """Where workers read their own blocks, the cuts found in a window before each block's end
    give whole frames (each block parses), the same bytes as a full read."""
    monkeypatch.setattr(source, "CUT_WINDOW", window)
    fr = source.open_frames(exported)
    blocks = {}
    for lazy in (False, True):
        with source.open_file(exported) as f:
            got = []
            for offset, data, kind in source.cuts(fr, f, size, lazy=lazy):
                if kind == "tail":
                    source.read_tail(fr, data, offset)
                    continue
                if isinstance(data, tuple):  # (what the worker reads)
                    start, n = data
                    data = exported.read_bytes()[start:start + n]
                got.append(data)
            blocks[lazy] = got
    assert b",".join(blocks[True]) == b",".join(blocks[False]) and len(blocks[True]) > 3
    for b in blocks[True]:
        assert isinstance(json.loads(b"{" + b + b"}"), dict)
    assert fr.tail is not None and set(fr.tail) >= {"objects", "contexts"}
    doc = json.loads(exported.read_bytes())["openlabel"]
    assert fr.document() == {k: v for k, v in doc.items() if k != "frames"}


def _deep(ol):
    val = 1
    for _ in range(70):
        val = [val]
    list(ol["frames"].values())[5]["frame_properties"]["deep"] = val


def _nan(ol):
    list(ol["frames"].values())[5]["frame_properties"]["timestamp"] = float("nan")


@pytest.mark.parametrize("damage", ["deep", "nan", "truncated", "frames_twice", "bad_tail", "string_in_tail",
                                    "broken_frame"])
def test_damaged_files_give_the_json_reading_or_its_error(exported, tmp_path, many_blocks, damage):
    """Nesting over 64 levels in a frame's properties (a file of less than a chunk of the
    pre-scan: refused as load_json refuses it), NaN (read whole, as json.loads reads it), a
    truncated file, a second frames member (the last counts), broken JSON after the frames or in
    a frame, an unclosed string: the recording json.loads reads, or a FormatError naming the
    file."""
    if damage in ("deep", "nan"):
        doc = json.loads(exported.read_bytes())
        {"deep": _deep, "nan": _nan}[damage](doc["openlabel"])
        raw = json.dumps(doc, separators=(",", ":")).encode()
    else:
        raw = exported.read_bytes().rstrip()
        raw = {"truncated": raw[:-40], "frames_twice": raw[:-2] + b',"frames":{}}}',
               "bad_tail": raw[:-2] + b',"x":[1,}}', "string_in_tail": raw[:-2] + b',"x":"a}}',
               "broken_frame": raw.replace(b'"frame_properties":{"timestamp":0.2',
                                           b'"frame_properties":{"timestamp" 0.2', 1)}[damage]
    p = tmp_path / f"{damage}.json"
    p.write_bytes(raw)
    (p.parent / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    if damage == "deep":
        with pytest.raises(FormatError, match="nested deeper than 64") as ei:
            convert("openlabel", [p], options={"workers": 2})
        return
    try:
        json.loads(raw)
    except ValueError:
        with pytest.raises(FormatError) as ei:
            convert("openlabel", [p], options={"workers": 2})
        assert str(p) in str(ei.value) and "broken JSON" in str(ei.value)
        return
    _same_as_json(p, workers=2)


# --- one box's attributes as a JSON parser reads them ---------------------------------------------

_NAMES = ["velocity", "acceleration", "bounding_box/ustddev", "velocity/ustddev", "open_drive/lane_position",
          "used_road_link", "open_drive/lane_id", "open_drive/local_road_coordinates", "lights/brake",
          "road/classification", "impact/gttc/values", "note", "velocity/uncertainties"]


def _expected(od: dict, n_boxes: int) -> dict:
    """What the profile reads of a box (the first item of a name over the kinds boolean, num,
    text, vec), from the parsed JSON."""
    from aveas_format.converters.openlabel.profile import attributes_of

    attrs = attributes_of(od)

    def first(name):
        items = attrs.get(name)
        return (True, items[0].get("val")) if items else (False, None)

    def num(x):
        try:
            return float(x) if x is not None and not isinstance(x, (list, dict)) else math.nan
        except (TypeError, ValueError):
            return math.nan

    out = {}
    for name, cols in (("velocity", {"vu": 0, "vv": 1, "yaw_rate": 5}), ("acceleration", {"au": 0, "av": 1}),
                       ("bounding_box/ustddev", {"x_std": 0, "heading_std": 5})):
        present, v = first(name)
        out[f"has:{name}"] = present and v is not None
        for c, e in cols.items():
            out[c] = num(v[e]) if isinstance(v, list) and len(v) > e else math.nan
    present, v = first("open_drive/lane_position")
    out["lane_position"] = num(v) if present else math.nan
    present, v = first("lights/brake")
    out["light_brake_p"] = math.nan if not present or v is None else float(bool(v))
    return out


def test_a_box_reads_as_a_json_parser_reads_it():
    """Attribute items of the profile's names and others, in any kind, of values of any type
    (numbers, texts, null, lists of numbers, of texts, ragged, objects), items without a name or
    with a name that is no text, a single item instead of a list: the block's columns are what
    the profile reads of the boxes json.loads parses."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from aveas_format.converters.openlabel.decode import decode_block

    values = st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.floats(-1e6, 1e6), st.text(max_size=3),
                       st.lists(st.one_of(st.floats(-10, 10), st.integers(-3, 3), st.none(), st.just("1.5")),
                                max_size=7),
                       st.dictionaries(st.text(max_size=2), st.integers(), max_size=2))
    item = st.one_of(st.fixed_dictionaries({"name": st.sampled_from(_NAMES), "val": values}),
                     st.fixed_dictionaries({"val": values}), st.fixed_dictionaries({"name": st.integers()}))
    kinds = st.dictionaries(st.sampled_from(["boolean", "num", "text", "vec"]),
                            st.one_of(st.lists(item, max_size=5), item), max_size=4)

    @settings(max_examples=150, deadline=None)
    @given(st.lists(kinds, min_size=1, max_size=6))
    def check(boxes):
        frames = {"0": {"objects": {str(i): {"object_data": {
            "cuboid": [{"name": "bounding_box", "val": [float(i), 0, 0.75, 0, 0, 0.1, 4, 2, 1.5]}], **od}}
            for i, od in enumerate(boxes)}}}
        blk = decode_block(json.dumps(frames).encode())
        for i, od in enumerate(json.loads(json.dumps(boxes))):
            for c, want in _expected(od, len(boxes)).items():
                got = blk.cols[c][i]
                assert (got == want) or (isinstance(want, float) and math.isnan(want) and math.isnan(got)), (c, od)

    check()


# --- the worker processes ------------------------------------------------------------------------

_FORKS: list | None = None


def _at_fork() -> None:
    import threading

    if _FORKS is not None:
        _FORKS.append(sorted(t.name for t in threading.enumerate() if t is not threading.main_thread()))


def test_worker_processes_are_forked_before_the_digest_thread_starts(exported, many_blocks, monkeypatch):
    """No thread of the import runs when its worker processes are forked (a fork copies a thread's
    locks, not the thread): the input's SHA-256 starts after the first block came back."""
    import hashlib
    import time

    from aveas_format.converters.common import provenance as common

    global _FORKS
    if not hasattr(os, "register_at_fork"):
        pytest.skip("no os.register_at_fork on this platform")
    if not getattr(test_worker_processes_are_forked_before_the_digest_thread_starts, "hooked", False):
        os.register_at_fork(before=_at_fork)
        test_worker_processes_are_forked_before_the_digest_thread_starts.hooked = True
    sha256 = common._sha256

    def slow_sha256(path, *args):  # (as on a large file: still hashing when the workers start)
        time.sleep(0.5)
        return sha256(path, *args)

    monkeypatch.setattr(common, "_sha256", slow_sha256)
    _FORKS = []
    try:
        rec, _ = _import(exported, workers=2)
        forks = _FORKS
    finally:
        _FORKS = None
    assert rec.states.num_rows and len(forks) >= 2
    assert not any(name.startswith("sha256") for names in forks for name in names), forks
    assert rec.meta.source.inputs[0].sha256 == hashlib.sha256(exported.read_bytes()).hexdigest()



def test_verbose_says_which_path_read_the_file(exported, tmp_path):
    """``convert -v``: the blocks (how many, how cut, by how many processes); a file the decoder
    refuses (NaN) read whole, and why."""
    from typer.testing import CliRunner

    from aveas_format.cli.app import app

    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(exported), "-o", str(tmp_path / "a.aveas"),
                                 "-v", "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert "read in 2 blocks of whole frames" in r.output and "decoded by this process" in r.output
    p = _edited(exported, tmp_path, _nan, name="nan.json")
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(p), "-o", str(tmp_path / "b.aveas"), "-v"])
    assert r.exit_code == 0, r.output
    assert "read whole (NaN or Infinity" in r.output
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(p), "-o", str(tmp_path / "c.aveas")])
    assert "read whole" not in r.output


def test_number_lists_read_as_a_json_parser_reads_them():
    """The lists of numbers a block parses at once (the cuboids' values, a vector's values of one
    length) are the floats ``json.loads`` reads, bit for bit: integers (``-0`` as 0.0), ``-0.0``,
    exponents, 17 digits, integers beyond 64 bits, a number below the smallest double, whitespace
    in the lists; next to a list that is empty, nested or holds no number (read box by box). So are
    single numbers (next to a null)."""
    from aveas_format.converters.openlabel.decode import decode_block

    def block(toks, vels):
        objs = ",".join(f'"{i}":{{"object_data":{{"cuboid":[{{"name":"bounding_box","val":[{i},0,0.75,0,0,0.1,'
                        f'{toks[i % len(toks)]},2,1.5]}}],"vec":[{{"name":"velocity","val":{v}}}],'
                        f'"num":[{{"name":"open_drive/lane_position","val":{(toks + ["null"])[i]}}}]}}}}'
                        for i, v in enumerate(vels))
        return decode_block(('{"0":{"objects":{' + objs + "}}}").encode())

    def bits(x):
        return np.asarray(x, float).tobytes()

    toks = ["-0.0", "0", "1E+2", "2.5e-3", "5e-324", "1e-400", "0.30000000000000004", "123456789012345678901",
            "-17", "1.7976931348623157e308", "-2.2250738585072014e-308"]
    for toks, sep in itertools.product((toks, ["-0", *toks]), (",", " , ", ",\n  ")):
        vels = [f"[{t}{sep}{toks[-1 - i]}{sep}0,0,0{sep}{t}]" for i, t in enumerate(toks)]
        for odd in (None, "[]", "[[1],2,0,0,0,1]", '[1,"a",0,0,0,1]', "[1,2]"):
            blk = block(toks, vels + [odd] * (odd is not None))
            want = [float(json.loads(t)) for t in toks]
            assert bits(blk.cols["vu"][:len(toks)]) == bits(want), (sep, odd)
            assert bits(blk.cols["yaw_rate"][:len(toks)]) == bits(want), (sep, odd)
            assert bits(blk.cols["vv"][:len(toks)]) == bits(want[::-1]), (sep, odd)
            assert bits(blk.cols["dl"][:len(toks)]) == bits(want), (sep, odd)
            assert bits(blk.cols["lane_position"][:len(toks)]) == bits(want), (sep, odd)
            if odd in ("[]", "[[1],2,0,0,0,1]"):
                assert math.isnan(blk.cols["vu"][-1]) and blk.cols["vv"][-1] == 2 if odd != "[]" else \
                    math.isnan(blk.cols["vv"][-1])


def test_extension_members_present_null_or_absent():
    """The ``aveas_format`` members of the boxes' cuboids, block after block (a block decoded with
    the types of the one before): a member with a value, with null and absent told apart."""
    from aveas_format.converters.openlabel.decode import decode_block
    from aveas_format.converters.openlabel.profile import EXT

    for exts in ([{"a": 1, "b": 2.5}, {"a": 2}], [{"a": 3}, {"a": None, "b": 1.0}], [{"b": 1.5}, {"a": 4}, {}],
                 [{"a": 1, "b": None}, None, {"c": "x"}], [{"a": 1, "b": 2.5}, {"a": 1, "b": 2.5}]):
        objs = {str(i): {"object_data": {"cuboid": [{"name": "bounding_box", "val": [i, 0, 0.75, 0, 0, 0.1, 4, 2, 1.5],
                                                     **({EXT: e} if e is not None else {})}]}}
                for i, e in enumerate(exts)}
        blk = decode_block(json.dumps({"0": {"objects": objs}}).encode())
        items = [e or {} for e in exts]
        assert sorted(blk.ext) == sorted(set(itertools.chain(*items)))
        for c, (vals, present) in blk.ext.items():
            assert present.tolist() == [c in e for e in items] and vals.to_pylist() == [e.get(c) for e in items], exts
