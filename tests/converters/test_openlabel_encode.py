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
