"""The follower/leader metrics of ``derive/interactions/_ttc.py`` against truth: MTTC (constant
accelerations, vehicles stop rather than reverse) against the first contact of the motion stepped
on a fine time grid, over every combination of degenerate pairs (contact, zero closing speed,
standing, stopping and accelerating vehicles); its std against Monte Carlo; shapes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from aveas_format.derive.interactions._ttc import follower_leader_metrics

DT = 1e-3
HORIZON = 40.0


def _position(v0, a, t):
    """Distance driven by the grid times ``t`` (steps of :data:`DT`) from speed ``v0 >= 0`` at
    constant acceleration ``a``, standing once a braking vehicle's speed reaches 0: its speed
    summed step by step (trapezoids), not the closed form."""
    v = v0 + a * t
    if a < 0 or v0 == 0 and a == 0:
        v = np.maximum(v, 0.0)
    return np.cumsum(0.5 * (np.r_[v0, v[:-1]] + v) * DT)


def _first_contact(gap, vf, af, vl, al):
    """The first grid time at which the stepped gap is <= 0 (inf if none within the horizon)."""
    if gap <= 0:
        return 0.0
    t = np.arange(1, int(HORIZON / DT) + 1) * DT
    g = gap + _position(vl, al, t) - _position(vf, af, t)
    k = np.flatnonzero(g <= 0)
    return float(t[k[0]]) if len(k) else np.inf


def _cases():
    """Every combination of a gap (contact, a hair, near, far), speeds (standing, slow, fast) and
    accelerations (braking, none, speeding up) of both vehicles."""
    return list(itertools.product([0.0, 1e-9, 5.0, 80.0], [0.0, 10.0, 30.0], [-3.0, 0.0, 1.0],
                                  [0.0, 10.0, 30.0], [-8.0, 0.0, 2.0]))


def _metrics(g, vf, af, vl, al, var=0.0):
    n = len(g)
    v = np.full(n, var)
    return follower_leader_metrics(g, v, np.full(n, 4.5), (vf, af, v, v), (vl, al, v, v))


def test_mttc_is_the_first_contact_of_the_motion():
    """Over all 972 combinations: where the stepped motion touches within the horizon, MTTC is
    its time (to the grid step); where it never does, MTTC is beyond the horizon or infinite;
    contact at t = 0 is 0 with std 0; a negative gap (overlap) is no collision course."""
    g, vf, af, vl, al = (np.array(c) for c in zip(*_cases()))
    m = _metrics(g, vf, af, vl, al)
    want = np.array([_first_contact(*c) for c in _cases()])
    hit = np.isfinite(want)
    assert hit.sum() > 100 and (~hit).sum() > 100
    np.testing.assert_allclose(m["ttc_ca"][hit], want[hit], atol=2 * DT)
    assert (m["ttc_ca"][~hit] > HORIZON - 2 * DT).all()
    assert (m["ttc_ca"][g == 0] == 0).all() and (m["ttc_ca_std"][g == 0] == 0).all()
    # constant velocities: gap / closing speed where closing, else never
    dv = vf - vl
    want_cv = np.where((dv > 0), g / np.where(dv > 0, dv, 1), np.inf)
    np.testing.assert_allclose(m["ttc"], want_cv, rtol=1e-12)
    np.testing.assert_allclose(m["thw"], np.where(vf > 0, g / np.where(vf > 0, vf, 1), np.inf))
    # an overlap (negative gap) is no collision course on either measure; DRAC undefined
    o = _metrics(np.full(3, -1.0), np.full(3, 20.0), np.zeros(3), np.full(3, 10.0), np.zeros(3))
    assert np.isinf(o["ttc"]).all() and np.isinf(o["ttc_ca"]).all() and np.isnan(o["drac"]).all()


def test_undefined_inputs_give_undefined_measures_not_errors():
    """NaN and infinite inputs and variances (a track without speed, an unknown variance) give
    NaN or infinite measures, never an exception or a finite number made up from them."""
    nan, inf = np.nan, np.inf
    g = np.array([nan, 20.0, 20.0, 20.0, 20.0])
    vf = np.array([20.0, nan, 20.0, 20.0, 20.0])
    vl = np.array([10.0, 10.0, nan, 10.0, 10.0])
    al = np.array([0.0, 0.0, 0.0, inf, 0.0])
    var = np.array([0.0, 0.0, 0.0, 0.0, inf])
    with np.errstate(all="raise"):  # (the path silences its own expected warnings)
        m = follower_leader_metrics(g, var, np.full(5, 4.5), (vf, np.zeros(5), var, var),
                                    (vl, al, var, var))
    for k in ("ttc", "ttc_ca", "drac"):
        assert not np.isfinite(m[k][:3]).any(), k
    assert not np.isfinite(m["thw"][:2]).any() and m["thw"][2] == 1.0  # (the leader's speed: no part)
    assert not np.isfinite(m["ttc_ca_std"][3])  # an infinite acceleration: no std
    assert m["ttc"][4] == pytest.approx(2.0) and not np.isfinite(m["ttc_std"][4])


def test_mttc_std_matches_monte_carlo():
    """The implicit-function delta method against the spread of MTTC over noisy inputs: a
    follower at 25 m/s braking gently behind a leader at 15 m/s braking hard, 30 m apart."""
    g, vf, af, vl, al = 30.0, 25.0, -0.5, 15.0, -4.0
    sd = {"g": 0.2, "vf": 0.1, "af": 0.05, "vl": 0.1, "al": 0.1}
    one = lambda x: np.array([x])  # noqa: E731
    m = follower_leader_metrics(one(g), one(sd["g"] ** 2), one(4.5),
                                (one(vf), one(af), one(sd["vf"] ** 2), one(sd["af"] ** 2)),
                                (one(vl), one(al), one(sd["vl"] ** 2), one(sd["al"] ** 2)))
    rng = np.random.default_rng(1)
    n = 200_000
    noisy = {k: x + sd[k] * rng.standard_normal(n)
             for k, x in (("g", g), ("vf", vf), ("af", af), ("vl", vl), ("al", al))}
    mc = follower_leader_metrics(noisy["g"], np.zeros(n), np.full(n, 4.5),
                                 (noisy["vf"], noisy["af"], np.zeros(n), np.zeros(n)),
                                 (noisy["vl"], noisy["al"], np.zeros(n), np.zeros(n)))
    assert np.isfinite(mc["ttc_ca"]).all()
    assert m["ttc_ca"][0] == pytest.approx(np.median(mc["ttc_ca"]), rel=0.01)
    assert m["ttc_ca_std"][0] == pytest.approx(np.std(mc["ttc_ca"]), rel=0.05)


def test_shapes_and_pass_through():
    """Scalars broadcast; ``gap`` and ``gap_var`` are the inputs; no pairs, empty outputs."""
    g = np.array([10.0, 20.0])
    gv = np.array([0.1, 0.2])
    m = follower_leader_metrics(g, gv, 4.5, (20.0, 0.0, 0.01, 0.0), (15.0, 0.0, 0.01, 0.0))
    assert m["gap"] is g and m["gap_var"] is gv
    np.testing.assert_allclose(m["ttc"], [2.0, 4.0])
    np.testing.assert_allclose(m["dhw"], [14.5, 24.5])
    e = follower_leader_metrics(np.zeros(0), np.zeros(0), np.zeros(0), (np.zeros(0),) * 4,
                                (np.zeros(0),) * 4)
    assert set(e) == set(m) and all(len(v) == 0 for v in e.values())
