"""The streamed column encoder of the OpenLABEL export writes the same document as the writer it
replaced (one dict per state + ``json.dumps``, kept in ``openlabel_writer_v0``): equal after
parsing, on the rich recording and the demo scene, with orjson and with the standard library."""

from __future__ import annotations

import json

import pytest

from aveas_format.converters.openlabel import encode, write
from aveas_format.sample import highway_scene

from .openlabel_writer_v0 import recording_to_openlabel as v0_document


def _streamed(rec, **kw) -> dict:
    return json.loads(b"".join(write.openlabel_chunks(rec, opendrive="map.xodr", **kw)))


@pytest.fixture(scope="module")
def demo():
    return highway_scene(n_vehicles=8, duration_s=4.0)


@pytest.mark.parametrize("extension", [True, False])
def test_rich_recording_same_document(rich, extension):
    assert _streamed(rich, extension=extension) == v0_document(rich, opendrive="map.xodr", extension=extension)


def test_demo_same_document_in_small_chunks(demo):
    want = v0_document(demo, opendrive="map.xodr")
    got = _streamed(demo, chunk_rows=7)  # chunks end at frame boundaries whatever the size
    assert got == want
    assert list(got["openlabel"]) == list(want["openlabel"])  # the keys in today's order
    assert list(got["openlabel"]["frames"]) == list(want["openlabel"]["frames"])


def test_without_orjson_same_document(rich, monkeypatch):
    want = _streamed(rich)
    monkeypatch.setattr(encode, "orjson", None)
    assert _streamed(rich) == want


def test_numbers_keep_float32_values_and_null_nan():
    import numpy as np

    got = encode.numbers(np.array([0.3, np.nan, 1e-5], dtype=np.float32))
    assert [json.loads(b) for b in got] == [float(np.float32(0.3)), None, float(np.float32(1e-5))]
    assert encode.numbers(np.array([[1, 2], [3, 4]])) == [b"1,2", b"3,4"]


# --- the import's fast path: frames cut into blocks and parsed with orjson ----------------------

def _frames_of(path, monkeypatch, *, fast: bool, block: int = 1 << 20) -> list:
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_BLOCK", block)
    if not fast:
        monkeypatch.setattr(stream, "orjson", None)
    ol, frames = stream._stream_doc(path)
    out = list(frames())
    monkeypatch.undo()
    return out


def test_fast_frames_equal_ijson_frames_whatever_the_block(demo, tmp_path, monkeypatch):
    path = tmp_path / "d.json"
    path.write_bytes(b"".join(write.openlabel_chunks(demo)))
    want = _frames_of(path, monkeypatch, fast=False)
    assert len(want) == len(set(demo.states.column("time").to_pylist()))
    for block in (1 << 20, 3000, 50):  # one block, many, smaller than a frame
        assert _frames_of(path, monkeypatch, fast=True, block=block) == want


def test_fast_frames_hand_over_to_ijson_where_they_cannot_cut(tmp_path, monkeypatch):
    """A frame head inside a string, another layout after some frames, a repeated key, NaN: the
    frames are the streaming parser's (a repeated key inside one block comes once, with its last
    value: what the importer keeps either way)."""
    trap = ',"9":{"frame_properties":{"timestamp":0}'
    frames = {str(k): {"frame_properties": {"timestamp": k * 0.1},
                       "objects": {"1": {"object_data": {"text": [{"name": "note", "val": trap * (k % 2)}]}}}}
              for k in range(40)}
    frames["30"] = {"objects": frames["30"]["objects"], "frame_properties": {"timestamp": 3.0}}
    text = json.dumps({"openlabel": {"metadata": {"schema_version": "1.0.0"}, "frames": frames}},
                      separators=(",", ":"))
    text = text.replace('"frames":{', '"frames":{"5":{"objects":{}},', 1)  # repeated key (kept last)
    path = tmp_path / "g.json"
    path.write_text(text)
    want = _frames_of(path, monkeypatch, fast=False)
    assert len(want) == 41
    for block in (1 << 20, 700, 64):
        assert dict(_frames_of(path, monkeypatch, fast=True, block=block)) == dict(want)


def test_layout_templates_keep_bits_and_optional_items():
    """Rows of one layout: columns constant over the rows go into the template (by their bits:
    -0.0 stays -0.0), optional items and their commas only where present."""
    import numpy as np

    lay = encode._Layout(3)
    item = lay.mask(np.array([True, False, True]))
    segs = [b"[", lay.floats(np.array([0.0, -0.0, 0.0])), b",", lay.ints(np.array([7, 7, 7])), b"]",
            lay.join(b"{", [(True, [b'"a":', lay.floats(np.array([1.5, np.nan, 2.0]))]),
                            (item, [b'"b%":', lay.floats(np.full((3, 2), 0.25))])], b"}", empty=b"")]
    got = lay.rows(segs).tolist()
    assert got == [b'[0.0,7]{"a":1.5,"b%":0.25,0.25}', b'[-0.0,7]{"a":null}', b'[0.0,7]{"a":2.0,"b%":0.25,0.25}']


def test_layout_of_rows_with_no_varying_value_keeps_a_percent_sign():
    """A chunk whose values are the same in every row (one row, say) is written as its text, not
    as a template: a ``%`` in a name (an extension column's) stays one ``%`` (it came out doubled
    before)."""
    import numpy as np

    lay = encode._Layout(1)
    segs = [b'{"a%b":', lay.floats(np.array([1.5])), b',"c":', lay.ints(np.array([7])), b"}"]
    assert lay.rows(segs).tolist() == [b'{"a%b":1.5,"c":7}']


# --- the compiled assembler of the rows (numba, the jit extra): the same bytes as the % path ----

def _both_paths(rec, monkeypatch, **kw) -> tuple[bytes, bytes, int]:
    """The document by the Python path and by the compiled one, and how often the compiled
    assembler ran."""
    from aveas_format.converters.openlabel import _jitrows

    calls = []
    real = _jitrows.assemble
    monkeypatch.setattr(_jitrows, "assemble", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(encode, "COMPILED_MIN_ROWS", 10**12)
    py = b"".join(write.openlabel_chunks(rec, **kw))
    monkeypatch.setattr(encode, "COMPILED_MIN_ROWS", 0)
    compiled = b"".join(write.openlabel_chunks(rec, **kw))
    return py, compiled, len(calls)


@pytest.mark.parametrize("chunk_rows", [7, 300, None])
@pytest.mark.parametrize("extension", [True, False])
def test_compiled_rows_write_the_same_bytes(rich, demo, monkeypatch, chunk_rows, extension):
    """The rich recording (lights, interior signals, impact attributes, uncertainty, z, float32
    extension columns, a trailer) and the demo scene, in chunks of a few rows to whole frames."""
    pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
    from aveas_format.converters.openlabel import _jitrows

    for rec in (rich, demo):
        py, compiled, calls = _both_paths(rec, monkeypatch, chunk_rows=chunk_rows, extension=extension)
        assert calls > 0 and compiled == py
    # (one argument type each: numba compiles once per type, ~2 s)
    assert len(_jitrows.number_spans.signatures) == 1
    monkeypatch.undo()
    assert len(_jitrows.assemble.signatures) == 1


def test_compiled_rows_with_extension_columns_of_every_type(monkeypatch):
    """States columns the profile lacks, of each Arrow type the extension block writes: strings
    (with quotes, commas, brackets, a percent sign, non-ASCII), booleans, integers beyond
    2**53, float32, lists, nulls; numbers NaN, infinite, -0.0, subnormal, huge."""
    pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
    import numpy as np
    import pyarrow as pa

    from aveas_format.io.writer import prepare_table
    from aveas_format.schema.tables import TABLES

    rec = highway_scene(n_vehicles=5, duration_s=3.0, seed=2)
    s = rec.states
    n = s.num_rows
    rng = np.random.default_rng(0)
    odd = np.array([np.nan, np.inf, -np.inf, -0.0, 5e-324, 1.7976931348623157e308, 0.1, -3.0])
    s = s.append_column("note", pa.array([None if i % 5 == 0 else f'a"b,{i}]}}%s ü' for i in range(n)]))
    s = s.append_column("flag", pa.array([None if i % 4 == 0 else bool(i % 3) for i in range(n)]))
    s = s.append_column("count", pa.array([2**62 + i if i % 6 else None for i in range(n)], pa.int64()))
    s = s.append_column("gain", pa.array(rng.normal(size=n).astype(np.float32)))
    s = s.append_column("odd", pa.array(odd[np.arange(n) % len(odd)]))
    s = s.append_column("tags", pa.array([[i, i + 1] if i % 2 else [] for i in range(n)], pa.list_(pa.int32())))
    rec.replace_tables({"states": prepare_table(s, TABLES["states"])})
    py, compiled, calls = _both_paths(rec, monkeypatch, chunk_rows=50)
    assert calls > 0 and compiled == py
    frames = json.loads(compiled)["openlabel"]["frames"]
    ext = [o["object_data"]["cuboid"][0].get("aveas_format", {}) for f in frames.values()
           for o in f["objects"].values()]
    assert any("note" in e and "," in e["note"] for e in ext) and any(e.get("count", 0) > 2**62 for e in ext)


def _layout_case(draw_values, m: int, comma) -> tuple:
    """A layout of ``m`` rows from drawn values (see the hypothesis test), a comma before the
    rows where ``comma``."""
    import numpy as np

    lay = encode._Layout(m)
    segs: list = [lay.coded(np.array([b"", b","], dtype=object), comma.astype(np.int64)), b"{"]
    items = []
    for kind, data, mask in draw_values:
        if kind == "f":
            tok = lay.floats(np.array(data, dtype=np.float64).reshape(m, -1) if data and isinstance(data[0], list)
                             else np.array(data, dtype=np.float64))
        elif kind == "i":
            tok = lay.ints(np.array(data, dtype=np.int64))
        elif kind == "t":
            tok = lay.text([bytes(x) for x in data])
        elif kind == "c":
            tok = lay.coded(np.array([b"false", b"true", b'"x%s,y"'], dtype=object), np.array(data) % 3)
        else:
            tok = lay.floats(data)  # (a scalar: the same in every row)
        items.append((lay.mask(None if mask is None else np.array(mask, dtype=bool)), [b'"k%":', tok]))
    segs.append(lay.join(b"[", items, b"]", empty=b"E"))
    segs.append(lay.join(b",(", items[::-1], b")"))
    segs.append(b"}")
    return lay, segs


def test_compiled_layout_equals_the_python_layout():
    """Any values, masks and row counts: the compiled assembler's text is the % path's, byte
    for byte (numbers of every kind, vectors, fragments with commas and brackets,
    items present in some rows, lists empty in some)."""
    pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
    import numpy as np
    from hypothesis import given, settings
    from hypothesis import strategies as st

    floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([-0.0, 0.0, 5e-324, 1e22]))
    ints = st.integers(-(2**63), 2**63 - 1)

    @st.composite
    def cases(draw):
        m = draw(st.integers(0, 12))
        values = []
        for _ in range(draw(st.integers(0, 6))):
            kind = draw(st.sampled_from("fivtcs"))
            mask = draw(st.one_of(st.none(), st.lists(st.booleans(), min_size=m, max_size=m)))
            if kind == "f":
                data = draw(st.lists(floats, min_size=m, max_size=m))
            elif kind == "v":
                w = draw(st.integers(1, 4))
                data = [draw(st.lists(floats, min_size=w, max_size=w)) for _ in range(m)]
                kind = "f"
            elif kind == "i":
                small = draw(st.booleans())
                data = draw(st.lists(st.integers(-5, 70000) if small else ints, min_size=m, max_size=m))
            elif kind == "t":
                data = draw(st.lists(st.binary(max_size=6), min_size=m, max_size=m))
            elif kind == "c":
                data = draw(st.lists(st.integers(0, 2), min_size=m, max_size=m))
            else:
                data = draw(floats)
            values.append((kind, data, mask))
        comma = draw(st.lists(st.booleans(), min_size=m, max_size=m))
        return m, values, np.array(comma, dtype=bool)

    @settings(max_examples=300, deadline=None)
    @given(cases())
    def check(case):
        m, values, comma = case
        lay, segs = _layout_case(values, m, comma)
        want = lay.packed(segs, False)
        lay, segs = _layout_case(values, m, comma)
        assert bytes(lay.packed(segs, True)) == want

    check()


def test_compiled_rows_without_orjson_write_the_same_bytes(rich, monkeypatch):
    """The standard library's numbers (``1e-05``, ``NaN`` written as null) scanned by the
    compiled path as orjson's are."""
    pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
    monkeypatch.setattr(encode, "orjson", None)
    py, compiled, calls = _both_paths(rich, monkeypatch, chunk_rows=50)
    assert calls > 0 and compiled == py
