"""1D time to collision, headways and their uncertainty for a follower and its leader in a lane.

``ttc`` under constant velocities (``gap / closing speed`` when closing) with its std by the delta
method; ``ttc_ca`` under constant accelerations where vehicles stop rather than reverse, with its
std by central finite differences; ``thw`` (net gap over the follower's speed) and ``dhw`` (gap
plus the leader's length). Conventions: docs/derive.md.
"""

from __future__ import annotations

import numpy as np


def follower_leader_metrics(gap: np.ndarray, gap_var: np.ndarray, leader_length: np.ndarray,
                            follower: tuple[np.ndarray, ...], leader: tuple[np.ndarray, ...]
                            ) -> dict[str, np.ndarray]:
    """The 1D metrics of follower/leader pairs along their lane: ``closing``, ``ttc``,
    ``ttc_std``, ``ttc_ca``, ``ttc_ca_std``, ``thw`` and ``dhw`` (with ``gap`` and ``gap_var``).

    ``follower`` and ``leader`` are ``(v, a, v_var, a_var)``: speed and acceleration along the lane
    and their variances. ``ttc_std`` is NaN where the pair is not closing."""
    vf, af, vfv, afv = follower
    vl, al, vlv, alv = leader
    dv = vf - vl
    dvvar = vfv + vlv
    ttc = ttc_constant_velocity(gap, vf, vl)
    with np.errstate(divide="ignore", invalid="ignore"):
        ttc_std = np.sqrt(gap_var / dv ** 2 + gap ** 2 * dvvar / dv ** 4)
    ttc_ca = ttc_constant_acceleration(gap, vf, af, vl, al)
    ttc_ca_std = _ttc_ca_std(gap, vf, af, vl, al, ttc_ca, gap_var, vfv, afv, vlv, alv)
    with np.errstate(divide="ignore", invalid="ignore"):
        thw = np.where((vf > 0) & (gap >= 0), gap / vf, np.inf)
    return {"gap": gap, "gap_var": gap_var, "closing": dv, "ttc": ttc,
            "ttc_std": np.where(np.isfinite(ttc), ttc_std, np.nan), "thw": thw,
            "dhw": gap + leader_length, "ttc_ca": ttc_ca, "ttc_ca_std": ttc_ca_std}


def ttc_constant_velocity(gap, v_follower, v_leader):
    """1D TTC under constant velocities: ``gap / (v_f - v_l)`` when closing, else +inf."""
    gap, vf, vl = np.broadcast_arrays(*(np.asarray(a, float) for a in (gap, v_follower, v_leader)))
    dv = vf - vl
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((dv > 0) & (gap >= 0), gap / dv, np.inf)


def _first_root(A, B, C, t0, t1):
    """Smallest t in [t0, t1] with A + B t + C t² <= 0 (inf where none), elementwise."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        g0 = A + B * t0 + C * t0 * t0
        out = np.where(g0 <= 0, t0, np.inf)
        lin = np.abs(C) < 1e-12
        r_lin = np.where(B < 0, -A / B, np.inf)
        disc = B * B - 4 * A * C
        sq = np.sqrt(np.maximum(disc, 0.0))
        # numerically stable pair of roots
        qq = -0.5 * (B + np.copysign(sq, B))
        r1 = np.where(qq != 0, qq / C, np.inf)
        r2 = np.where(qq != 0, A / qq, np.inf)
        r1 = np.where(disc >= 0, r1, np.inf)
        r2 = np.where(disc >= 0, r2, np.inf)
        cand = np.stack([np.where(lin, r_lin, r1), np.where(lin, np.inf, r2)])
    cand = np.where((cand >= t0) & (cand <= t1), cand, np.inf)
    return np.minimum(out, cand.min(axis=0))


def ttc_constant_acceleration(gap, v_follower, a_follower, v_leader, a_leader):
    """1D TTC with constant accelerations where vehicles stop rather than reverse (+inf if never).

    ``gap(t) = gap + x_l(t) - x_f(t)``, ``x(t) = v t + a t²/2`` until the vehicle stops."""
    g, vf, af, vl, al = np.broadcast_arrays(*(np.asarray(a, float) for a in
                                              (gap, v_follower, a_follower, v_leader, a_leader)))
    with np.errstate(divide="ignore", invalid="ignore"):
        Tf = np.where((af < 0) & (vf > 0), -vf / af, np.where((vf <= 0) & (af <= 0), 0.0, np.inf))
        Tl = np.where((al < 0) & (vl > 0), -vl / al, np.where((vl <= 0) & (al <= 0), 0.0, np.inf))
    b1 = np.minimum(Tf, Tl)
    b2 = np.maximum(Tf, Tl)
    out = np.full(g.shape, np.inf)
    with np.errstate(invalid="ignore", over="ignore"):
        return _ttc_ca_pieces(g, vf, af, vl, al, Tf, Tl, b1, b2, out)


def _ttc_ca_pieces(g, vf, af, vl, al, Tf, Tl, b1, b2, out):
    for lo, hi in ((np.zeros_like(g), b1), (b1, b2), (b2, np.full_like(g, np.inf))):
        mid = np.where(np.isfinite(hi), 0.5 * (lo + hi), lo + 1.0)
        f_moving = mid < Tf
        l_moving = mid < Tl
        # x(t) = c0 + c1 t + c2 t²
        xf = (np.where(f_moving, 0.0, vf * Tf + 0.5 * af * Tf * Tf), np.where(f_moving, vf, 0.0),
              np.where(f_moving, 0.5 * af, 0.0))
        xl = (np.where(l_moving, 0.0, vl * Tl + 0.5 * al * Tl * Tl), np.where(l_moving, vl, 0.0),
              np.where(l_moving, 0.5 * al, 0.0))
        xf = tuple(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0) for c in xf)
        xl = tuple(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0) for c in xl)
        A = g + xl[0] - xf[0]
        B = xl[1] - xf[1]
        C = xl[2] - xf[2]
        valid = lo < hi
        r = _first_root(A, B, C, lo, np.where(np.isfinite(hi), hi, 1e300))
        out = np.where(valid & (r < out), r, out)
    return np.where(g < 0, np.inf, out)


def _ttc_ca_std(g, vf, af, vl, al, ttc, gvar, vfv, afv, vlv, alv):
    """Delta method for the constant-acceleration TTC by central finite differences."""
    base = np.isfinite(ttc)
    var = np.zeros(len(g))
    args = [g, vf, af, vl, al]
    for k, v in enumerate((gvar, vfv, afv, vlv, alv)):
        v = np.nan_to_num(v)
        h = np.maximum(1e-4, 1e-3 * np.abs(args[k]))
        up = list(args)
        dn = list(args)
        up[k] = args[k] + h
        dn[k] = args[k] - h
        with np.errstate(invalid="ignore"):
            d = (ttc_constant_acceleration(*up) - ttc_constant_acceleration(*dn)) / (2 * h)
            var = var + np.where(np.isfinite(d), d * d * v, 0.0)
    return np.where(base & np.isfinite(af) & np.isfinite(al), np.sqrt(var), np.nan)
