"""The follower/leader metrics fused into one compiled pass over the pairs (numba, the ``jit``
extra): every measure of :func:`._ttc.follower_leader_metrics` and its std for one pair at a time,
with no temporaries.

The NumPy path (``_ttc._metrics`` and :func:`._surrogates.lane_surrogates`) is the reference and
the fallback, and the formulas here are the same: ``fastmath`` off; every branch computed and the
defined one selected, as the NumPy path does with ``np.where``; NumPy's elementwise rules spelled
out where a scalar ``min``, ``max`` or cast would differ (``np.minimum``/``np.maximum`` propagate
NaN, ``np.nan_to_num`` maps NaN to 0 and ±inf to the largest finite float, a comparison with NaN
is false); where the NumPy path divides several times by one quantity, the kernel multiplies by
its reciprocal. Both give the same numbers to a few units in the last place, NaN and ±inf in the
same places (tests/derive/test_kernel.py, over random pairs and every combination of degenerate
ones: NaN and infinite inputs, zero closing speed, contact, negative gaps, stopping vehicles).

Imported only where the numba path runs (:func:`aveas_format.numeric.kernel_backend` decides, in one place); the
first call in an environment compiles the kernel (seconds) and caches it next to this module
(numba's ``cache=True``); later processes load it with numba's import in well under a second
when the machine is idle. docs/derive.md "Fast path".
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: the kernel's outputs, in the order of the rows of its output array (keys of the metrics dict)
OUTPUTS = ("closing", "ttc", "ttc_std", "thw", "dhw", "ttc_ca", "ttc_ca_std",
           "drac", "drac_std", "mdrac", "mdrac_std", "psd", "psd_std")

#: the loops: IEEE arithmetic as NumPy's (error_model "numpy": x/0 is ±inf or NaN, not
#: ZeroDivisionError), no fast-math (NaN and inf are meaningful here)
_jit_loop = numba.njit(cache=True, fastmath=False, error_model="numpy")
#: the per-pair functions, inlined into the loops (as calls they cost 12 % more time per pair and
#: a reference-count update of the output per pair; compiling takes twice as long, once: cached)
_jit = numba.njit(cache=True, fastmath=False, error_model="numpy", inline="always")
_INF = math.inf
_NAN = math.nan
_BIG = float(np.finfo(np.float64).max)


def metrics(args: list[np.ndarray], reaction_time: float, max_deceleration: float,
            parallel: bool = False) -> dict[str, np.ndarray]:
    """The kernel's outputs (:data:`OUTPUTS`) for the pairs of ``args`` (``gap, gap_var,
    leader_length, vf, af, vfv, afv, vl, al, vlv, alv``, float arrays of one length) as a dict of
    rows of one fresh block. ``parallel``: split the pairs over numba's threads (prange)."""
    n = len(args[0])
    # one block, a row per output: the loop then holds one output pointer, not 13 (with 13
    # separate arrays it runs 1.8x slower: 0.122 vs 0.067 CPU-s per 10^6 pairs, measured)
    out = np.empty((len(OUTPUTS), n))
    cols = [np.ascontiguousarray(a, dtype=np.float64) for a in args]
    if n:
        (_loop_parallel if parallel else _loop)(*cols, float(reaction_time),
                                                 float(max_deceleration), out)
    return dict(zip(OUTPUTS, out))


@_jit
def _nan_to_num(x):
    """``np.nan_to_num`` of a scalar."""
    y = 0.0 if x != x else x
    return _BIG if y == _INF else -_BIG if y == -_INF else y


@_jit
def _minimum(a, b):
    """``np.minimum`` of scalars (NaN if either is NaN)."""
    return _NAN if (a != a) | (b != b) else a if a <= b else b


@_jit
def _maximum(a, b):
    """``np.maximum`` of scalars (NaN if either is NaN)."""
    return _NAN if (a != a) | (b != b) else a if a >= b else b


@_jit
def _finite(x):
    return abs(x) < _INF


@_jit
def _stop_time(v, a):
    """``_ttc._stop_time`` of one vehicle."""
    t = -v / a
    return t if (a < 0) & (v > 0) else 0.0 if (v <= 0) & (a <= 0) else _INF


@_jit
def _first_root(A, B, C, t0, t1):
    """``_ttc._first_root`` of one quadratic ``A + B t + C t²`` on ``[t0, t1]``."""
    g0 = A + t0 * (B + C * t0)
    disc = B * B - 4.0 * A * C
    sq = math.sqrt(_maximum(disc, 0.0))
    q = -0.5 * (B + math.copysign(sq, B))
    real = disc >= 0
    r1 = q / C
    r2 = A / q
    r1 = r1 if real & (C != 0) & (r1 >= t0) else _INF
    r2 = r2 if real & (r2 >= t0) else _INF
    r = _minimum(r1, r2)
    r = r if r <= t1 else _INF
    return t0 if g0 <= 0 else r


@_jit
def _ttc_ca(g, vf, af, vl, al):
    """``_ttc._ttc_ca`` of one pair: ``(ttc, tau_f, tau_l)``. Both pieces are computed and the
    result selected (no branch to mispredict)."""
    Tf = _stop_time(vf, af)
    Tl = _stop_time(vl, al)
    b1 = _minimum(Tf, Tl)
    fin1 = _finite(b1)
    r = _first_root(g, vl - vf, 0.5 * (al - af), 0.0, b1 if fin1 else 1e300)
    out = r if r < _INF else _INF
    # piece 2: the one that stopped first stands at x(T) = v T + a T²/2
    f_stopped = Tf <= Tl
    T = b1
    xf = vf * T + 0.5 * af * T * T
    xl = vl * T + 0.5 * al * T * T
    A = g - xf if f_stopped else g + xl
    B = vl if f_stopped else -vf
    C = 0.5 * al if f_stopped else -0.5 * af
    b2 = _maximum(Tf, Tl)
    r2 = _first_root(A, B, C, T, b2 if _finite(b2) else 1e300)
    out = r2 if fin1 & (out == _INF) else out
    out = _INF if g < 0 else out
    return out, _minimum(out, Tf), _minimum(out, Tl)


@_jit
def _pair(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out, i):
    """Every output of one pair into column ``i`` of ``out`` (rows: :data:`OUTPUTS`).
    Every quantity is computed and the defined ones selected (no branches: the kinds of pairs
    alternate at random, a branch would be mispredicted); where the NumPy path divides several
    times by one quantity, this multiplies by its reciprocal."""
    dv = vf - vl
    dvvar = vfv + vlv
    # ttc (constant velocities) and its std by the delta method (NaN where ttc is infinite)
    ttc = g / dv
    ttc = ttc if (dv > 0) & (g >= 0) else _INF
    r2 = 1.0 / (dv * dv)
    ttc_std = math.sqrt(gv * r2 + g * g * dvvar * (r2 * r2))
    ttc_std = ttc_std if _finite(ttc) else _NAN
    # MTTC (constant accelerations) and its std (implicit function theorem)
    ttc_ca, tf, tl = _ttc_ca(g, vf, af, vl, al)
    rate = (vl + al * tl) - (vf + af * tf)
    ok = _finite(ttc_ca) & (ttc_ca > 0) & (rate < 0) & _finite(af) & _finite(al)
    tf2, tl2 = tf * tf, tl * tl
    var = (_nan_to_num(gv) + tf2 * _nan_to_num(vfv) + 0.25 * (tf2 * tf2) * _nan_to_num(afv)
           + tl2 * _nan_to_num(vlv) + 0.25 * (tl2 * tl2) * _nan_to_num(alv)) / (rate * rate)
    ttc_ca_std = math.sqrt(var) if ok else 0.0 if _finite(ttc_ca) & (ttc_ca == 0) else _NAN
    thw = g / vf
    thw = thw if (vf > 0) & (g >= 0) else _INF
    # the surrogates (_surrogates.lane_surrogates)
    sg2 = _nan_to_num(gv)
    sdv2 = _nan_to_num(dvvar)
    svf2 = _nan_to_num(vfv)
    closing = (dv > 0) & (g > 0)
    ig = 1.0 / g
    drac = 0.5 * dv * dv * ig
    # ∂/∂Δv = Δv / g, ∂/∂g = -Δv² / (2 g²) = -DRAC / g
    drac_std = math.sqrt((dv * ig) ** 2 * sdv2 + (drac * ig) ** 2 * sg2)
    den = g - R * dv
    iden = 1.0 / den
    mdrac = 0.5 * dv * dv * iden
    # ∂/∂g = -MDRAC / den, ∂/∂Δv = Δv (g - R Δv / 2) / den²
    mdrac_std = math.sqrt((mdrac * iden) ** 2 * sg2
                          + (dv * (g - 0.5 * R * dv) * (iden * iden)) ** 2 * sdv2)
    iv = 1.0 / vf
    psd = 2.0 * d * g * (iv * iv)
    # ∂/∂g = 2 d / v², ∂/∂v = -4 d g / v³ = -2 PSD / v
    psd_std = math.sqrt((2.0 * d * (iv * iv)) ** 2 * sg2 + (2.0 * psd * iv) ** 2 * svf2)
    mdrac_ok = closing & (den > 0)
    drac, drac_std = (drac, drac_std) if closing else (_NAN, _NAN)
    mdrac, mdrac_std = (mdrac, mdrac_std) if mdrac_ok else (_NAN, _NAN)
    psd, psd_std = (psd, psd_std) if vf > 0 else (_NAN, _NAN)
    out[0, i] = dv
    out[1, i] = ttc
    out[2, i] = ttc_std
    out[3, i] = thw
    out[4, i] = g + ll
    out[5, i] = ttc_ca
    out[6, i] = ttc_ca_std
    out[7, i] = drac
    out[8, i] = drac_std
    out[9, i] = mdrac
    out[10, i] = mdrac_std
    out[11, i] = psd
    out[12, i] = psd_std


@_jit_loop
def _loop(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out):
    for i in range(len(g)):
        _pair(g[i], gv[i], ll[i], vf[i], af[i], vfv[i], afv[i], vl[i], al[i], vlv[i], alv[i],
              R, d, out, i)


@numba.njit(cache=True, fastmath=False, error_model="numpy", parallel=True)
def _loop_parallel(g, gv, ll, vf, af, vfv, afv, vl, al, vlv, alv, R, d, out):
    for i in numba.prange(len(g)):
        _pair(g[i], gv[i], ll[i], vf[i], af[i], vfv[i], afv[i], vl[i], al[i], vlv[i], alv[i],
              R, d, out, i)
