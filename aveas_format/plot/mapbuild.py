"""The figure of a map built from trajectories (``aveas-format map build --figure``): the built
lanes with the trajectories over them, and the lateral residuals of the trajectories per lane."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.errors import require
from aveas_format.plot.map import plot_map
from aveas_format.safeio import save_figure_atomic


def plot_build(net, x: np.ndarray, y: np.ndarray, heading: np.ndarray | None = None, *, points: int = 20000,
               seed: int = 0, title: str | None = None):
    """Left: the built map (lanes by type, reference lines) with a sample of ``points`` trajectory
    points over it; right: per lane, the distribution of the points' distance from its centre
    (``lane_offset``, the map's fit residual). Returns the figure."""
    require("matplotlib", extra="plot", what="figures")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(seed)
    idx = np.arange(len(x)) if len(x) <= points else np.sort(rng.choice(len(x), points, replace=False))
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.2), gridspec_kw={"width_ratios": [2.2, 1]})
    plot_map(net, ax, labels=True, legend=False, title=title or "built map and trajectories")
    ax.plot(x[idx], y[idx], ".", ms=0.6, color="#1f4e99", alpha=0.35, rasterized=True)
    x0, y0, x1, y1 = net.bounds
    if max(x1 - x0, y1 - y0) > 4 * min(x1 - x0, y1 - y0):  # a long, thin site: 150 m of it, up close
        cx, cy = float(np.median(x)), float(np.median(y))
        ax.set_xlim(cx - 75, cx + 75)
        ax.set_ylim(cy - 40, cy + 40)
    pr = net.world_to_road(x[idx], y[idx], None if heading is None else heading[idx], drivable_only=True)
    on = pr.n_candidates > 0
    keys = np.array([f"road {r} lane {l}" for r, l in zip(pr.road_id[on], pr.lane_id[on])])
    off = pr.lane_offset[on]
    uniq, counts = np.unique(keys, return_counts=True)
    top = uniq[np.argsort(-counts)][:8]
    bins = np.linspace(-1.5, 1.5, 61)
    for k in sorted(top):
        bx.hist(off[keys == k], bins=bins, histtype="step", lw=1.2, label=k)
    p95 = float(np.percentile(np.abs(off), 95)) if on.any() else float("nan")
    bx.set_xlabel("lateral offset from the lane centre [m]")
    bx.set_ylabel("points")
    bx.set_title(f"residuals: p95 {p95:.2f} m, {100 * on.mean():.1f} % on a lane", fontsize=10)
    bx.legend(fontsize=7)
    fig.tight_layout()
    return fig


def save_build(net, path: str | Path, x, y, heading=None, *, dpi: int = 120, **kw: Any) -> Path:
    """:func:`plot_build` written to ``path`` (PNG, SVG or PDF by the suffix)."""
    return save_figure_atomic(plot_build(net, x, y, heading, **kw), path, dpi=dpi)


__all__ = ["plot_build", "save_build"]
