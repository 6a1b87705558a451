"""Kinematics, ``jerk_density="auto"``: the maximum-likelihood choice of the process noise (coarse
grid, bisection, parabola), the tabulated fast pass against the full recursion, and the calibration
of the standard deviations where the truth is a white-jerk process of any intensity."""

from __future__ import annotations

import numpy as np
import pytest

import aveas_format.derive.kinematics._jerk_density as jd
import aveas_format.derive.kinematics._smoother as smoother
from aveas_format.derive.kinematics import KinematicsParams, estimate


def _white_jerk(q: float, n: int = 1500, tracks: int = 20, seed: int = 1, dt: float = 0.04,
                std: float = 0.1) -> dict[str, np.ndarray]:
    """Tracks whose acceleration is a random walk (white jerk of density ``q`` per axis)."""
    rng = np.random.default_rng(seed)
    j = rng.normal(0, np.sqrt(q / dt), (tracks, n, 2))
    a = np.cumsum(j, 1) * dt
    a -= a.mean(1, keepdims=True)
    v = np.cumsum(a, 1) * dt + np.array([30.0, 0.0])
    pos = np.cumsum(v, 1) * dt
    m = tracks * n
    return {"pid": np.repeat(np.arange(tracks), n), "t": np.tile(np.arange(n) * dt, tracks),
            "x": pos[..., 0].ravel() + rng.normal(0, std, m),
            "y": pos[..., 1].ravel() + rng.normal(0, std, m),
            "ax": a[..., 0].ravel(), "ay": a[..., 1].ravel()}


def _run(d: dict[str, np.ndarray], std: float = 0.1, **kw) -> dict[str, np.ndarray]:
    n = len(d["t"])
    return estimate(d["pid"], d["t"], d["x"], d["y"], np.full(n, std), np.full(n, std),
                    np.zeros(n), None, KinematicsParams(**kw))


def _coverage(d: dict[str, np.ndarray], r: dict[str, np.ndarray]) -> float:
    return float(np.mean(np.r_[np.abs(r["ax"] - d["ax"]) <= r["ax_std"],
                               np.abs(r["ay"] - d["ay"]) <= r["ay_std"]]))


@pytest.mark.parametrize("q", [0.003, 0.5])
def test_auto_std_calibrated_for_any_intensity(q):
    """The ML density (decades, one bisection, parabola) is unbiased enough that the 1-sigma band
    covers a white-jerk truth ~68 % of the time, across two decades of intensity."""
    d = _white_jerk(q)
    assert 0.62 <= _coverage(d, _run(d)) <= 0.74


def test_auto_recovers_the_density():
    """Per window the ML density is within a factor 2 of the truth (windows of 1,024 samples)."""
    d = _white_jerk(0.2, n=1024, tracks=12)
    captured = {}
    orig = smoother.ml_jerk_density

    def spy(*a, **k):
        captured["q"] = orig(*a, **k)
        return captured["q"]

    smoother.ml_jerk_density = spy
    try:
        _run(d)
    finally:
        smoother.ml_jerk_density = orig
    q = captured["q"]
    assert q.shape == (12, 2)
    assert np.all(np.abs(np.log(q / 0.2)) < np.log(2.0))


def test_auto_goes_below_the_old_floor_on_constant_acceleration():
    """A track with constant acceleration (no jerk) takes a density far below 0.01 m²/s⁵, so its
    std shrinks to what the data support instead of being set by the grid's floor."""
    t = np.arange(750) * 0.04
    rng = np.random.default_rng(5)
    d = {"pid": np.zeros(len(t), np.int64), "t": t,
         "x": 25 * t + 0.3 * t * t + rng.normal(0, 0.1, len(t)),
         "y": rng.normal(0, 0.1, len(t)), "ax": np.full(len(t), 0.6), "ay": np.zeros(len(t))}
    r = _run(d)
    mid = slice(100, 650)
    assert np.median(r["ax_std"][mid]) < 0.01
    assert np.max(np.abs(r["ax"][mid] - 0.6)) < 0.05
    fixed = _run(d, jerk_density=0.01)
    assert np.median(r["ax_std"][mid]) < 0.3 * np.median(fixed["ax_std"][mid])


def test_fast_pass_equals_full_recursion(monkeypatch):
    """Rows with one step and one noise variance use tabulated gains; the result equals the full
    recursion (forced here on every row), including windows, padding and short segments."""
    rng = np.random.default_rng(1)
    lens = rng.integers(3, 300, 40)
    pid = np.repeat(np.arange(40), lens)
    t = np.concatenate([np.arange(m) * 0.04 for m in lens])
    x = 20 * t + 0.3 * t ** 2 + rng.normal(0, 0.1, len(t))
    y = np.sin(0.5 * t) + rng.normal(0, 0.1, len(t))
    d = {"pid": pid, "t": t, "x": x, "y": y}
    kw = dict(batch_rows=7, window_steps=100, overlap_steps=20)
    fast = _run(d, **kw)
    monkeypatch.setattr(jd, "_regular_rows",
                        lambda dt, r, first, valid: (np.zeros(first.shape[1], bool), 0.0, 0.0))
    full = _run(d, **kw)
    for c in fast:
        # jerk_lon_std is the root of Var(a[k+1]) + Var(a[k]) - 2 Cov: where q -> 0 (no jerk) the
        # two passes' rounding differs by ~1e-6 m/s³ in it (variances ~1e-4, difference ~1e-12)
        atol = 1e-5 if c == "jerk_lon_std" else 1e-8
        assert np.allclose(fast[c], full[c], rtol=1e-6, atol=atol, equal_nan=True), c


def test_mixed_regular_and_irregular_rows(monkeypatch):
    """Irregular sampling or a varying std sends a row to the full recursion while the others
    stay on the fast pass; each track's result equals the one computed alone."""
    calls = {"fast": 0, "full": 0}
    for name, key in (("_ca_window_loglik_regular", "fast"), ("_ca_window_loglik", "full")):
        def counted(*a, _f=getattr(jd, name), _k=key, **k):
            calls[_k] += 1
            return _f(*a, **k)
        monkeypatch.setattr(jd, name, counted)
    rng = np.random.default_rng(2)
    parts = []
    for i in range(6):
        n = 400
        t = np.arange(n) * 0.04
        if i % 3 == 1:
            t = np.cumsum(rng.uniform(0.02, 0.06, n))  # irregular
        std = np.full(n, 0.1) if i % 3 != 2 else rng.uniform(0.05, 0.2, n)  # varying noise
        x = 20 * t + 0.2 * np.sin(t) + rng.normal(0, 1, n) * std
        y = 0.1 * t * t + rng.normal(0, 1, n) * std
        parts.append((np.full(n, i), t, x, y, std))
    cat = [np.concatenate(c) for c in zip(*parts)]
    pid, t, x, y, std = cat
    p = KinematicsParams()  # one track per row
    both = estimate(pid, t, x, y, std, std, np.zeros(len(t)), None, p)
    assert calls["fast"] > 0 and calls["full"] > 0
    for i, (pi, ti, xi, yi, si) in enumerate(parts):
        alone = estimate(pi, ti, xi, yi, si, si, np.zeros(len(ti)), None, p)
        for c in ("ax", "ay", "ax_std", "speed"):
            assert np.allclose(both[c][pid == i], alone[c], rtol=1e-6, atol=1e-8), (i, c)


def test_parabola_vertex_and_refined_grid():
    g = jd._refined_grid(np.array([1e-2, 1.0, 1e2]), 2)
    assert np.allclose(np.log10(g), np.arange(-2, 2.01, 0.5))
    x = np.log(np.array([0.1, 1.0, 10.0]))
    for x0 in (-0.7, 0.0, 1.2):
        y = -(x - x0) ** 2
        assert jd._parabola_vertex(*x, *y) == pytest.approx(x0)
    # a missing neighbour or a flat top keeps the best point
    assert jd._parabola_vertex(*x, -np.inf, 0.0, -1.0) == x[1]
    assert jd._parabola_vertex(*x, 0.0, 0.0, 0.0) == x[1]


def test_coupled_filter_uses_auto_density():
    """With correlated noise (6-state filter) 'auto' still works and is close to the fixed
    density it selects on a smooth track."""
    d = _white_jerk(0.05, n=600, tracks=3)
    n = len(d["t"])
    r = estimate(d["pid"], d["t"], d["x"], d["y"], np.full(n, 0.1), np.full(n, 0.1),
                 np.full(n, 0.3), None, KinematicsParams())
    assert np.isfinite(r["ax"]).all() and np.isfinite(r["ax_std"]).all()
    err = np.r_[r["ax"] - d["ax"], r["ay"] - d["ay"]]
    assert np.sqrt(np.mean(err ** 2)) < 0.25


def _naive_loglik(z, r, t, q, prior_v=50.0, prior_a=10.0):
    """Innovations' log-likelihood of one track (scalar loop; the first sample's term is 0)."""
    x = np.array([z[0], 0.0, 0.0])
    P = np.diag([1e6, prior_v ** 2, prior_a ** 2])
    ll = 0.0
    for k in range(len(z)):
        if k:
            d = t[k] - t[k - 1]
            F = np.array([[1, d, d * d / 2], [0, 1, d], [0, 0, 1]])
            Q = q * np.array([[d ** 5 / 20, d ** 4 / 8, d ** 3 / 6], [d ** 4 / 8, d ** 3 / 3, d * d / 2],
                              [d ** 3 / 6, d * d / 2, d]])
            x, P = F @ x, F @ P @ F.T + Q
        S = P[0, 0] + r[k]
        e = z[k] - x[0]
        if k:
            ll += -0.5 * (np.log(S) + e * e / S)
        K = P[:, 0] / S
        x, P = x + K * e, P - np.outer(K, P[0])
    return ll


@pytest.mark.parametrize("regular", [True, False])
def test_window_loglik_matches_a_naive_filter(regular):
    """Both likelihood passes (tabulated gains; full recursion with irregular steps and varying
    noise) give the innovations' log-likelihood of a plain per-track Kalman filter, up to the
    constant -log(2π)/2 per sample."""
    rng = np.random.default_rng(4)
    lens = np.array([40, 25, 3])
    L, W = lens.max(), len(lens)
    qs = np.array([1e-3, 0.1, 2.0])
    z = np.zeros((L, 2, W))
    r = np.ones((L, 2, W))
    dt = np.zeros((L, W))
    first = np.ones((L, W), bool)
    tracks = []
    for w, m in enumerate(lens):
        t = np.arange(m) * 0.04 if regular else np.cumsum(rng.uniform(0.02, 0.06, m))
        rr = np.full((m, 2), 0.01) if regular else rng.uniform(0.002, 0.03, (m, 2))
        zz = np.c_[3 * t + 0.2 * t * t, np.sin(t)] + rng.normal(0, 1, (m, 2)) * np.sqrt(rr)
        z[:m, :, w], r[:m, :, w] = zz, rr
        dt[1:m, w] = np.diff(t)
        first[1:m, w] = False
        tracks.append((zz, rr, t))
    order = np.argsort(lens - 1, kind="stable")  # windows sorted by their last step
    ends = (lens[order] - 1, order, np.arange(W))  # (last step, row, result row)
    if regular:
        table = jd._gain_table(int(L), 0.04, 0.01, tuple(qs.tolist()), 50.0, 10.0)
        got = jd._ca_window_loglik_regular(z, first, lens[order] - 1, ends, table, 0.04,
                                           np.arange(3), np.arange(3))
    else:
        got = jd._ca_window_loglik(z, r, dt[:, None, :], first, ends, W, qs, 50.0, 10.0)
    got = got[np.argsort(order)]  # back to the tracks' order
    for w, (zz, rr, t) in enumerate(tracks):
        for i, q in enumerate(qs):
            for a in range(2):
                assert got[w, i, a] == pytest.approx(_naive_loglik(zz[:, a], rr[:, a], t, q),
                                                     rel=1e-9, abs=1e-6)


def test_auto_std_calibrated_without_any_jerk():
    """Constant-acceleration tracks (no jerk at all: the likelihood is flat towards q = 0): the
    grid's floor (1e-15 m²/s⁵) stands for 'no jerk' and the band covers the truth ~68 % of the
    time even on the longest windows (1,280 samples); with the earlier floor at 1e-6 the
    random-walk prior still let the acceleration wander over the smoother's span (~0.96 on
    30-s tracks)."""
    rng = np.random.default_rng(11)
    tracks, n, dt = 100, 750, 0.04
    t = np.arange(n) * dt
    a = rng.normal(0, 0.5, (tracks, 1, 2))
    v0 = np.array([30.0, 0.0]) + rng.normal(0, 1.0, (tracks, 1, 2))
    pos = v0 * t[None, :, None] + 0.5 * a * t[None, :, None] ** 2
    m = tracks * n
    d = {"pid": np.repeat(np.arange(tracks), n), "t": np.tile(t, tracks),
         "x": pos[..., 0].ravel() + rng.normal(0, 0.1, m),
         "y": pos[..., 1].ravel() + rng.normal(0, 0.1, m),
         "ax": np.repeat(a[:, 0, 0], n), "ay": np.repeat(a[:, 0, 1], n)}
    assert 0.6 <= _coverage(d, _run(d)) <= 0.76
    floor6 = _run(d, jerk_density_grid=(1e-6, 1e-5, 1e-4, 1e-3, 0.01, 0.1, 1.0, 10.0, 100.0))
    assert _coverage(d, floor6) > 0.9
