"""The streamed column encoder of the OpenLABEL export writes the same document as the writer it
replaced (one dict per state + ``json.dumps``, kept in ``openlabel_writer_v0``): equal after
parsing, on the rich recording and the demo scene, with orjson and with the standard library."""

from __future__ import annotations

import json

import pytest

from aveas_format.converters.openlabel import write
from aveas_format.io import jsontext
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
    monkeypatch.setattr(jsontext, "orjson", None)
    assert _streamed(rich) == want


# --- odd values: what the export writes is what json.loads reads --------------------------------

def test_extension_columns_of_every_type_round_trip(tmp_path):
    """States columns the profile lacks, of each Arrow type the extension block writes: strings
    (with quotes, commas, brackets, a percent sign, non-ASCII), booleans, integers beyond
    2**53, float32, lists, nulls; numbers NaN, infinite, -0.0, subnormal, huge: the file parses
    with json.loads and the import gives the columns back as they were (NaN and infinities as
    null: JSON has neither)."""
    import numpy as np
    import pyarrow as pa

    from aveas_format.converters import convert, get_converter
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
    out = tmp_path / "odd.json"
    get_converter("openlabel", "export")(rec, out, options={"workers": 1})
    frames = json.loads(out.read_bytes())["openlabel"]["frames"]
    ext = [o["object_data"]["cuboid"][0].get("aveas_format", {}) for f in frames.values()
           for o in f["objects"].values()]
    assert any("note" in e and "," in e["note"] for e in ext) and any(e.get("count", 0) > 2**62 for e in ext)
    back = convert("openlabel", [out]).states
    want = rec.states
    for c in ("note", "flag", "count", "gain", "tags"):
        assert back.column(c).cast(want.column(c).type).to_pylist() == want.column(c).to_pylist(), c
    got, ref = back.column("odd").to_numpy(zero_copy_only=False), want.column("odd").to_numpy()
    fin = np.isfinite(ref)  # (JSON has no NaN or infinity: null, as the profile's values)
    np.testing.assert_array_equal(got[fin], ref[fin])
    np.testing.assert_array_equal(np.signbit(got[fin]), np.signbit(ref[fin]))
    assert back.column("odd").is_null().to_numpy(zero_copy_only=False)[~fin].all()
