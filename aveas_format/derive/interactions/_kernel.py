"""The follower/leader metrics fused into one compiled pass over the pairs (numba, the ``jit``
extra): every measure of :func:`._ttc.follower_leader_metrics` and its std for one pair at a time,
with no temporaries.

The NumPy path (``_ttc._metrics`` and :func:`._surrogates.lane_surrogates`) is the reference and
the fallback: the formulas here are the same (``fastmath`` off; where the NumPy path divides
several times by one quantity, the kernel multiplies by its reciprocal), so both give the same
numbers to rounding (a few units in the last place) (asserted in
tests/derive/test_kernel.py over random and degenerate pairs: NaN inputs, zero closing speed,
contact, negative gaps, stopping vehicles). NumPy's elementwise rules are spelled out where a plain
scalar ``min``, ``max`` or cast would differ: ``np.minimum``/``np.maximum`` propagate NaN,
``np.nan_to_num`` maps NaN to 0 and ±inf to the largest finite float, ``np.where`` takes the
second branch where the condition compares a NaN.

Imported only where the numba path runs (:func:`._ttc.kernel_backend` decides, in one place); the
first call in an environment compiles the kernel (a few seconds) and caches it next to this module
(numba's ``cache=True``): later processes load it in a fraction of a second.
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: the kernel's outputs, in the order of the rows of its output array (keys of the metrics dict)
OUTPUTS = ("closing", "ttc", "ttc_std", "thw", "dhw", "ttc_ca", "ttc_ca_std",
           "drac", "drac_std", "mdrac", "mdrac_std", "psd", "psd_std")

#: IEEE arithmetic as NumPy's (error_model "numpy": x/0 is ±inf or NaN, not ZeroDivisionError)
_jit = numba.njit(cache=True, fastmath=False, error_model="numpy")
_INF = math.inf
_NAN = math.nan
_BIG = float(np.finfo(np.float64).max)


def metrics(args: list[np.ndarray], reaction_time: float, max_deceleration: float,
            parallel: bool = False) -> dict[str, np.ndarray]:
    """The kernel's outputs (:data:`OUTPUTS`) for the pairs of ``args`` (``gap, gap_var,
    leader_length, vf, af, vfv, afv, vl, al, vlv, alv``, float arrays of one length) as a dict of
    fresh arrays. ``parallel``: split the pairs over numba's threads (prange)."""
    n = len(args[0])
    # one array per output, not one 2D block: arrays of 10^6 floats are reused by the allocator
    # from call to call, a block of 13 x 10^6 is mapped afresh each time (page faults: +40 %)
    out = tuple(np.empty(n) for _ in OUTPUTS)
    cols = [np.ascontiguousarray(a, dtype=np.float64) for a in args]
    if n:
        (_loop_parallel if parallel else _loop)(*cols, float(reaction_time),
                                                 float(max_deceleration), out)
    return dict(zip(OUTPUTS, out))


@_jit
def _nan_to_num(x):
    """``np.nan_to_num`` of a scalar."""
    if x != x:
        return 0.0
    if x == _INF:
        return _BIG
    if x == -_INF:
        return -_BIG
    return x


@_jit
def _minimum(a, b):
    """``np.minimum`` of scalars (NaN if either is NaN)."""
    if a != a or b != b:
        return _NAN
    return a if a <= b else b


@_jit
def _maximum(a, b):
    """``np.maximum`` of scalars (NaN if either is NaN)."""
    if a != a or b != b:
        return _NAN
    return a if a >= b else b


@_jit
def _stop_time(v, a):
    """``_ttc._stop_time`` of one vehicle."""
    if a < 0 and v > 0:
        return -v / a
    if v <= 0 and a <= 0:
        return 0.0
    return _INF


@_jit
def _first_root(A, B, C, t0, t1):
    """``_ttc._first_root`` of one quadratic ``A + B t + C t²`` on ``[t0, t1]``."""
    g0 = A + t0 * (B + C * t0)
    disc = B * B - 4.0 * A * C
    sq = math.sqrt(_maximum(disc, 0.0))
    q = -0.5 * (B + math.copysign(sq, B))
    real = disc >= 0
    r1 = q / C if real and C != 0 else _INF
    r2 = A / q if real else _INF
    if r1 < t0:
        r1 = _INF
    if r2 < t0:
        r2 = _INF
    r = _minimum(r1, r2)
    if not r <= t1:
        r = _INF
    return t0 if g0 <= 0 else r


@_jit
def _ttc_ca(g, vf, af, vl, al):
    """``_ttc._ttc_ca`` of one pair: ``(ttc, tau_f, tau_l)``."""
    Tf = _stop_time(vf, af)
    Tl = _stop_time(vl, al)
    b1 = _minimum(Tf, Tl)
    out = _INF
    r = _first_root(g, vl - vf, 0.5 * (al - af), 0.0, b1 if math.isfinite(b1) else 1e300)
    if r < out:
        out = r
    if math.isfinite(b1) and out == _INF:
        f_stopped = Tf <= Tl
        T = b1
        if f_stopped:
            x_stop = vf * T + 0.5 * af * T * T
            A, B, C = g - x_stop, vl, 0.5 * al
        else:
            x_stop = vl * T + 0.5 * al * T * T
            A, B, C = g + x_stop, -vf, -0.5 * af
        b2 = _maximum(Tf, Tl)
        out = _first_root(A, B, C, T, b2 if math.isfinite(b2) else 1e300)
    if g < 0:
        out = _INF
    return out, _minimum(out, Tf), _minimum(out, Tl)


@_jit
def _pair(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out, i):
    """Every output of one pair into element ``i`` of the arrays ``out`` (:data:`OUTPUTS`)."""
    dv = vf - vl
    dvvar = vfv + vlv
    # ttc (constant velocities) and its std by the delta method (NaN where ttc is infinite)
    closing_1d = dv > 0 and g >= 0
    ttc = g / dv if closing_1d else _INF
    ttc_std = _NAN
    if math.isfinite(ttc):
        r2 = 1.0 / (dv * dv)  # a reciprocal, then products: fewer divisions than NumPy's path
        ttc_std = math.sqrt(gv * r2 + g * g * dvvar * (r2 * r2))
    # MTTC (constant accelerations) and its std (implicit function theorem)
    ttc_ca, tf, tl = _ttc_ca(g, vf, af, vl, al)
    rate = (vl + al * tl) - (vf + af * tf)
    ok = math.isfinite(ttc_ca) and ttc_ca > 0 and rate < 0 and math.isfinite(af) \
        and math.isfinite(al)
    if ok:
        tf2, tl2 = tf * tf, tl * tl
        var = (_nan_to_num(gv) + tf2 * _nan_to_num(vfv) + 0.25 * (tf2 * tf2) * _nan_to_num(afv)
               + tl2 * _nan_to_num(vlv) + 0.25 * (tl2 * tl2) * _nan_to_num(alv)) / (rate * rate)
        ttc_ca_std = math.sqrt(var)
    elif math.isfinite(ttc_ca) and ttc_ca == 0:
        ttc_ca_std = 0.0
    else:
        ttc_ca_std = _NAN
    # the surrogates (_surrogates.lane_surrogates)
    sg2 = _nan_to_num(gv)
    sdv2 = _nan_to_num(dvvar)
    svf2 = _nan_to_num(vfv)
    drac = drac_std = mdrac = mdrac_std = psd = psd_std = _NAN
    if dv > 0 and g > 0:
        ig = 1.0 / g
        drac = 0.5 * dv * dv * ig
        # ∂/∂Δv = Δv / g, ∂/∂g = -Δv² / (2 g²) = -DRAC / g
        drac_std = math.sqrt((dv * ig) ** 2 * sdv2 + (drac * ig) ** 2 * sg2)
        den = g - R * dv
        if den > 0:
            iden = 1.0 / den
            mdrac = 0.5 * dv * dv * iden
            # ∂/∂g = -MDRAC / den, ∂/∂Δv = Δv (g - R Δv / 2) / den²
            mdrac_std = math.sqrt((mdrac * iden) ** 2 * sg2
                                  + (dv * (g - 0.5 * R * dv) * (iden * iden)) ** 2 * sdv2)
    thw = _INF
    if vf > 0:
        iv = 1.0 / vf
        if g >= 0:
            thw = g * iv
        psd = 2.0 * d * g * (iv * iv)
        # ∂/∂g = 2 d / v², ∂/∂v = -4 d g / v³ = -2 PSD / v
        psd_std = math.sqrt((2.0 * d * (iv * iv)) ** 2 * sg2 + (2.0 * psd * iv) ** 2 * svf2)
    out[0][i] = dv
    out[1][i] = ttc
    out[2][i] = ttc_std
    out[3][i] = thw
    out[4][i] = g + ll
    out[5][i] = ttc_ca
    out[6][i] = ttc_ca_std
    out[7][i] = drac
    out[8][i] = drac_std
    out[9][i] = mdrac
    out[10][i] = mdrac_std
    out[11][i] = psd
    out[12][i] = psd_std


@_jit
def _loop(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out):
    for i in range(len(g)):
        _pair(g[i], gv[i], ll[i], vf[i], af[i], vfv[i], afv[i], vl[i], al[i], vlv[i], alv[i],
              R, d, out, i)


@numba.njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def _loop_parallel(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out):
    for i in numba.prange(len(g)):
        _pair(g[i], gv[i], ll[i], vf[i], af[i], vfv[i], afv[i], vl[i], al[i], vlv[i], alv[i],
              R, d, out, i)
