"""The figure of the W99 sensitivity study (the paper's figure "WiedemannPara"): per parameter, the
smallest mean TTC and the smallest TTC of the altered vehicles against the position of the varied
value within the parameter's range.

The rows and the ranges come from :mod:`aveas_format.sim.sensitivity` (``sensitivity`` and
``W99_RANGES``); this module only draws.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path


from aveas_format.plot._mpl import Figure
from aveas_format.safeio import save_figure_atomic


def plot_sensitivity(rows: list[dict], path: str | Path,
                     ranges: Mapping[str, tuple[float, float]]) -> Path:
    """Draw ``rows`` (``param``, ``value``, ``min_mean_ttc``, ``min_ttc``; rows with ``error`` are
    left out) into ``path``; x is ``(value - start) / (end - start)`` with ``ranges[param]``."""
    fig = Figure(figsize=(7, 6))
    axes = fig.subplots(2, 1, sharex=True)
    for p in sorted({r["param"] for r in rows}):
        rs = [r for r in rows if r["param"] == p and "error" not in r]
        if not rs:
            continue
        lo, hi = ranges[p]
        x = [(r["value"] - lo) / (hi - lo) for r in rs]  # normalised position in the range
        axes[0].plot(x, [r["min_mean_ttc"] for r in rs], marker="o", label=p)
        axes[1].plot(x, [r["min_ttc"] for r in rs], marker="o", label=p)
    axes[0].set_ylabel("min mean TTC (s)")
    axes[1].set_ylabel("min TTC (s)")
    axes[1].set_xlabel("position in the parameter's range (start -> end)")
    axes[0].legend(ncol=5, fontsize=7)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)
    return Path(path)


__all__ = ["plot_sensitivity"]
