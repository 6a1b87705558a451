"""1D time to collision, headways and their uncertainty for a follower and its leader in a lane.

``ttc`` under constant velocities (``gap / closing speed`` when closing) with its std by the delta
method; ``ttc_ca`` under constant accelerations where vehicles stop rather than reverse, with its
std by central finite differences; ``thw`` (net gap over the follower's speed) and ``dhw`` (gap
plus the leader's length). Conventions: docs/derive.md.
"""

from __future__ import annotations

import numpy as np

from aveas_format.derive.interactions._surrogates import lane_surrogates

#: elements per chunk of the 1D metrics (the temporaries of a chunk stay in the CPU's cache)
CHUNK = 1 << 15


def follower_leader_metrics(gap: np.ndarray, gap_var: np.ndarray, leader_length: np.ndarray,
                            follower: tuple[np.ndarray, ...], leader: tuple[np.ndarray, ...],
                            reaction_time: float = 1.0,
                            max_deceleration: float = 3.4) -> dict[str, np.ndarray]:
    """The 1D metrics of follower/leader pairs along their lane: ``closing``, ``ttc``,
    ``ttc_std``, ``ttc_ca`` (MTTC), ``ttc_ca_std``, ``thw`` and ``dhw`` (with ``gap`` and
    ``gap_var``), and the surrogates ``drac``, ``mdrac``, ``psd`` with their ``_std``
    (:func:`._surrogates.lane_surrogates`).

    ``follower`` and ``leader`` are ``(v, a, v_var, a_var)``: speed and acceleration along the lane
    and their variances. ``ttc_std`` is NaN where the pair is not closing. Computed in chunks of
    :data:`CHUNK` pairs (the many temporaries of a chunk stay in the cache: 2-3x faster than whole
    arrays for millions of pairs). ``gap`` and ``gap_var`` are the inputs themselves (not
    copied)."""
    n = len(gap)
    args = [np.asarray(a, float) for a in (gap, gap_var, leader_length, *follower, *leader)]
    args = np.broadcast_arrays(*args) if n else args
    out: dict[str, np.ndarray] = {}
    for lo in range(0, max(n, 1), CHUNK):
        part = _metrics(*(a[lo:lo + CHUNK] for a in args), reaction_time, max_deceleration)
        if not out:
            out = {k: args[0] if k == "gap" else args[1] if k == "gap_var" else np.empty(n)
                   for k in part}
        for k, v in part.items():
            if k not in PASSED_THROUGH:
                out[k][lo:lo + CHUNK] = v
    return out


#: outputs of :func:`follower_leader_metrics` that are its inputs
PASSED_THROUGH = frozenset({"gap", "gap_var"})


def _metrics(gap, gap_var, leader_length, vf, af, vfv, afv, vl, al, vlv, alv,
             reaction_time, max_deceleration) -> dict[str, np.ndarray]:
    dv = vf - vl
    dvvar = vfv + vlv
    ttc = ttc_constant_velocity(gap, vf, vl)
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc_std = np.sqrt(gap_var / dv ** 2 + gap ** 2 * dvvar / dv ** 4)
    ttc_ca, tf, tl = _ttc_ca(gap, vf, af, vl, al)
    ttc_ca_std = _ttc_ca_std(gap, vf, af, vl, al, ttc_ca, gap_var, vfv, afv, vlv, alv,
                             taus=(tf, tl))
    with np.errstate(divide="ignore", invalid="ignore"):
        thw = np.where((vf > 0) & (gap >= 0), gap / vf, np.inf)
    return {"gap": gap, "gap_var": gap_var, "closing": dv, "ttc": ttc,
            "ttc_std": np.where(np.isfinite(ttc), ttc_std, np.nan), "thw": thw,
            "dhw": gap + leader_length, "ttc_ca": ttc_ca, "ttc_ca_std": ttc_ca_std,
            **lane_surrogates(gap, gap_var, dv, dvvar, vf, vfv, reaction_time, max_deceleration)}


def ttc_constant_velocity(gap, v_follower, v_leader):
    """1D TTC under constant velocities: ``gap / (v_f - v_l)`` when closing, else +inf."""
    gap, vf, vl = np.broadcast_arrays(*(np.asarray(a, float) for a in (gap, v_follower, v_leader)))
    dv = vf - vl
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((dv > 0) & (gap >= 0), gap / dv, np.inf)


def _first_root(A, B, C, t0, t1):
    """Smallest t in [t0, t1] with A + B t + C t² <= 0 (inf where none), elementwise, for
    quadratics that are positive at t0 unless they are at most 0 there (then t0)."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        g0 = A + t0 * (B + C * t0)
        disc = B * B - 4.0 * A * C
        sq = np.sqrt(np.maximum(disc, 0.0))
        # numerically stable pair of roots; with C = 0 the second is the linear root -A/B
        q = -0.5 * (B + np.copysign(sq, B))
        r1 = q / C
        r2 = A / q
        r1[~(disc >= 0) | (C == 0)] = np.inf
        r2[~(disc >= 0)] = np.inf
        r1[r1 < t0] = np.inf
        r2[r2 < t0] = np.inf
        r = np.minimum(r1, r2)
    r[~(r <= t1)] = np.inf
    return np.where(g0 <= 0, t0, r)


def _stop_time(v, a):
    """When a vehicle at speed ``v`` with constant acceleration ``a`` stops (it does not reverse):
    ``-v/a`` when braking from a positive speed, 0 when standing or backing without accelerating
    forward, else never (inf)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((a < 0) & (v > 0), -v / a, np.where((v <= 0) & (a <= 0), 0.0, np.inf))


def ttc_constant_acceleration(gap, v_follower, a_follower, v_leader, a_leader):
    """1D TTC with constant accelerations where vehicles stop rather than reverse (+inf if never).

    ``gap(t) = gap + x_l(t) - x_f(t)``, ``x(t) = v τ + a τ²/2`` with ``τ = min(t, T)`` and ``T`` the
    vehicle's stop time. Until the first stop both move (``gap`` is quadratic in t); between the
    stops one stands (quadratic again); after both stopped the gap is constant, so the first
    contact is the first root in one of the first two pieces."""
    g, vf, af, vl, al = np.broadcast_arrays(*(np.asarray(a, float) for a in
                                              (gap, v_follower, a_follower, v_leader, a_leader)))
    return _ttc_ca(g, vf, af, vl, al)[0]


def _ttc_ca(g, vf, af, vl, al):
    """``(ttc, tau_f, tau_l)``: the TTC with constant accelerations and each vehicle's time in
    motion until then (``min(ttc, T)``), for the analytic derivatives."""
    Tf, Tl = _stop_time(vf, af), _stop_time(vl, al)
    b1 = np.minimum(Tf, Tl)
    out = np.full(g.shape, np.inf)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        # piece 1, [0, b1]: both move; gap = g + (vl - vf) t + (al - af) t²/2
        r = _first_root(g, vl - vf, 0.5 * (al - af), 0.0, np.where(np.isfinite(b1), b1, 1e300))
        out = np.where(r < out, r, out)
        # piece 2, [b1, b2]: the one that stopped first stands at x(T) = v T + a T²/2; only
        # where one stops and piece 1 found no contact (a subset: computed on it alone)
        k = np.flatnonzero(np.isfinite(b1) & (out == np.inf))
        if len(k):
            gk, vfk, afk, vlk, alk, Tfk, Tlk = (a[k] for a in (g, vf, af, vl, al, Tf, Tl))
            f_stopped = Tfk <= Tlk
            T = b1[k]
            x_stop = np.where(f_stopped, vfk * T + 0.5 * afk * T * T, vlk * T + 0.5 * alk * T * T)
            A = np.where(f_stopped, gk - x_stop, gk + x_stop)
            B = np.where(f_stopped, vlk, -vfk)
            C = np.where(f_stopped, 0.5 * alk, -0.5 * afk)
            b2 = np.maximum(Tfk, Tlk)
            out[k] = _first_root(A, B, C, T, np.where(np.isfinite(b2), b2, 1e300))
    out = np.where(g < 0, np.inf, out)
    return out, np.minimum(out, Tf), np.minimum(out, Tl)


def _ttc_ca_std(g, vf, af, vl, al, ttc, gvar, vfv, afv, vlv, alv, taus=None):
    """Delta method for the constant-acceleration TTC with analytic derivatives: at the root
    ``gap(t*; θ) = 0``, so ``dt*/dθ = -(∂gap/∂θ) / (∂gap/∂t)`` (implicit function theorem), with
    ``∂gap/∂t = v_l(t*) - v_f(t*)`` and, as ``x = v τ + a τ²/2`` with ``τ = min(t, T)`` whether or
    not the vehicle stopped, ``∂x/∂v = τ`` and ``∂x/∂a = τ²/2``. NaN where the TTC is infinite,
    0 (already touching) or the contact grazing (``∂gap/∂t = 0``)."""
    tf, tl = taus if taus is not None else _taus(ttc, vf, af, vl, al)
    # over: an infinite variance (nan_to_num: the largest float) times tau² is inf, as meant
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        rate = (vl + al * tl) - (vf + af * tf)  # d gap / dt at the root
        var = (np.nan_to_num(gvar) + tf * tf * np.nan_to_num(vfv) + 0.25 * tf ** 4 * np.nan_to_num(afv)
               + tl * tl * np.nan_to_num(vlv) + 0.25 * tl ** 4 * np.nan_to_num(alv)) / (rate * rate)
    ok = np.isfinite(ttc) & (ttc > 0) & (rate < 0) & np.isfinite(af) & np.isfinite(al)
    return np.where(ok, np.sqrt(var), np.where(np.isfinite(ttc) & (ttc == 0), 0.0, np.nan))


def _taus(ttc, vf, af, vl, al):
    return np.minimum(ttc, _stop_time(vf, af)), np.minimum(ttc, _stop_time(vl, al))
