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
