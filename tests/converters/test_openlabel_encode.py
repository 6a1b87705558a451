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


# --- odd values: what the layout writes is what json.loads reads --------------------------------

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


def test_layout_rows_are_what_json_loads_reads():
    """Any values, masks and row counts: each row of a layout parses with json.loads to the values
    it was given (numbers of every kind, NaN and infinities as null, vectors, texts, items present
    in some rows only, lists empty in some)."""
    import math

    import numpy as np
    from hypothesis import given, settings
    from hypothesis import strategies as st

    floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([-0.0, 0.0, 5e-324, 1e22]))
    ints = st.integers(-(2**63), 2**63 - 1)

    def as_json(v):
        return None if isinstance(v, float) and not math.isfinite(v) else v

    @st.composite
    def cases(draw):
        m = draw(st.integers(0, 12))
        values = []
        for _ in range(draw(st.integers(0, 6))):
            kind = draw(st.sampled_from("fvit"))
            mask = draw(st.one_of(st.none(), st.lists(st.booleans(), min_size=m, max_size=m)))
            if kind == "f":
                data = draw(st.lists(floats, min_size=m, max_size=m))
            elif kind == "v":
                w = draw(st.integers(1, 4))
                data = [draw(st.lists(floats, min_size=w, max_size=w)) for _ in range(m)]
            elif kind == "i":
                data = draw(st.lists(st.one_of(st.integers(-5, 70000), ints), min_size=m, max_size=m))
            else:
                data = draw(st.lists(st.text(max_size=6), min_size=m, max_size=m))
            values.append((kind, data, mask))
        return m, values

    @settings(max_examples=300, deadline=None)
    @given(cases())
    def check(case):
        m, values = case
        lay = encode._Layout(m)
        items = []
        for k, (kind, data, mask) in enumerate(values):
            if kind == "f":
                tok = [lay.floats(np.array(data, dtype=np.float64))]
            elif kind == "v":
                tok = [b"[", lay.floats(np.array(data, dtype=np.float64).reshape(m, len(data[0]) if m else 1)), b"]"]
            elif kind == "i":
                tok = [lay.ints(np.array(data, dtype=np.int64))]
            else:
                tok = [lay.text(encode.texts(data))]
            items.append((lay.mask(None if mask is None else np.array(mask, dtype=bool)),
                          [b'{"k%d":' % k, *tok, b"}"]))
        rows = lay.rows([b'{"a":', lay.join(b"[", items, b"]"), b"}"]).tolist()
        for i, row in enumerate(rows):
            want = [{f"k{k}": [as_json(x) for x in data[i]] if kind == "v" else as_json(data[i])}
                    for k, (kind, data, mask) in enumerate(values) if mask is None or mask[i]]
            got = json.loads(row)["a"]
            assert got == want
            assert [math.copysign(1, x) for d in got for v in d.values() for x in (v if isinstance(v, list) else [v])
                    if isinstance(x, float) and x == 0] == \
                   [math.copysign(1, x) for d in want for v in d.values() for x in (v if isinstance(v, list) else [v])
                    if isinstance(x, float) and x == 0]

    check()
