"""Figures of derived tables: time series of one participant with their 1-sigma bands.

- :func:`ttc_figure`: the TTC of one participant to another over time (``derived/interactions``),
  one series per ``ttc_kind`` (2D box TTC while the other is a neighbour, lane-based 1D TTC while it
  is the leader), each with its ±1 std band.
- :func:`ttc_drac_figure`: TTC and DRAC of one pair over time, each with its ±1 std band.
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

from aveas_format.io.arrow import column_numpy
from aveas_format.plot._mpl import Figure

#: colour and legend label per ``ttc_kind``, in drawing order
TTC_KINDS: dict[str, tuple[str, str]] = {
    "box_2d": ("tab:orange", "2D boxes (neighbour)"),
    "lane_1d": ("tab:blue", "1D lane (leader)"),
}


def _is(t: pa.Table, name: str, value: int) -> np.ndarray:
    """Rows whose id column equals ``value``, compared as int64 (never through float64, which
    merges ids above 2**53); null ids match nothing."""
    import pyarrow.compute as pc

    eq = pc.equal(t.column(name), pa.scalar(int(value), t.column(name).type))
    return np.asarray(pc.fill_null(eq, False).to_numpy(zero_copy_only=False), bool)


def ttc_figure(interactions: pa.Table, participant_id: int, other_id: int, *,
               highlight: tuple[float, float, str] | None = None,
               xlim: tuple[float, float] | None = None, ylim: tuple[float, float] = (0.0, 10.0),
               ylabel: str | None = None, title: str | None = None) -> Figure:
    """TTC of ``participant_id`` to ``other_id`` over time, by ``ttc_kind`` with ±1 std bands
    (a null ``ttc_std`` draws no band). ``highlight``: ``(t0, t1, label)``, a shaded time span (a
    manoeuvre)."""
    fig = Figure(figsize=(7, 3.4))
    ax = fig.subplots()
    pair = _is(interactions, "participant_id", participant_id) & _is(interactions, "other_id",
                                                                    other_id)
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
    m = _is(kinematics, "participant_id", participant_id)
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


def ttc_drac_figure(interactions: pa.Table, participant_id: int, other_id: int, *,
                    xlim: tuple[float, float] | None = None, ttc_max: float = 10.0,
                    title: str | None = None, axes=None,
                    span: tuple[float, float] | None = None) -> Figure:
    """TTC (top) and DRAC (bottom) of ``participant_id`` to ``other_id`` over time with their
    ±1 std bands where the rows have a std, by ``ttc_kind`` (the rows of
    ``derived/interactions`` of that pair; DRAC is drawn where it is defined, i.e. while the pair
    closes in). ``axes``: two axes to draw into (their figure is returned; else a new figure),
    ``span``: a time span to shade (a critical episode)."""
    if axes is None:
        fig = Figure(figsize=(7, 4.8))
        axes = fig.subplots(2, 1, sharex=True)
        own = True
    else:
        fig = axes[0].figure
        own = False
    pair = _is(interactions, "participant_id", participant_id) & _is(interactions, "other_id", other_id)
    kind = np.asarray(interactions.column("ttc_kind").to_pylist(), dtype=object)
    time = column_numpy(interactions, "time")
    banded = False
    for a, col, unit in ((axes[0], "ttc", "s"), (axes[1], "drac", "m/s²")):
        if col not in interactions.column_names:
            continue
        v = column_numpy(interactions, col)
        sd = (column_numpy(interactions, f"{col}_std") if f"{col}_std" in
              interactions.column_names else np.full(len(v), np.nan))
        for k, (colour, label) in TTC_KINDS.items():
            m = pair & (kind == k) & np.isfinite(v)
            if not m.any():
                continue
            o = np.argsort(time[m])
            t, y, e = time[m][o], v[m][o], sd[m][o]
            if len(t) > 2:  # no line across gaps (where the pair had no such row)
                gap = np.flatnonzero(np.diff(t) > 3 * np.median(np.diff(t)))
                t, y, e = (np.insert(a_, gap + 1, np.nan) for a_ in (t, y, e))
            a.plot(t, y, ".-", ms=3, lw=0.8, color=colour, label=label)
            # a band where the value is drawn (a TTC far above the axis with a std of its size
            # would paint the whole height)
            has = np.isfinite(e) & (y <= (ttc_max if col == "ttc" else np.inf))
            if has.any():
                banded = True
                a.fill_between(t, y - e, y + e, where=has, color=colour, alpha=0.3, lw=0,
                               label=f"±1 std ({label.split(' (')[0]})" if col == "ttc" else None)
        if span is not None:
            a.axvspan(span[0], span[1], color="0.85", zorder=0)
        a.set_ylabel(f"{col.upper()} ({unit})")
    axes[0].set_ylim(0.0, ttc_max)
    axes[1].set_ylim(bottom=0.0)
    axes[1].set_xlabel("time (s)")
    if not own:
        axes[0].set_xlabel("time (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        axes[0].legend(loc="upper right", fontsize=7)
    if xlim is not None:
        axes[1].set_xlim(*xlim)
    what = "TTC and DRAC" + (" ± 1 std (shaded)" if banded else " (no std)")
    axes[0].set_title(title or f"participant {participant_id} to {other_id}: {what}",
                      fontsize=9 if not own else None)
    if own:
        fig.tight_layout()
    return fig


__all__ = ["TTC_KINDS", "acceleration_figure", "ttc_drac_figure", "ttc_figure"]
