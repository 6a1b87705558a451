"""The per-segment median of the uncertainty rules: the compiled path (one selection per run of a
segment) gives the NumPy path's numbers (one sort by segment and value), runs or not."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.validate.rules.uncertainty import seg_median

pytest.importorskip("numba", reason="numba is not installed (the jit extra)")

_VALUES = st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")), st.just(float("inf")), st.just(float("-inf")),
                    st.sampled_from([0.0, 1.0, 2.5]))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), _VALUES), max_size=60), st.booleans())
def test_both_paths_give_the_same_medians(pairs, runs):
    seg = np.asarray([s for s, _ in pairs], np.int64)
    vals = np.asarray([v for _, v in pairs], np.float64)
    if runs:  # (the states view's segments: non-decreasing)
        order = np.argsort(seg, kind="stable")
        seg, vals = seg[order], vals[order]
    with np.errstate(invalid="ignore"):  # (inf - inf in a middle pair: NaN on both paths)
        want = seg_median(seg, vals, "numpy")
        got = seg_median(seg, vals, "numba")
    assert np.array_equal(got[0], want[0])
    assert np.array_equal(got[1], want[1], equal_nan=True)


def test_runs_of_a_large_array():
    rng = np.random.default_rng(5)
    seg = np.sort(rng.integers(0, 300, 50_000))
    vals = rng.normal(size=50_000)
    vals[::11] = np.nan
    want, got = seg_median(seg, vals, "numpy"), seg_median(seg, vals, "numba")
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    s = seg[~np.isnan(vals)]
    assert got[1][0] == np.median(vals[~np.isnan(vals)][s == got[0][0]])
