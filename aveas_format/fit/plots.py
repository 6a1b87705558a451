"""Figures of a fit: recorded histogram vs simulated KDE per class (the paper's "IV_histogram") and
start/end parameters per restart (the paper's "IV_Parameters")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.fit.objective import kde_logpdf

COLOURS = {"car": ("tab:blue", "black"), "truck": ("tab:green", "tab:orange")}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_histogram(recorded: dict[str, np.ndarray], simulated: dict[str, np.ndarray], path: str | Path,
                   *, bandwidth: str | float = "silverman", unit: str = "km/h") -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    allv = np.concatenate([np.asarray(v) for v in [*recorded.values(), *simulated.values()] if len(v)])
    grid = np.linspace(allv.min() - 10, allv.max() + 10, 400)
    bins = np.arange(np.floor(allv.min() / 2.5) * 2.5, allv.max() + 2.5, 2.5)
    for c, v in recorded.items():
        hc, kc = COLOURS.get(c, (None, None))
        if len(v):
            ax.hist(v, bins=bins, density=True, alpha=0.5, color=hc, label=f"recorded {c} (n={len(v)})")
        s = simulated.get(c, np.empty(0))
        if len(s):
            ax.plot(grid, np.exp(kde_logpdf(s, grid, bandwidth)), color=kc, lw=2,
                    label=f"simulated {c} KDE (n={len(s)})")
    ax.set_xlabel(f"mean speed ({unit})")
    ax.set_ylabel("density")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_parameters(runs: list[dict], classes: list[str], path: str | Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 5))
    for k, c in enumerate(classes):
        col = COLOURS.get(c, ("tab:red",))[0]
        ax.scatter([r[f"start_mu_{c}"] for r in runs], [r[f"start_sigma_{c}"] for r in runs], s=12,
                   color="0.6", label="starts" if k == 0 else None)
        ax.scatter([r[f"mu_{c}"] for r in runs], [r[f"sigma_{c}"] for r in runs], s=18, color=col,
                   label=f"end ({c})")
        for r in runs:
            ax.plot([r[f"start_mu_{c}"], r[f"mu_{c}"]], [r[f"start_sigma_{c}"], r[f"sigma_{c}"]],
                    color="0.85", lw=0.5, zorder=0)
    if runs:
        best = min(runs, key=lambda r: r["fun"])
        for c in classes:
            ax.scatter([best[f"mu_{c}"]], [best[f"sigma_{c}"]], marker="*", s=150, color="red",
                       zorder=5, label="best" if c == classes[0] else None)
    ax.set_xlabel("mu (km/h)")
    ax.set_ylabel("sigma (km/h)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)
