"""Figures of derived tables: time series of one participant with their 1-sigma bands.

- :func:`ttc_figure`: the TTC of one participant to another over time (``derived/interactions``),
  one series per ``ttc_kind`` (2D box TTC while the other is a neighbour, lane-based 1D TTC while it
  is the leader), each with its ±1 std band.
- :func:`acceleration_figure`: derived longitudinal/lateral acceleration of one participant
  (``derived/kinematics``) with its ±1 std band, optionally against the truth.

Both take the derived tables and return a standalone matplotlib ``Figure`` (no pyplot state); write
it with :func:`aveas_format.safeio.save_figure_atomic`. ``tools/derive_figures.py`` makes the
figures of docs/derive.md with them.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pyarrow as pa
from matplotlib.figure import Figure

from aveas_format.io.arrow import column_numpy

#: colour and legend label per ``ttc_kind``, in drawing order
TTC_KINDS: dict[str, tuple[str, str]] = {
    "box_2d": ("tab:orange", "2D boxes (neighbour)"),
    "lane_1d": ("tab:blue", "1D lane (leader)"),
}


def _ids(t: pa.Table, name: str) -> np.ndarray:
    """An id column as it is (int64; a column with nulls comes as float with NaN)."""
    return np.asarray(t.column(name).to_numpy(zero_copy_only=False))


def ttc_figure(interactions: pa.Table, participant_id: int, other_id: int, *,
               highlight: tuple[float, float, str] | None = None,
               xlim: tuple[float, float] | None = None, ylim: tuple[float, float] = (0.0, 10.0),
               ylabel: str | None = None, title: str | None = None) -> Figure:
    """TTC of ``participant_id`` to ``other_id`` over time, by ``ttc_kind`` with ±1 std bands
    (a null ``ttc_std`` draws no band). ``highlight``: ``(t0, t1, label)``, a shaded time span (a
    manoeuvre)."""
    fig = Figure(figsize=(7, 3.4))
    ax = fig.subplots()
    pair = (_ids(interactions, "participant_id") == participant_id) & (
        _ids(interactions, "other_id") == other_id)
    pair &= interactions.column("ttc").is_valid().to_numpy(zero_copy_only=False)
    kind = np.asarray(interactions.column("ttc_kind").to_pylist(), dtype=object)
    time, ttc = column_numpy(interactions, "time"), column_numpy(interactions, "ttc")
    std = column_numpy(interactions, "ttc_std", null=0.0)
    for k, (colour, label) in TTC_KINDS.items():
        m = pair & (kind == k)
        if not m.any():
            continue
        t, v, s = time[m], ttc[m], std[m]
        ax.plot(t, v, ".", ms=3, color=colour, label=label)
        ax.fill_between(t, v - s, v + s, color=colour, alpha=0.25, lw=0)
    if highlight is not None:
        ax.axvspan(highlight[0], highlight[1], color="0.9", zorder=0, label=highlight[2])
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel or f"TTC of {participant_id} to {other_id} (s)")
    ax.set_ylim(*ylim)
    ax.legend(loc="upper right", fontsize=8)
    if xlim is not None:
        ax.set_xlim(*xlim)
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return fig


def acceleration_figure(kinematics: pa.Table, participant_id: int, *,
                        truth: Mapping[str, np.ndarray] | None = None,
                        title: str | None = None) -> Figure:
    """Derived ``ax`` (top) and ``ay`` (bottom) of ``participant_id`` over time with ±1 std bands;
    ``truth``: ``{"ax": ..., "ay": ...}`` aligned with the rows of ``kinematics``, drawn dashed."""
    fig = Figure(figsize=(7, 4.6))
    axes = fig.subplots(2, 1, sharex=True)
    m = _ids(kinematics, "participant_id") == participant_id
    t = column_numpy(kinematics, "time")[m]
    for a, col in ((axes[0], "ax"), (axes[1], "ay")):
        v = column_numpy(kinematics, col)[m]
        s = column_numpy(kinematics, f"{col}_std")[m]
        a.fill_between(t, v - s, v + s, color="tab:blue", alpha=0.25, lw=0, label="±1 std")
        a.plot(t, v, color="tab:blue", lw=1, label=f"derived {col}")
        if truth is not None:
            a.plot(t, np.asarray(truth[col])[m], color="k", lw=1, ls="--", label="truth")
        a.set_ylabel(f"{col} (m/s²)")
    axes[0].legend(loc="upper right", fontsize=8, ncol=3)
    axes[1].set_xlabel("time (s)")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    return fig


__all__ = ["TTC_KINDS", "acceleration_figure", "ttc_figure"]
