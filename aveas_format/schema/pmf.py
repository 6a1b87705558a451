"""Helpers for PMF, binary-probability and Gaussian columns on numpy arrays.

A PMF column is held here as a 2D float array of shape (rows, categories), categories in the order
of the category set; ``aveas_format.io.arrow`` converts Arrow struct columns to and from this form.
"""

from __future__ import annotations

import numpy as np

from aveas_format.schema.taxonomy import CATEGORY_SETS, PMF_TOLERANCE

STD_SUFFIX = "_std"
CORR_PAIRS: dict[str, tuple[str, str]] = {
    "xy_corr": ("x", "y"),
    "vxvy_corr": ("vx", "vy"),
    "axay_corr": ("ax", "ay"),
}


def std_name(column: str) -> str:
    """``x`` -> ``x_std``."""
    return column + STD_SUFFIX


def base_of_std(column: str) -> str | None:
    """``x_std`` -> ``x``; None if not a ``_std`` column."""
    return column[: -len(STD_SUFFIX)] if column.endswith(STD_SUFFIX) else None


def categories(set_name: str) -> tuple[str, ...]:
    return CATEGORY_SETS[set_name]


def one_hot(labels: np.ndarray | list[str], set_name: str) -> np.ndarray:
    """A (n, k) float32 PMF matrix that puts all mass on each row's label."""
    cats = CATEGORY_SETS[set_name]
    index = {c: i for i, c in enumerate(cats)}
    labels = np.asarray(labels, dtype=object)
    try:
        idx = np.fromiter((index[v] for v in labels), dtype=np.int64, count=len(labels))
    except KeyError as e:
        raise ValueError(f"unknown {set_name} category {e.args[0]!r}; expected one of {list(cats)}") from None
    out = np.zeros((len(labels), len(cats)), dtype=np.float32)
    out[np.arange(len(labels)), idx] = 1.0
    return out


def argmax(matrix: np.ndarray, set_name: str) -> np.ndarray:
    """Most probable category of each row (object array of category names). Ties: first in order."""
    cats = np.asarray(CATEGORY_SETS[set_name], dtype=object)
    return cats[np.argmax(np.asarray(matrix), axis=1)]


def pmf_problems(matrix: np.ndarray, tol: float = PMF_TOLERANCE) -> np.ndarray:
    """Boolean mask of rows that are not a valid PMF (negative, non-finite, or sum != 1 +- tol).

    Rows that are entirely NaN (a null struct) are not flagged: null means 'unknown'.
    """
    m = np.asarray(matrix, dtype=np.float64)
    allnan = np.isnan(m).all(axis=1)
    bad = ~np.isfinite(m).all(axis=1) | (m < 0).any(axis=1) | (np.abs(m.sum(axis=1) - 1.0) > tol)
    return bad & ~allnan


def normalise(matrix: np.ndarray) -> np.ndarray:
    """Rows scaled to sum to 1 (float32); rows summing to 0 become uniform."""
    m = np.clip(np.asarray(matrix, dtype=np.float64), 0.0, None)
    s = m.sum(axis=1, keepdims=True)
    k = m.shape[1]
    out = np.where(s > 0, m / np.where(s > 0, s, 1.0), 1.0 / k)
    return out.astype(np.float32)


def probability_problems(p: np.ndarray) -> np.ndarray:
    """Mask of binary probabilities outside [0, 1] or non-finite (NaN = null is fine)."""
    p = np.asarray(p, dtype=np.float64)
    return ~np.isnan(p) & (~np.isfinite(p) | (p < 0) | (p > 1))


def std_problems(std: np.ndarray) -> np.ndarray:
    """Mask of standard deviations that are negative or infinite (NaN = unknown is fine)."""
    s = np.asarray(std, dtype=np.float64)
    return ~np.isnan(s) & (~np.isfinite(s) | (s < 0))


def corr_problems(c: np.ndarray) -> np.ndarray:
    """Mask of correlations outside [-1, 1] or infinite (NaN = unknown is fine)."""
    c = np.asarray(c, dtype=np.float64)
    return ~np.isnan(c) & (~np.isfinite(c) | (c < -1) | (c > 1))


def covariance_2x2(sx: np.ndarray, sy: np.ndarray, rho: np.ndarray | None = None) -> np.ndarray:
    """(n, 2, 2) covariance matrices from two standard deviations and a correlation (default 0)."""
    sx = np.asarray(sx, dtype=np.float64)
    sy = np.asarray(sy, dtype=np.float64)
    r = np.zeros_like(sx) if rho is None else np.nan_to_num(np.asarray(rho, dtype=np.float64))
    cov = np.empty(sx.shape + (2, 2))
    cov[..., 0, 0] = sx * sx
    cov[..., 1, 1] = sy * sy
    cov[..., 0, 1] = cov[..., 1, 0] = r * sx * sy
    return cov
