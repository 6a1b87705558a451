"""The per-segment median of the uncertainty rules against ``np.median`` of each segment's values
(NaN dropped), with segments in runs (the states view's) or scattered, infinite values and ties."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.validate.rules.uncertainty import seg_median

_VALUES = st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")), st.just(float("inf")),
                    st.just(float("-inf")), st.sampled_from([0.0, 1.0, 2.5]))


def _reference(seg, vals):
    """Each segment with a value that is not NaN, and ``np.median`` of its values."""
    ok = ~np.isnan(vals)
    segs = np.unique(seg[ok])
    with np.errstate(invalid="ignore"):  # (inf - inf in a middle pair: NaN, as np.median says)
        return segs, np.array([np.median(vals[ok & (seg == s)]) for s in segs])


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 6), _VALUES), max_size=60), st.booleans())
def test_the_median_of_each_segment(pairs, runs):
    seg = np.asarray([s for s, _ in pairs], np.int64)
    vals = np.asarray([v for _, v in pairs], np.float64)
    if runs:  # (the states view's segments: non-decreasing)
        order = np.argsort(seg, kind="stable")
        seg, vals = seg[order], vals[order]
    want = _reference(seg, vals)
    with np.errstate(invalid="ignore"):
        got = seg_median(seg, vals)
    assert got[0].dtype == seg.dtype or not len(got[0])
    assert np.array_equal(got[0], want[0])
    assert np.array_equal(got[1], want[1], equal_nan=True)


def test_runs_and_scattered_segments_of_a_large_array():
    rng = np.random.default_rng(5)
    seg = np.sort(rng.integers(-3, 300, 50_000))
    vals = rng.normal(size=50_000)
    vals[::11] = np.nan
    vals[::17] = 0.1  # ties, as a constant stated std gives
    want = _reference(seg, vals)
    for order in (np.arange(len(seg)), rng.permutation(len(seg))):
        got = seg_median(seg[order], vals[order])
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
