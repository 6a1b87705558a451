"""The columnar Protocol Buffers encoder (converters/_protowire.py) against protobuf's own."""

from __future__ import annotations

import numpy as np
from google.protobuf.internal.encoder import _VarintBytes
from hypothesis import given
from hypothesis import strategies as st

from aveas_format.converters import _protowire as pw


@given(st.lists(st.integers(min_value=-(2**63), max_value=2**63 - 1), max_size=40))
def test_varints_are_protobufs(values):
    got = pw.varints(np.array(values, np.int64)).tolist()
    assert got == [_VarintBytes(v if v >= 0 else v + 2**64) for v in values]


@given(st.lists(st.binary(max_size=20), min_size=1, max_size=30),
       st.lists(st.binary(max_size=5), min_size=1, max_size=30), st.data())
def test_concat_keep_group(a, c, data):
    n = min(len(a), len(c))
    a, c = a[:n], c[:n]

    def ragged(rows):
        return pw.Ragged(np.frombuffer(b"".join(rows), np.uint8).copy(),
                         np.array([len(r) for r in rows], np.int64))

    assert pw.concat(ragged(a), ragged(c)).tolist() == [x + y for x, y in zip(a, c)]
    mask = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    assert pw.keep(ragged(a), mask).tolist() == [x if m else b"" for x, m in zip(a, mask)]
    cuts = sorted(data.draw(st.lists(st.integers(0, n), min_size=2, max_size=6)))
    assert pw.group(ragged(a), np.array(cuts)).tolist() == [b"".join(a[i:j])
                                                             for i, j in zip(cuts[:-1], cuts[1:])]


def test_fields_decode_with_protobuf():
    from google.protobuf.struct_pb2 import Value

    # Value: number_value = 2 (double), string_value = 3
    raw = pw.concat(pw.f_double(2, np.array([1.5, -0.25]))).tolist()
    assert [Value.FromString(r).number_value for r in raw] == [1.5, -0.25]
    raw = pw.f_strings(3, ["a", "é" * 200]).tolist()
    assert [Value.FromString(r).string_value for r in raw] == ["a", "é" * 200]
    framed = pw.length_prefixed(pw.f_double(2, np.array([3.0])))
    assert framed[:4] == (9).to_bytes(4, "little") and Value.FromString(framed[4:]).number_value == 3.0


@given(st.lists(st.tuples(st.binary(max_size=9), st.binary(min_size=2, max_size=2), st.binary(max_size=4)),
                min_size=1, max_size=25))
def test_nested_concats_lay_out_their_leaves_once(rows):
    """Concatenations inside length-prefixed fields inside concatenations (laid out lazily, each
    leaf copied once into the final buffer) give the bytes of the eager, level-by-level layout —
    also where a part's rows vary in width but add up to a fixed-width total."""
    def ragged(parts):
        return pw.Ragged(np.frombuffer(b"".join(parts), np.uint8).copy(),
                         np.array([len(p) for p in parts], np.int64))

    a, b, c = (ragged([r[k] for r in rows]) for k in range(3))
    inner = pw.concat(a, b)
    outer = pw.concat(c, pw.f_message(3, inner), a, pw.f_message(4, pw.concat(b, inner)))

    def msg(field, body):
        return pw.key(field, pw.LEN) + pw.varint_bytes(len(body)) + body

    want = [z + msg(3, x + y) + x + msg(4, y + x + y) for x, y, z in rows]
    assert outer.tolist() == want
    assert pw.group(outer, np.array([0, len(rows)])).tolist() == [b"".join(want)]
