"""Array helpers every layer shares (numpy only; foundation layer, below ``schema``).

One home for the small numerical conventions of the package, so that they cannot drift apart:
angle wrapping, the per-participant segmentation of ``(participant_id, time)``-sorted rows, and
how a number is written in a message for people (:func:`fmt_num`).
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

import numpy as np


def fmt_num(v: object, digits: int = 6) -> str:
    """A number as people read it in a message: floats to ``digits`` significant digits but at
    least two decimals kept where they exist, no float noise, no exponent in everyday ranges
    (``6.6000000000000005`` -> ``6.6``, ``25.080000000000002`` -> ``25.08``, ``691234.5678`` ->
    ``691234.57``, ``1.0`` -> ``1.0``); integers, ``nan``/``inf`` and non-numbers as ``str``."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, Real) or isinstance(v, int):
        return str(v)
    v = float(v)
    if not math.isfinite(v):
        return str(v)
    if v == 0:
        return "0.0"
    mag = math.floor(math.log10(abs(v)))
    if not -10 < mag < 16:
        return f"{v:.{digits}g}"
    decimals = min(15, max(2, digits - 1 - mag))
    text = f"{v:.{decimals}f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to (-pi, pi] (the format's heading range; -pi maps to +pi)."""
    w = np.mod(np.asarray(a, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def same_participant(pid: np.ndarray) -> np.ndarray:
    """Boolean mask of length n-1: row i and row i+1 belong to the same participant (rows sorted
    by participant, then time)."""
    pid = np.asarray(pid)
    return pid[1:] == pid[:-1]



def central_differences(pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray,
                        x_std: np.ndarray | None = None, y_std: np.ndarray | None = None, *,
                        std: bool = True) -> tuple[np.ndarray, np.ndarray, Any, Any]:
    """Time derivatives of (x, y) within each participant and their 1-sigma, vectorised.

    Inner samples use the second-order scheme on uneven spacing (numpy.gradient's): with the
    steps ``hb = t[i] - t[i-1]`` and ``hf = t[i+1] - t[i]``,
    ``x'(t_i) = (hb/(hb+hf)) (x[i+1]-x[i])/hf + (hf/(hb+hf)) (x[i]-x[i-1])/hb``, exact for constant
    acceleration however uneven the sampling (the plain average of the two slopes and the secant
    ``(x[i+1]-x[i-1]) / (t[i+1]-t[i-1])`` are not); on even sampling all three agree. Track ends
    (and samples next to a repeated time) take the one-sided difference; a participant with one
    sample gets 0 with std NaN. The std propagates independent errors of ``x_std``/``y_std``
    (absent: 0) through the scheme's weights (``std=False``: not computed, None; the
    derivatives alone in ~60 % of the time). Rows must be sorted by (participant, time).
    """
    t = np.asarray(t, np.float64)
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    n = len(t)
    if n == 0:
        z = np.zeros(0)
        return (z, z, z, z) if std else (z, z, None, None)
    idx = np.arange(n)
    step = np.diff(t)
    prev = np.r_[False, same_participant(pid) & (step > 0)]  # row i has a usable predecessor
    nxt = np.r_[prev[1:], False]                               # row i has a usable successor
    lo = np.where(prev, idx - 1, idx)
    hi = np.where(nxt, idx + 1, idx)
    hb = np.where(prev, t - t[lo], 1.0)  # 1.0: a placeholder where the neighbour is missing
    hf = np.where(nxt, t[hi] - t, 1.0)
    both = prev & nxt
    w_hi = np.where(both, hb / (hf * (hb + hf)), np.where(nxt, 1.0 / hf, 0.0))
    w_lo = np.where(both, -hf / (hb * (hb + hf)), np.where(prev, -1.0 / hb, 0.0))
    w_mid = -(w_hi + w_lo)  # the weights of a derivative sum to 0
    ok = prev | nxt
    vx = w_hi * x[hi] + w_mid * x + w_lo * x[lo]
    vy = w_hi * y[hi] + w_mid * y + w_lo * y[lo]
    if not std:
        return vx, vy, None, None
    sx = np.zeros(n) if x_std is None else np.nan_to_num(np.asarray(x_std, np.float64))
    sy = np.zeros(n) if y_std is None else np.nan_to_num(np.asarray(y_std, np.float64))
    vx_std = np.where(ok, np.sqrt((w_hi * sx[hi]) ** 2 + (w_mid * sx) ** 2 + (w_lo * sx[lo]) ** 2),
                      np.nan)
    vy_std = np.where(ok, np.sqrt((w_hi * sy[hi]) ** 2 + (w_mid * sy) ** 2 + (w_lo * sy[lo]) ** 2),
                      np.nan)
    return vx, vy, vx_std, vy_std


__all__ = ["central_differences", "finite_quantiles", "fmt_num", "same_participant", "wrap_angle"]


def instant_lateral_steps(same: np.ndarray, dt: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                          lane_heading: np.ndarray, lane_width: np.ndarray, lane_changed: np.ndarray,
                          v_lateral: np.ndarray, max_lateral_speed: float = 3.0) -> np.ndarray:
    """Steps (sample i -> i+1 of one participant; arrays of length n-1) that are instantaneous lane
    changes, as traffic simulators write them by default (SUMO without ``--lanechange.duration``):
    the position moves across the lane by about one lane width (0.5-1.5 of the width at i) into
    an adjacent lane or road (``lane_changed``), faster than ``max_lateral_speed`` (m/s), while
    the velocity across the lane (``v_lateral``, the step's mean) explains less than half of it.

    ``lane_heading``: the lane's direction at i (its sign does not matter), ``lane_width`` at i
    (NaN off the map: never a step)."""
    nx, ny = -np.sin(lane_heading), np.cos(lane_heading)
    lat = dx * nx + dy * ny
    with np.errstate(invalid="ignore", divide="ignore"):
        across = np.abs(lat)
        ok = same & (dt > 0) & np.isfinite(across) & np.isfinite(lane_width) & (lane_width > 0)
        jump = ok & lane_changed & (across >= 0.5 * lane_width) & (across <= 1.5 * lane_width)
        jump &= across / np.where(dt > 0, dt, np.inf) > max_lateral_speed
        jump &= np.abs(lat - np.nan_to_num(v_lateral) * dt) > 0.5 * across
    return jump


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _splitmix64(z: np.ndarray) -> np.ndarray:
    """SplitMix64's output function (Steele et al. 2014) on uint64 arrays (wrapping)."""
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def keyed_normals(seed: int, keys: tuple[np.ndarray, ...], n: int) -> np.ndarray:
    """``(n, m)`` standard normal draws for ``m`` elements, each column a function of ``seed``,
    that element's ``keys`` (integer arrays of length ``m``) and the draw index only: the same
    element gets the same draws whatever else is in the batch (a counter-based generator:
    SplitMix64 of the keys and the counter, Box-Muller). For Monte Carlo whose result must not
    depend on how the rows are split into batches (time windows, subsets)."""
    keys = tuple(np.asarray(k).astype(np.int64).view(np.uint64) for k in keys)
    m = len(keys[0]) if keys else 0
    half = (n + 1) // 2
    with np.errstate(over="ignore"):
        h = np.full(m, np.uint64(seed & 0xFFFFFFFFFFFFFFFF), np.uint64)
        for k in keys:
            h = _splitmix64(h ^ k)
        c = (np.arange(1, half + 1, dtype=np.uint64) * _GOLDEN)[:, None]
        bits = _splitmix64(h[None, :] ^ c)  # (half, m): two 32-bit uniforms each
    u1 = ((bits >> np.uint64(32)).astype(np.float64) + 1.0) * (1.0 / 4294967296.0)  # (0, 1]
    u2 = (bits & np.uint64(0xFFFFFFFF)).astype(np.float64) * (2.0 * np.pi / 4294967296.0)
    r = np.sqrt(-2.0 * np.log(u1))
    out = np.empty((2 * half, m))
    np.multiply(r, np.cos(u2), out=out[:half])
    np.multiply(r, np.sin(u2), out=out[half:])
    return out[:n]


def finite_quantiles(a: np.ndarray, qs: tuple[float, ...]) -> list[np.ndarray]:
    """The quantiles ``qs`` over axis 0 of the finite values of each column of ``a`` (NaN where a
    column has none): the values of ``np.nanquantile`` with its default (linear) method on the
    array with its infinities made NaN, from one sort of the whole array instead of its loop
    over columns (``apply_along_axis``, ~100 us per column; Monte Carlo stds have 10^5-10^6)."""
    a = np.asarray(a, float)
    fin = np.isfinite(a)
    n = fin.sum(0)
    srt = np.sort(np.where(fin, a, np.inf), axis=0)  # the finite values first, in order
    out = []
    for q in qs:
        vi = (n - 1) * float(q)
        lo = np.clip(np.floor(vi), 0, np.maximum(n - 1, 0)).astype(np.int64)
        hi = np.minimum(lo + 1, np.maximum(n - 1, 0))
        x0 = np.take_along_axis(srt, lo[None], 0)[0] if a.shape[0] else np.full(n.shape, np.nan)
        x1 = np.take_along_axis(srt, hi[None], 0)[0] if a.shape[0] else x0
        t = vi - lo
        with np.errstate(invalid="ignore"):
            d = x1 - x0
            # numpy's _lerp: from the nearer end, so that t = 1 gives x1 exactly
            v = np.where(t >= 0.5, x1 - d * (1 - t), x0 + d * t)
        out.append(np.where(n > 0, v, np.nan))
    return out


class small_pages:
    """Within the block, numpy's large arrays are not advised onto transparent huge pages (numpy
    advises them by default on Linux): where the kernel compacts memory to give a huge page on
    first touch (``defrag`` = ``madvise``, the usual setting), every fresh array of the import's
    millions of rows costs a stall — measured here, 16 MB arrays allocated and filled 2.8x faster
    without the advice (docs/performance.md). A no-op where numpy has no such switch."""

    def __enter__(self):
        setter = getattr(getattr(np, "_core", None), "multiarray", None)
        self._set = getattr(setter, "_set_madvise_hugepage", None)
        self._was = self._set(False) if self._set is not None else None
        return self

    def __exit__(self, *exc):
        if self._set is not None:
            self._set(bool(self._was))


class no_gc:
    """Pause the cyclic garbage collector while building or walking millions of small objects
    (it otherwise runs again and again over a growing, acyclic document)."""

    def __enter__(self):
        import gc

        self._was = gc.isenabled()
        gc.disable()

    def __exit__(self, *exc):
        import gc

        if self._was:
            gc.enable()
