"""Array helpers every layer shares (numpy only; foundation layer, below ``schema``).

One home for the small numerical conventions of the package, so that they cannot drift apart:
angle wrapping and the per-participant segmentation of ``(participant_id, time)``-sorted rows.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to (-pi, pi] (the format's heading range; -pi maps to +pi)."""
    w = np.mod(np.asarray(a, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def same_participant(pid: np.ndarray) -> np.ndarray:
    """Boolean mask of length n-1: row i and row i+1 belong to the same participant (rows sorted
    by participant, then time)."""
    pid = np.asarray(pid)
    return pid[1:] == pid[:-1]


__all__ = ["same_participant", "wrap_angle"]
