"""The columnar fast path of the OpenLABEL import (issue 22, converters/openlabel/fastblock.py):
blocks of frames in the profile's layout become columns through a numpy structural index, an
orjson skeleton and Arrow's JSON reader — or, where numba is installed, the compiled reader
(_jitblock.py; every test here runs on both: the ``backend`` fixture); the recording and the
located findings are those of the generic path, and every block it cannot take is handed over
(never guessed)."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pytest

import aveas_format.converters.openlabel.fastblock as fb
from aveas_format.converters import convert, get_converter
from aveas_format.errors import collect_source_findings
from aveas_format.sample import highway_scene

from helpers_common import KERNEL_BACKENDS, kernel
from helpers_converters import assert_identical

pytest.importorskip("orjson")
_READ_BLOCK = fb.read_block


@pytest.fixture(autouse=True, params=KERNEL_BACKENDS)
def backend(request):
    """Every test on the Arrow reader (``numpy``) and on the compiled one (``numba``; Arrow's where
    it hands a block over; used here for files of any size)."""
    from aveas_format.converters.openlabel import stream

    old = stream._COMPILED_MIN
    stream._COMPILED_MIN = 0
    try:
        with kernel(request.param):
            yield request.param
    finally:
        stream._COMPILED_MIN = old


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fastblock")
    rec = highway_scene(n_vehicles=6, duration_s=4.0, seed=5)
    path = tmp / "rec.json"
    get_converter("openlabel", "export")(rec, path)
    return path


def _import(path, monkeypatch, *, fast: bool, workers: int = 1):
    """``(recording, findings, (blocks the fast path took, blocks offered))`` (the blocks counted
    where they are read in this process: ``workers=1``)."""
    taken = []

    def read_block(buf, threads=True, compiled=True):
        out = _READ_BLOCK(buf, threads, compiled) if fast else None
        taken.append(out is not None)
        return out

    monkeypatch.setattr(fb, "read_block", read_block)
    with collect_source_findings() as found, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = convert("openlabel", [path], options={"workers": workers})
    return rec, [(f.code, f.location, f.count) for f in found], (sum(taken), len(taken))


def _same_both_ways(path, monkeypatch):
    fast, f_fast, n_fast = _import(path, monkeypatch, fast=True)
    slow, f_slow, _ = _import(path, monkeypatch, fast=False)
    assert_identical(fast, slow)
    assert f_fast == f_slow
    return n_fast, f_fast


def test_profile_export_goes_through_columns_with_the_same_result(exported, monkeypatch):
    (n_fast, n), _ = _same_both_ways(exported, monkeypatch)
    assert n_fast == n >= 1


def test_pretty_printed_file_too(exported, tmp_path, monkeypatch):
    p = tmp_path / "pretty.json"
    p.write_text(json.dumps(json.loads(exported.read_bytes()), indent=2))
    (tmp_path / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    (n_fast, n), _ = _same_both_ways(p, monkeypatch)
    assert n_fast == n >= 1


def _edited(exported, tmp_path, edit, name="edited.json"):
    doc = json.loads(exported.read_bytes())
    edit(doc["openlabel"])
    p = tmp_path / name
    p.write_bytes(json.dumps(doc, separators=(",", ":")).encode())
    (tmp_path / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    return p


def _first_box(ol):
    fr = next(iter(ol["frames"].values()))
    return next(iter(fr["objects"].values()))


def _rotate(ol):
    _first_box(ol)["object_data"]["cuboid"][0]["val"][3] = 0.01


def _null_ext(ol):
    _first_box(ol)["object_data"]["cuboid"][0]["aveas_format"]["lane_offset"] = None


def _tricky_text(ol):
    _first_box(ol)["object_data"]["text"].append({"name": "note", "val": 'a "{[}]" \\ b'})


def _interior(ol):
    _first_box(ol)["object_data"]["num"].append({"name": "interior/steering_angle", "val": 0.1})


def _pmf(ol):
    _first_box(ol)["object_data"]["vec"].append({"name": "classification/uncertainties", "val": [0.5, 0.4]})


def _velocity_as_text(ol):
    _first_box(ol)["object_data"]["vec"][0]["val"] = ["1", "2"]


def _missing_velocity(ol):
    vec = _first_box(ol)["object_data"]["vec"]
    vec[:] = [v for v in vec if v["name"] != "velocity"]


@pytest.mark.parametrize("edit, fast", [
    (_rotate, False), (_null_ext, False), (_interior, False), (_velocity_as_text, False),
    (_tricky_text, True), (_pmf, True), (_missing_velocity, True)])
def test_blocks_it_cannot_take_are_handed_over(exported, tmp_path, monkeypatch, edit, fast):
    """A rotated box, a null, interior attributes, a vector of texts: the generic path reads the
    block; escaped quotes and brackets in strings, a PMF not summing to 1, a missing mandatory
    attribute: read in columns, with the same recording and located findings."""
    p = _edited(exported, tmp_path, edit)
    taken, offered = _import(p, monkeypatch, fast=True)[2]
    assert taken == (offered if fast else offered - 1)
    _, found = _same_both_ways(p, monkeypatch)
    if edit is _pmf:
        assert [c for c, *_ in found] == ["source.openlabel.pmf_sum"]
        assert found[0][1]["frame"] == "0"


def test_a_uid_twice_in_a_frame_is_handed_over(exported, tmp_path, monkeypatch):
    """A frame listing an object twice (JSON keeps the last): the generic path, the same result."""
    raw = exported.read_bytes()
    i = raw.index(b'"objects":{') + len(b'"objects":{')  # the first box of the first frame
    end = _object_end(raw, raw.index(b"{", i))
    p = tmp_path / "dup.json"
    p.write_bytes(raw[:end] + b"," + raw[i:end] + raw[end:])
    (tmp_path / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    (n_fast, n), found = _same_both_ways(p, monkeypatch)
    assert n_fast == n - 1
    assert "source.openlabel.duplicate_state" not in [c for c, *_ in found]


def _object_end(raw: bytes, start: int) -> int:
    depth = 0
    for k in range(start, len(raw)):
        c = raw[k:k + 1]
        depth += (c == b"{") - (c == b"}")
        if depth == 0:
            return k + 1
    raise AssertionError


def test_structural_index_skips_strings():
    buf = (b'{"0":{"frame_properties":{"x":"}{[\\"]"},"objects":{"a\\"}":{"object_data":{"text":'
           b'[{"name":"n","val":"{\\\\"}]}},"b":{"object_data":{}}}},'
           b'"1":{"objects":{"c":{"object_data":{"cuboid":[]}}},"other":{"d":{"e":1}}}}')
    starts, ends = fb._box_spans(buf)
    boxes = [json.loads(buf[s:e]) for s, e in zip(starts.tolist(), ends.tolist())]
    assert boxes == [{"object_data": {"text": [{"name": "n", "val": '{\\'}]}}, {"object_data": {}},
                     {"object_data": {"cuboid": []}}]
    assert np.all(ends > starts)


@pytest.mark.parametrize("block", [3000, 50])
def test_any_block_size_gives_the_same_recording(exported, monkeypatch, block):
    """Many small blocks (a frame or less each; below a frame the reader hands over to ijson)."""
    from aveas_format.converters.openlabel import stream

    want, f_want, _ = _import(exported, monkeypatch, fast=False)
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", block)
    got, f_got, (n_fast, n) = _import(exported, monkeypatch, fast=True)
    assert_identical(got, want)
    assert f_got == f_want
    assert n_fast == n and (n > 1 if block == 3000 else n == 0)


def _mixed(ol, rotate: bool = True):
    """A PMF not summing to 1, a missing velocity and a rotated box (a block for the generic
    path) in frames after the first."""
    frames = list(ol["frames"].values())
    boxes = [next(iter(frames[i]["objects"].values()))["object_data"] for i in (3, 7, 12)]
    boxes[0]["vec"].append({"name": "classification/uncertainties", "val": [0.5, 0.4]})
    boxes[1]["vec"][:] = [v for v in boxes[1]["vec"] if v["name"] != "velocity"]
    if rotate:
        boxes[2]["cuboid"][0]["val"][3] = 0.01


@pytest.mark.parametrize("block", [3000, 20_000])
def test_blocks_read_in_worker_processes_give_the_same_recording_and_findings(exported, tmp_path,
                                                                                 monkeypatch, block):
    """Two worker processes read the blocks (columns handed back in file order; with 20 kB blocks
    the workers read their bytes themselves): the same recording and the same located findings
    as in process, a block the fast path cannot take included."""
    from aveas_format.converters.openlabel import stream

    p = _edited(exported, tmp_path, _mixed)
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", block)  # ~a frame a block: many blocks in flight
    want, f_want, (n_fast, n) = _import(p, monkeypatch, fast=True)
    assert n_fast == n - 1 and n > 4 - 2 * (block > 3000)
    assert sorted(c for c, *_ in f_want) == ["source.openlabel.missing_attribute", "source.openlabel.pmf_sum"]
    got, f_got, _ = _import(p, monkeypatch, fast=True, workers=2)
    assert_identical(got, want)
    assert f_got == f_want


def _outcome(path, monkeypatch, prescan: bool):
    """The recording (or the error's message) of an import, with the frames read without the
    structural pre-scan where that path takes them (``prescan=False``), else with it."""
    from aveas_format.converters.openlabel import stream
    from aveas_format.errors import FormatError

    if prescan:
        monkeypatch.setattr(stream, "_frames_without_prescan", lambda path: None)
    try:
        rec, found, _ = _import(path, monkeypatch, fast=True)
        return rec, found
    except FormatError as e:
        return str(e), None
    finally:
        monkeypatch.undo()


@pytest.mark.parametrize("workers", [1, 2])
def test_frames_without_the_prescan_give_the_same_recording(exported, tmp_path, monkeypatch, workers):
    """The structure scanned up to the frames only; the frames' blocks verify their own; the
    members after the frames (the contexts) read at their end: the same recording and findings."""
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_HEAD_CHUNK", 512)  # (else the small file is scanned whole)
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 3000)
    p = _edited(exported, tmp_path, lambda ol: _mixed(ol, rotate=False))
    ol, frames = stream._stream_doc(p, prescan=False)
    assert list(ol)[-1] == "frames"  # the members after the frames come with their end
    n = sum(1 for _ in frames(columnar=True, workers=workers))
    assert n > 4 and list(ol)[-1] != "frames" and ol["frames"] == {}
    want_ol, _ = stream._stream_doc(p)
    assert ol == want_ol
    monkeypatch.setattr(stream, "_HEAD_CHUNK", 512)
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 3000)
    got, f_got, _ = _import(p, monkeypatch, fast=True, workers=workers)
    want, f_want = _outcome(p, monkeypatch, prescan=True)
    assert_identical(got, want)
    assert f_got == f_want


def _deep(ol):
    val = 1
    for _ in range(70):
        val = [val]
    list(ol["frames"].values())[5]["frame_properties"]["deep"] = val


def _nan(ol):
    list(ol["frames"].values())[5]["frame_properties"]["timestamp"] = float("nan")


@pytest.mark.parametrize("damage", ["deep", "nan", "rotated", "truncated", "frames_twice", "bad_tail",
                                    "string_in_tail"])
def test_files_the_prescan_must_judge_give_the_same_result_or_error(exported, tmp_path, monkeypatch,
                                                                    damage):
    """Nesting over the limit in a frame, NaN, a block for the generic path before the objects
    are known, a truncated file, a second frames member, broken JSON after the frames, an
    unclosed string: the path without the pre-scan hands over to it, with the same recording or
    the same located error as the pre-scan path gives."""
    from aveas_format.converters.openlabel import stream

    if damage in ("deep", "nan", "rotated"):
        doc = json.loads(exported.read_bytes())
        {"deep": _deep, "nan": _nan, "rotated": _mixed}[damage](doc["openlabel"])
        raw = json.dumps(doc, separators=(",", ":")).encode()
    else:
        raw = exported.read_bytes().rstrip()
        raw = {"truncated": raw[:-40], "frames_twice": raw[:-2] + b',"frames":{}}}',
               "bad_tail": raw[:-2] + b',"x":[1,}}', "string_in_tail": raw[:-2] + b',"x":"a}}'}[damage]
    p = tmp_path / f"{damage}.json"
    p.write_bytes(raw)
    (tmp_path / "rec.xodr").write_bytes(exported.with_suffix(".xodr").read_bytes())
    outcomes = []
    for prescan in (False, True):
        monkeypatch.setattr(stream, "_HEAD_CHUNK", 512)
        monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 3000)
        outcomes.append(_outcome(p, monkeypatch, prescan))
    (a, fa), (b, fb_) = outcomes
    if isinstance(b, str):
        assert a == b
        assert damage != "nan"
    else:
        assert_identical(a, b)
        assert fa == fb_


@pytest.mark.parametrize("size, window", [(3000, 3000), (3000, 400), (20_000, 1 << 18)])
def test_lazy_cuts_give_the_blocks_of_a_full_read(exported, monkeypatch, size, window):
    """Where workers read their own blocks, the cuts found in a window before each block's end
    (a window smaller than a frame: the block read here, as before) give whole frames each, the
    same bytes in all."""
    from aveas_format.converters.openlabel import stream
    from aveas_format.safeio import scan_json_member

    monkeypatch.setattr(stream, "_CUT_WINDOW", window)
    cuts = {}
    for lazy in (False, True):
        with open(exported, "rb") as f:
            _, span, _ = scan_json_member(f, "openlabel", "frames")
            f.seek(span[0] + 1)
            got = []
            for pos, cut in stream._cut_blocks(f, span, size, lazy=lazy):
                if isinstance(cut, tuple):  # (what the worker reads)
                    start, n = cut
                    cut = exported.read_bytes()[start:start + n]
                got.append((pos, cut))
            cuts[lazy] = got
    assert b",".join(c for _, c in cuts[True]) == b",".join(c for _, c in cuts[False])
    assert len(cuts[True]) > 3
    for _, c in cuts[True]:
        assert isinstance(json.loads(b"{" + c + b"}"), dict)
    with open(exported, "rb") as f:  # (and the window's cut is taken where it is found)
        _, span, _ = scan_json_member(f, "openlabel", "frames")
        f.seek(span[0] + 1)
        lazy = [c for _, c in stream._cut_blocks(f, span, size, lazy=True)]
    assert any(isinstance(c, tuple) for c in lazy) == (size == 20_000)  # (a frame: ~7 kB)


def test_a_worker_reads_its_block_with_or_without_preadv(exported, monkeypatch):
    """The worker's read of a lazily cut block (``os.preadv`` into its buffer, ``os.pread`` where
    the platform lacks it) gives the block the main process would have read."""
    from aveas_format.converters.openlabel import stream
    from aveas_format.safeio import scan_json_member

    with open(exported, "rb") as f:
        _, span, _ = scan_json_member(f, "openlabel", "frames")
        f.seek(span[0] + 1)
        pos, cut = next(c for c in stream._cut_blocks(f, span, 20_000, lazy=True) if isinstance(c[1], tuple))
    start, n = cut
    want = _READ_BLOCK(b"{" + exported.read_bytes()[start:start + n] + b"}")
    assert want is not None
    for drop in (False, True):
        if drop:
            monkeypatch.delattr(os, "preadv")
        got = stream._read_cut((pos, cut), path=str(exported), threads=False)
        assert got.frames == want.frames and got.cols.keys() == want.cols.keys()
        assert all(np.array_equal(got.cols[k], want.cols[k], equal_nan=got.cols[k].dtype.kind == "f")
                   for k in want.cols)


_FORKS: list | None = None


def _at_fork() -> None:
    import threading

    if _FORKS is not None:
        _FORKS.append(sorted(t.name for t in threading.enumerate() if t is not threading.main_thread()))


def test_worker_processes_are_forked_before_the_digest_thread_starts(exported, monkeypatch):
    """No thread of the import runs when its worker processes are forked (a fork copies a thread's
    locks, not the thread): the input's SHA-256 starts after the first block came back."""
    import hashlib
    import os
    import time

    from aveas_format.converters.openlabel import stream

    global _FORKS
    if not hasattr(os, "register_at_fork"):
        pytest.skip("no os.register_at_fork on this platform")
    if not getattr(test_worker_processes_are_forked_before_the_digest_thread_starts, "hooked", False):
        os.register_at_fork(before=_at_fork)
        test_worker_processes_are_forked_before_the_digest_thread_starts.hooked = True
    from aveas_format.converters.common import provenance as common

    sha256 = common._sha256

    def slow_sha256(path, *args):  # (as on a large file: still hashing when the workers start)
        time.sleep(0.5)
        return sha256(path, *args)

    monkeypatch.setattr(common, "_sha256", slow_sha256)
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 3000)
    _FORKS = []
    try:
        rec, _, _ = _import(exported, monkeypatch, fast=True, workers=2)
        forks = _FORKS
    finally:
        _FORKS = None
    assert rec.states.num_rows and len(forks) >= 2
    assert not any(name.startswith("sha256") for names in forks for name in names), forks
    assert rec.meta.source.inputs[0].sha256 == hashlib.sha256(exported.read_bytes()).hexdigest()
