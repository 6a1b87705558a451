"""Figures of a fit: recorded histogram vs simulated density per class (the paper's "IV_histogram")
and start/end parameters per restart (the paper's "IV_Parameters").

The fitter (:mod:`aveas_format.fit.optimize`) calls these with its data; the density of the
simulated values comes from the fitter as a callable (its KDE), so this module only draws.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from aveas_format.plot._mpl import Figure
from aveas_format.safeio import save_figure_atomic

#: (histogram colour, density colour) per class
COLOURS = {"car": ("tab:blue", "black"), "truck": ("tab:green", "tab:orange")}


def plot_histogram(recorded: dict[str, np.ndarray], simulated: dict[str, np.ndarray], path: str | Path,
                   *, density: Callable[[np.ndarray, np.ndarray], np.ndarray], unit: str = "km/h",
                   label: str = "mean speed") -> Path:
    """Histogram of the recorded values per class with the simulated density over it, written to
    ``path``. ``density(samples, grid)`` is the density of ``samples`` at the points ``grid`` (the
    fitter passes its KDE, so the curve is the one its likelihood uses)."""
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    parts = [np.asarray(v) for v in [*recorded.values(), *simulated.values()] if len(v)]
    allv = np.concatenate(parts) if parts else np.zeros(1)
    lo, hi = float(allv.min()), float(allv.max())
    width = 2.5 if unit == "km/h" else max((hi - lo) / 40, 1e-3)  # the paper's 2.5 km/h bins
    pad = 10.0 if unit == "km/h" else 0.1 * (hi - lo) + width
    grid = np.linspace(lo - pad, hi + pad, 400)
    bins = np.arange(np.floor(lo / width) * width, hi + width, width)
    for c, v in recorded.items():
        hc, kc = COLOURS.get(c, (None, None))
        if len(v):
            ax.hist(v, bins=bins, density=True, alpha=0.5, color=hc, label=f"recorded {c} (n={len(v)})")
        s = simulated.get(c, np.empty(0))
        if len(s):
            ax.plot(grid, density(s, grid), color=kc, lw=2,
                    label=f"simulated {c} KDE (n={len(s)})")
    ax.set_xlabel(f"{label} ({unit})")
    ax.set_ylabel("density")
    ax.legend()
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)
    return Path(path)


def _axes_pairs(names: list[str]) -> list[tuple[str, str | None]]:
    """The (x, y) parameter pairs to draw: (mu, sigma) per class, else consecutive pairs; a lone
    parameter is drawn as end against start (y None)."""
    pairs, rest = [], []
    for n in names:
        kind, _, c = n.partition("_")
        if kind == "mu" and f"sigma_{c}" in names:
            pairs.append((n, f"sigma_{c}"))
        elif not (kind == "sigma" and f"mu_{c}" in names):
            rest.append(n)
    pairs += [(rest[i], rest[i + 1] if i + 1 < len(rest) else None) for i in range(0, len(rest), 2)]
    return pairs


def plot_parameters(runs: list[dict], names: list[str], path: str | Path, *,
                    estimate: dict[str, float] | None = None, se: dict[str, float] | None = None
                    ) -> Path:
    """Start (grey) and end (colour) parameters of every restart, the best as a red star; with
    ``estimate`` (and ``se``) the fit's estimate as a black cross with its 95 % intervals."""
    pairs = _axes_pairs(names)
    same_axes = all(x.startswith("mu_") for x, _ in pairs)  # the paper's figure: one (mu, sigma) plot
    n_ax = 1 if same_axes else len(pairs)
    fig = Figure(figsize=(5 * n_ax, 5))
    axes = fig.subplots(1, n_ax, squeeze=False)
    best = min(runs, key=lambda r: r["fun"]) if runs else None
    for k, (xn, yn) in enumerate(pairs):
        ax = axes[0, 0 if same_axes else k]
        c = xn.partition("_")[2]
        col = COLOURS.get(c, ("tab:red",))[0]

        if yn is None:  # one parameter: where each restart started and ended
            ax.scatter([r[f"start_{xn}"] for r in runs], [r[xn] for r in runs], s=18, color=col,
                       label="restarts")
            if best is not None:
                ax.scatter([best[f"start_{xn}"]], [best[xn]], marker="*", s=150, color="red",
                           zorder=5, label="best")
            if estimate is not None:
                ax.axhline(estimate[xn], color="black", lw=1, label="estimate")
                if se is not None and np.isfinite(se.get(xn, np.nan)):
                    ax.axhspan(estimate[xn] - 1.96 * se[xn], estimate[xn] + 1.96 * se[xn],
                               color="black", alpha=0.1, label="95 % interval")
            ax.set_xlabel(f"start {xn}")
            ax.set_ylabel(f"end {xn}")
            ax.legend(fontsize=8)
            continue
        ax.scatter([r[f"start_{xn}"] for r in runs], [r[f"start_{yn}"] for r in runs], s=12,
                   color="0.6", label="starts" if k == 0 or not same_axes else None)
        for r in runs:
            ax.plot([r[f"start_{xn}"], r[xn]], [r[f"start_{yn}"], r[yn]], color="0.85", lw=0.5,
                    zorder=0)
        ax.scatter([r[xn] for r in runs], [r[yn] for r in runs], s=18, color=col,
                   label=f"end ({c})" if same_axes else "end")
        if best is not None:
            ax.scatter([best[xn]], [best[yn]], marker="*", s=150, color="red", zorder=5,
                       label="best restart" if k == 0 or not same_axes else None)
        if estimate is not None:
            err = None
            if se is not None:
                err = ([1.96 * se.get(xn, np.nan)], [1.96 * se.get(yn, np.nan)])
            ax.errorbar([estimate[xn]], [estimate[yn]], xerr=None if err is None else err[0],
                        yerr=None if err is None else err[1], fmt="x", color="black", ms=9, mew=2,
                        capsize=3, zorder=6,
                        label="estimate (95 % interval)" if k == 0 or not same_axes else None)
        if same_axes:
            ax.set_xlabel("mu (km/h)")
            ax.set_ylabel("sigma (km/h)")
        else:
            ax.set_xlabel(xn)
            ax.set_ylabel(yn)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=120)
    return Path(path)


def plot_recovery(rows: list[dict], truth: dict[str, float], names: list[str], sizes: list[str],
                  path: str | Path) -> Path:
    """The recovery study: per sample size (rows) and parameter (columns) every replicate's
    estimate with its 95 % interval, the truth (line) and the sampling floor (the recorded
    vehicles' own desired-speed moments, grey dots)."""
    from matplotlib.ticker import MaxNLocator

    sizes = [s for s in sizes if any(r["size"] == s for r in rows)]
    fig = Figure(figsize=(3.2 * len(names), 2.8 * max(len(sizes), 1)))
    axes = fig.subplots(max(len(sizes), 1), len(names), squeeze=False)
    for i, size in enumerate(sizes):
        rs = sorted((r for r in rows if r["size"] == size), key=lambda r: r["seed"])
        seeds = [r["seed"] for r in rs]
        for j, n in enumerate(names):
            ax = axes[i, j]
            c = n.partition("_")[2]
            col = COLOURS.get(c, ("tab:red",))[0]
            est = np.array([r[n] for r in rs], np.float64)
            se = np.array([np.nan if r.get(f"se_{n}") is None else r[f"se_{n}"] for r in rs], np.float64)
            ax.errorbar(seeds, est, yerr=np.where(np.isfinite(se), 1.96 * se, 0), fmt="o", color=col,
                        ms=4, capsize=2, label="estimate, 95 % interval")
            floor = [r.get(f"floor_{n}") for r in rs]
            if all(v is not None for v in floor):
                ax.scatter(seeds, floor, marker="_", s=80, color="0.4", label="sampling floor")
            ax.axhline(truth[n], color="black", lw=1, label="truth")
            e = est - truth[n]
            ax.set_title(f"{n} ({size}): bias {e.mean():+.2f}, RMSE {np.sqrt(np.mean(e ** 2)):.2f}",
                         fontsize=8)
            ax.set_xlabel("seed", fontsize=8)
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.tick_params(labelsize=7)
            if i == 0 and j == 0:
                ax.legend(fontsize=6)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    return Path(path)
