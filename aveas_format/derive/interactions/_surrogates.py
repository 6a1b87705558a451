"""Surrogate safety measures beyond TTC for the pairs of ``derived/interactions``: DRAC, MDRAC and
PSD with their standard deviations (docs/derive.md "Surrogate safety measures").

Lane pairs (a follower and its leader along the lane, 1D), with the gap ``g`` (net, bumper to
bumper), the closing speed ``Δv = v_f - v_l`` and the follower's speed ``v_f``:

- **DRAC** ``= Δv² / (2 g)``: the constant deceleration of the follower (relative to the leader)
  that just avoids contact (Cooper & Ferguson 1976; SUMO's SSM device); null where not closing or
  in contact (``g <= 0``, where TTC is 0).
- **MDRAC** ``= Δv / (2 (TTC - PRT))`` with TTC ``= g / Δv``: DRAC after a perception-reaction
  time ``PRT`` (Fazekas et al. 2017; SUMO's ``device.ssm.mdrac.prt``, 1 s); null where
  ``TTC <= PRT`` (no deceleration avoids contact after the reaction) or not closing.
- **PSD** ``= g / (v_f² / (2 d_max))``: the remaining distance to the potential collision point
  (the leader's current rear) over the follower's minimum stopping distance at ``d_max``
  (Allen et al. 1978); < 1: the follower cannot stop before that point. Null where ``v_f <= 0``.

Their std is the delta method on the gap and speed variances (analytic derivatives below), as for
the 1D TTC.

2D pairs (neighbours and conflicting pairs with a box TTC), with the relative velocity ``w``:
``DRAC = |w| / (2 TTC)`` — the smallest constant deceleration of the relative motion, along
``w``, that stops it before the first contact (under constant velocity the relative position moves
along ``w`` and reaches contact after ``|w| TTC``; stopping within that distance needs
``|w|² / (2 a) <= |w| TTC``); it equals ``Δv² / (2 g)`` for two vehicles in line. ``MDRAC = |w| /
(2 (TTC - PRT))``; ``PSD = 2 d_max TTC / |v_i|`` (the participant's own distance to the contact,
``|v_i| TTC``, over its stopping distance). Their std comes from the same Monte Carlo draws as the
2D TTC's.
"""

from __future__ import annotations

import numpy as np

from aveas_format.numeric import finite_quantiles


def lane_surrogates(gap: np.ndarray, gap_var: np.ndarray, dv: np.ndarray, dv_var: np.ndarray,
                    vf: np.ndarray, vf_var: np.ndarray, reaction_time: float,
                    max_deceleration: float) -> dict[str, np.ndarray]:
    """``drac``, ``mdrac``, ``psd`` and their ``_std`` for follower/leader pairs (NaN where
    undefined); see the module docstring."""
    g, dv, vf = (np.asarray(a, float) for a in (gap, dv, vf))
    sg2, sdv2, svf2 = (np.nan_to_num(np.asarray(a, float)) for a in (gap_var, dv_var, vf_var))
    R, d = float(reaction_time), float(max_deceleration)
    closing = (dv > 0) & (g > 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        drac = np.where(closing, 0.5 * dv * dv / g, np.nan)
        # ∂/∂Δv = Δv / g, ∂/∂g = -Δv² / (2 g²)
        drac_std = np.sqrt((dv / g) ** 2 * sdv2 + (0.5 * dv * dv / (g * g)) ** 2 * sg2)
        den = g - R * dv  # = Δv (TTC - PRT)
        ok = closing & (den > 0)
        mdrac = np.where(ok, 0.5 * dv * dv / den, np.nan)
        # MDRAC = Δv² / (2 (g - R Δv)): ∂/∂g = -Δv² / (2 den²), ∂/∂Δv = Δv (g - R Δv / 2) / den²
        mdrac_std = np.sqrt((0.5 * dv * dv / den ** 2) ** 2 * sg2
                            + (dv * (g - 0.5 * R * dv) / den ** 2) ** 2 * sdv2)
        moving = vf > 0
        psd = np.where(moving, 2.0 * d * g / (vf * vf), np.nan)
        # ∂/∂g = 2 d / v², ∂/∂v = -4 d g / v³
        psd_std = np.sqrt((2.0 * d / (vf * vf)) ** 2 * sg2 + (4.0 * d * g / vf ** 3) ** 2 * svf2)
    return {"drac": drac, "drac_std": np.where(closing, drac_std, np.nan),
            "mdrac": mdrac, "mdrac_std": np.where(ok, mdrac_std, np.nan),
            "psd": psd, "psd_std": np.where(moving, psd_std, np.nan)}


def box_surrogates(ttc: np.ndarray, rel_speed: np.ndarray, own_speed: np.ndarray,
                   reaction_time: float, max_deceleration: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(drac, mdrac, psd)`` of 2D pairs from their box TTC, the magnitude of their relative
    velocity and the participant's own speed (any broadcastable shapes; NaN where undefined)."""
    ttc, w, v = (np.asarray(a, float) for a in (ttc, rel_speed, own_speed))
    R, d = float(reaction_time), float(max_deceleration)
    fin = np.isfinite(ttc) & (ttc > 0) & (w > 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        drac = np.where(fin, 0.5 * w / ttc, np.nan)
        mdrac = np.where(fin & (ttc > R), 0.5 * w / (ttc - R), np.nan)
        psd = np.where(np.isfinite(ttc) & (v > 0), 2.0 * d * ttc / v, np.nan)
    return drac, mdrac, psd


def sample_std(samples: np.ndarray, min_share: float = 0.5) -> np.ndarray:
    """The spread over axis 0 of Monte Carlo samples as a standard deviation: the interquartile
    range of the finite ones / 1.349 (the std where they are normal; NaN where fewer than
    ``min_share`` of them are finite). A TTC of a nearly parallel relative motion is a gap over
    a closing speed near 0: its draws have a heavy tail (up to 50x the median in the demo's
    closest encounter) whose sample std does not settle (docs/derive.md), the quartiles do."""
    cnt = np.isfinite(samples).sum(0)
    q1, q3 = finite_quantiles(samples, (0.25, 0.75))  # = np.nanquantile, vectorised
    return np.where(cnt >= max(min_share * samples.shape[0], 2), (q3 - q1) / 1.349, np.nan)
