"""The shared array helpers of aveas_format.numeric (foundation layer)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.numeric import central_differences, fmt_num, wrap_angle


@given(st.lists(st.floats(-1e4, 1e4), min_size=1, max_size=50))
def test_wrap_angle_range_and_identity(a):
    w = wrap_angle(np.array(a))
    assert ((w > -np.pi) & (w <= np.pi)).all()
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-9)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-9)


def test_wrap_angle_boundary_is_plus_pi():
    assert wrap_angle(-np.pi) == np.pi and wrap_angle(np.pi) == np.pi and wrap_angle(3 * np.pi) == np.pi


@st.composite
def uneven_tracks(draw):
    """Two or three participants, each with 1-30 samples at uneven, strictly increasing times."""
    k = draw(st.integers(1, 3))
    pid, t = [], []
    for p in range(k):
        n = draw(st.integers(1, 30))
        steps = draw(st.lists(st.floats(0.01, 2.0), min_size=n, max_size=n))
        pid += [p] * n
        t += list(np.cumsum(steps))
    return np.array(pid), np.array(t)


@settings(max_examples=200)
@given(tracks=uneven_tracks(), a=st.floats(-5, 5), v0=st.floats(-40, 40), x0=st.floats(-1e3, 1e3))
def test_exact_for_constant_acceleration_on_uneven_sampling(tracks, a, v0, x0):
    pid, t = tracks
    x = x0 + v0 * t + 0.5 * a * t**2
    vx, vy, _, _ = central_differences(pid, t, x, -x)
    starts = np.r_[True, pid[1:] != pid[:-1]]
    ends = np.r_[pid[1:] != pid[:-1], True]
    inner = ~starts & ~ends
    truth = v0 + a * t
    np.testing.assert_allclose(vx[inner], truth[inner], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(vy, -vx)
    single = starts & ends
    assert (vx[single] == 0).all()


@settings(max_examples=100)
@given(tracks=uneven_tracks(), seed=st.integers(0, 2**31))
def test_equals_numpy_gradient_per_participant(tracks, seed):
    pid, t = tracks
    x = np.random.default_rng(seed).normal(size=len(t)).cumsum()
    vx, _, _, _ = central_differences(pid, t, x, x)
    for p in np.unique(pid):
        m = pid == p
        if m.sum() >= 2:
            np.testing.assert_allclose(vx[m], np.gradient(x[m], t[m]), rtol=1e-9, atol=1e-9)


@settings(max_examples=50)
@given(tracks=uneven_tracks(), seed=st.integers(0, 2**31))
def test_without_std_the_same_derivatives(tracks, seed):
    """``std=False`` (the export's accelerations): the same derivatives, bit for bit, no std."""
    pid, t = tracks
    rng = np.random.default_rng(seed)
    x, y, sx = rng.normal(size=(3, len(t)))
    vx, vy, _, _ = central_differences(pid, t, x, y, abs(sx), abs(sx))
    wx, wy, a, b = central_differences(pid, t, x, y, abs(sx), abs(sx), std=False)
    assert a is None and b is None
    assert np.array_equal(vx, wx, equal_nan=True) and np.array_equal(vy, wy, equal_nan=True)


def test_std_propagates_independent_errors():
    """Monte Carlo over position noise agrees with the analytic std on uneven sampling."""
    rng = np.random.default_rng(3)
    t = np.array([0.0, 0.1, 0.35, 0.4, 0.9])
    pid = np.zeros(5, int)
    sx = np.array([0.1, 0.2, 0.05, 0.3, 0.1])
    _, _, std, _ = central_differences(pid, t, np.zeros(5), np.zeros(5), sx, sx)
    draws = np.array([central_differences(pid, t, rng.normal(0, sx), np.zeros(5))[0]
                      for _ in range(20000)])
    np.testing.assert_allclose(draws.std(axis=0), std, rtol=0.03)


def test_even_sampling_gives_the_classic_central_difference():
    t = np.arange(6) * 0.1
    x = np.array([0.0, 1.0, 4.0, 9.0, 16.0, 25.0])
    vx, _, std, _ = central_differences(np.zeros(6), t, x, x, np.full(6, 0.1), None)
    np.testing.assert_allclose(vx[1:-1], (x[2:] - x[:-2]) / 0.2)
    np.testing.assert_allclose(std[1:-1], np.hypot(0.1, 0.1) / 0.2)
    np.testing.assert_allclose([vx[0], vx[-1]], [(x[1] - x[0]) / 0.1, (x[-1] - x[-2]) / 0.1])


def test_repeated_times_and_single_samples():
    pid = np.array([0, 0, 0, 1])
    t = np.array([0.0, 0.0, 1.0, 5.0])
    x = np.array([0.0, 0.0, 2.0, 7.0])
    vx, _, std, _ = central_differences(pid, t, x, x, np.full(4, 0.1), None)
    assert vx.tolist() == [0.0, 2.0, 2.0, 0.0]
    assert np.isnan(std[0]) and np.isnan(std[3])


@pytest.mark.parametrize("value,text", [
    (6.6000000000000005, "6.6"), (25.080000000000002, "25.08"), (0.1 + 0.2, "0.3"), (1.0, "1.0"),
    (691234.5678, "691234.57"), (1646667310.044372, "1646667310.04"), (5e-07, "0.0000005"),
    (-0.000123456, "-0.000123456"), (0.0, "0.0"), (3.123456789e20, "3.12346e+20"), (7, "7"),
    (np.float32(0.1), "0.1"), (np.int64(3), "3"), (float("nan"), "nan"), ("x", "x"), (True, "True"),
])
def test_numbers_in_messages_are_rounded_for_people(value, text):
    assert fmt_num(value) == text


def test_keyed_normals_depend_on_the_keys_only():
    """The draws of an element are the same in any batch; standard normal and uncorrelated
    across draws and elements."""
    from scipy import stats

    from aveas_format.numeric import keyed_normals

    a, b = np.arange(4000), np.arange(4000) * 7 + 3
    z = keyed_normals(5, (a, b), 33)
    assert z.shape == (33, 4000)
    np.testing.assert_array_equal(keyed_normals(5, (a[[17, 3]], b[[17, 3]]), 33), z[:, [17, 3]])
    assert not np.array_equal(keyed_normals(6, (a, b), 33), z)
    assert not np.array_equal(keyed_normals(5, (b, a), 33), z)
    assert stats.kstest(z.ravel(), "norm").pvalue > 1e-3
    c = np.corrcoef(z)
    assert np.abs(c[np.triu_indices(33, 1)]).max() < 0.08


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 40), st.integers(1, 30), st.integers(0, 2**32 - 1))
def test_finite_quantiles_equal_nanquantile(k, m, seed):
    """The vectorised quantiles of the finite values are np.nanquantile's, bit for bit (with
    infinities and all-NaN columns)."""
    import warnings

    from aveas_format.numeric import finite_quantiles

    rng = np.random.default_rng(seed)
    a = rng.standard_cauchy((k, m))
    a[rng.random((k, m)) < rng.random(m)] = np.nan
    a[rng.random((k, m)) < 0.1] = np.inf
    a[rng.random((k, m)) < 0.05] = -np.inf
    qs = (0.0, 0.25, 0.5, 0.75, 0.9, 1.0)
    got = finite_quantiles(a, qs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for q, g in zip(qs, got):
            ref = (np.nanquantile(np.where(np.isfinite(a), a, np.nan), q, axis=0) if k
                   else np.full(m, np.nan))
            np.testing.assert_array_equal(g, ref)
