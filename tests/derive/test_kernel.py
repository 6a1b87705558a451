"""The follower/leader metrics on their two paths: the fused numba kernel gives the NumPy path's
numbers (to a few units in the last place) on random pairs and on every degenerate kind of pair,
and the path is chosen in one place (``aveas_format.numeric.kernel_backend``)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from aveas_format import numeric
from aveas_format.derive.interactions._ttc import follower_leader_metrics
from aveas_format.numeric import kernel_backend

from helpers_common import KERNEL_BACKENDS

NUMBA = KERNEL_BACKENDS[1]


def _pairs(seed: int = 3) -> tuple:
    """Random pairs, then every combination of degenerate values: contact and negative gaps,
    zero closing speed (equal speeds), standing, reversing and stopping vehicles, NaN and
    infinite inputs and variances."""
    rng = np.random.default_rng(seed)
    n = 20_000
    vf = rng.uniform(0, 40, n)
    cols = [rng.uniform(-2, 80, n), rng.uniform(0, 0.5, n), rng.uniform(3, 6, n),
            vf, rng.normal(0, 2, n), rng.uniform(0, 0.1, n), rng.uniform(0, 0.2, n),
            vf - rng.normal(1, 3, n), rng.normal(0, 3, n), rng.uniform(0, 0.1, n),
            rng.uniform(0, 0.2, n)]
    grid = list(itertools.product([-1.0, 0.0, 1e-9, 5.0, 80.0, np.nan],   # gap
                                  [0.0, 10.0, 30.0, -1.0, np.nan],       # follower speed
                                  [-3.0, 0.0, 1.0, np.nan],              # follower acceleration
                                  [0.0, 10.0, 30.0, np.nan],             # leader speed
                                  [-8.0, 0.0, 2.0, np.inf]))             # leader acceleration
    g, v_f, a_f, v_l, a_l = (np.array(c) for c in zip(*grid))
    m = len(g)
    var = rng.choice([0.0, 0.04, np.nan, np.inf], (6, m), p=[0.4, 0.4, 0.1, 0.1])
    degenerate = [g, var[0], np.full(m, 4.5), v_f, a_f, var[1], var[2], v_l, a_l, var[3], var[4]]
    args = [np.concatenate([a, b]) for a, b in zip(cols, degenerate)]
    return args[:3], tuple(args[3:7]), tuple(args[7:])


@pytest.mark.parametrize("backend", [NUMBA])
def test_numba_equals_numpy(backend):
    (g, gv, ll), fol, lead = _pairs()
    a = follower_leader_metrics(g, gv, ll, fol, lead, 1.0, 3.4, backend="numpy")
    b = follower_leader_metrics(g, gv, ll, fol, lead, 1.0, 3.4, backend=backend)
    assert list(a) == list(b)
    worst = {}
    for k in a:
        x, y = a[k], b[k]
        assert np.array_equal(np.isnan(x), np.isnan(y)), k
        assert np.array_equal(np.isposinf(x), np.isposinf(y)), k
        assert np.array_equal(np.isneginf(x), np.isneginf(y)), k
        f = np.isfinite(x)
        rel = np.abs(x[f] - y[f]) / np.maximum(np.abs(x[f]), 1e-300)
        worst[k] = rel.max(initial=0.0)
    assert max(worst.values()) <= 1e-12, worst
    # the degenerate kinds are in the sample, on both paths alike
    assert np.isnan(a["ttc_ca"]).any() or np.isinf(a["ttc_ca"]).any()
    assert (a["ttc_ca"] == 0).any() and np.isnan(a["drac"]).any() and (a["ttc_ca_std"] == 0).any()


@pytest.mark.slow  # compiles the prange loop (several seconds on a fresh checkout); bench only
@pytest.mark.parametrize("backend", [NUMBA])
def test_parallel_equals_serial(backend):
    from aveas_format.derive.interactions import _kernel

    (g, gv, ll), fol, lead = _pairs(seed=4)
    args = [g, gv, ll, *fol, *lead]
    a = _kernel.metrics(args, 1.0, 3.4)
    b = _kernel.metrics(args, 1.0, 3.4, parallel=True)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


@pytest.mark.parametrize("backend", KERNEL_BACKENDS)
def test_shapes_and_pass_through(backend):
    """Scalars broadcast; ``gap`` and ``gap_var`` are the inputs; no pairs, empty outputs."""
    g = np.array([10.0, 20.0])
    gv = np.array([0.1, 0.2])
    m = follower_leader_metrics(g, gv, 4.5, (20.0, 0.0, 0.01, 0.0), (15.0, 0.0, 0.01, 0.0),
                                backend=backend)
    assert m["gap"] is g and m["gap_var"] is gv
    np.testing.assert_allclose(m["ttc"], [2.0, 4.0])
    np.testing.assert_allclose(m["dhw"], [14.5, 24.5])
    e = follower_leader_metrics(np.zeros(0), np.zeros(0), np.zeros(0), (np.zeros(0),) * 4,
                                (np.zeros(0),) * 4, backend=backend)
    assert set(e) == set(m) and all(len(v) == 0 for v in e.values())


def test_backend_choice(monkeypatch):
    monkeypatch.delenv(numeric.KERNEL_ENV, raising=False)
    assert kernel_backend("numpy") == "numpy"
    monkeypatch.setenv(numeric.KERNEL_ENV, "numpy")
    assert kernel_backend() == "numpy"
    monkeypatch.setenv(numeric.KERNEL_ENV, "fortran")
    with pytest.raises(ValueError, match="'fortran'.*AVEAS_FORMAT_KERNEL.*auto, numpy or numba"):
        kernel_backend()
    monkeypatch.setattr(numeric, "_HAS_NUMBA", False)
    monkeypatch.delenv(numeric.KERNEL_ENV)
    assert kernel_backend() == "numpy"
    with pytest.raises(ImportError, match=r"aveas-format\[jit\]"):
        kernel_backend("numba")
    monkeypatch.setattr(numeric, "_HAS_NUMBA", True)
    assert kernel_backend() == "numba" == kernel_backend("auto")
