"""JSON text of columns (io/jsontext.py): numbers keep their values, templates their bits, and
each row of a layout is what ``json.loads`` reads back to the values it was given. (The OpenLABEL
export through it: tests/converters/test_openlabel_encode.py.)"""

from __future__ import annotations

import json

from aveas_format.io.jsontext import Layout, numbers, texts


def test_numbers_keep_float32_values_and_null_nan():
    import numpy as np

    got = numbers(np.array([0.3, np.nan, 1e-5], dtype=np.float32))
    assert [json.loads(b) for b in got] == [float(np.float32(0.3)), None, float(np.float32(1e-5))]
    assert numbers(np.array([[1, 2], [3, 4]])) == [b"1,2", b"3,4"]


def test_layout_templates_keep_bits_and_optional_items():
    """Rows of one layout: columns constant over the rows go into the template (by their bits:
    -0.0 stays -0.0), optional items and their commas only where present."""
    import numpy as np

    lay = Layout(3)
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

    lay = Layout(1)
    segs = [b'{"a%b":', lay.floats(np.array([1.5])), b',"c":', lay.ints(np.array([7])), b"}"]
    assert lay.rows(segs).tolist() == [b'{"a%b":1.5,"c":7}']


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
        lay = Layout(m)
        items = []
        for k, (kind, data, mask) in enumerate(values):
            if kind == "f":
                tok = [lay.floats(np.array(data, dtype=np.float64))]
            elif kind == "v":
                tok = [b"[", lay.floats(np.array(data, dtype=np.float64).reshape(m, len(data[0]) if m else 1)), b"]"]
            elif kind == "i":
                tok = [lay.ints(np.array(data, dtype=np.int64))]
            else:
                tok = [lay.text(texts(data))]
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
