"""Input checks of the road fit: each polyline becomes an (N, 2) array of distinct consecutive
points, or a :class:`~aveas_format.errors.MapError` (a ValueError) naming the line
(``lines[i]``/``markings[i]``) and where.

Rejected here: fewer than 2 distinct points, non-finite values, points out of order (the direction
turns back), a self-intersecting line. The fit itself rejects lines that cross or do not run
alongside the reference line, and lines farther from it than its curve radius
(:mod:`.road`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from aveas_format.errors import MapError


def as_line(obj: Any, label: str) -> np.ndarray:
    """An (N, 2) float array of distinct consecutive points, checked (see the module doc)."""
    try:
        a = np.asarray(obj, dtype=np.float64)
    except (TypeError, ValueError):
        raise MapError(f"{label}: expected an (N, 2) array of x, y numbers") from None
    if a.ndim != 2 or a.shape[1] not in (2, 3):
        raise MapError(f"{label}: expected an (N, 2) array of x, y; got shape {a.shape}")
    a = a[:, :2]
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MapError(f"{label}: point {i} ({a[i, 0]}, {a[i, 1]}) is not finite")
    orig = np.arange(len(a))
    if len(a) > 1:
        keep = np.r_[True, np.hypot(*np.diff(a, axis=0).T) > 1e-9]
        a, orig = a[keep], orig[keep]
    if len(a) < 2:
        raise MapError(f"{label}: has {len(a)} distinct point(s); a line needs at least 2")
    seg = np.diff(a, axis=0)
    ln = np.hypot(seg[:, 0], seg[:, 1])
    if len(a) > 2:
        cos = (seg[:-1] * seg[1:]).sum(1) / (ln[:-1] * ln[1:])
        back = np.flatnonzero(cos < -0.5)
        if len(back):
            i = int(back[0]) + 1
            ang = float(np.degrees(np.arccos(np.clip(cos[back[0]], -1, 1))))
            raise MapError(
                f"{label}: the points are not ordered along the line: the direction turns by "
                f"{ang:.0f} deg at point {int(orig[i])} ({a[i, 0]:.3f}, {a[i, 1]:.3f})"
            )
    if len(a) > 3:
        check_simple(a, label)
    return a


def check_simple(a: np.ndarray, label: str) -> None:
    import shapely

    if shapely.LineString(a).is_simple:
        return
    segs = shapely.linestrings(np.stack([a[:-1], a[1:]], axis=1))
    tree = shapely.STRtree(segs)
    i, j = tree.query(segs, predicate="intersects")
    far = np.abs(i - j) > 1
    if far.any():
        k = int(np.flatnonzero(far)[0])
        p = shapely.intersection(segs[i[k]], segs[j[k]])
        x, y = shapely.get_coordinates(p)[0]
        a0, a1 = sorted((int(i[k]), int(j[k])))
        raise MapError(
            f"{label}: intersects itself near ({x:.3f}, {y:.3f}) (segments {a0} and {a1})"
        )
    raise MapError(f"{label}: intersects itself")

