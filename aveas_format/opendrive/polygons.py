"""Lane polygons (shapely) per lane section, for plotting, occupancy and containment tests."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import shapely

if TYPE_CHECKING:  # pragma: no cover
    from .core import NetworkCore


#: m: lane sections shorter than this have no polygon (they cover no area)
MIN_SECTION_LENGTH = 1e-6


def section_samples(net: NetworkCore, gsec: int, step: float) -> np.ndarray:
    """Sample positions s along lane section ``gsec``: every ``step`` m plus its pieces' starts."""
    lanes = net.lanes
    a, b = lanes.section_start[gsec], lanes.section_end[gsec]
    n = max(2, int(np.ceil((b - a) / step)) + 1)
    first, cnt = lanes.section_first_piece[gsec], lanes.section_npieces[gsec]
    return np.unique(np.concatenate([np.linspace(a, b, n), lanes.piece_start[first : first + cnt]]))


def lane_polygons(net: NetworkCore, step: float = 1.0, drivable_only: bool = False) -> list[tuple[str, int, int, Any]]:
    """``[(road_id, section_index, lane_id, Polygon)]`` for every lane with a non-zero width.

    Each polygon runs along the inner border from the section's start to its end and back along
    the outer border, sampled every ``step`` m and at every change of width polynomial. Lanes
    that fold (wider than the curve radius) give self-intersecting polygons; they are returned as
    they are (``shapely.make_valid`` repairs them if needed). Sections shorter than
    :data:`MIN_SECTION_LENGTH` (zero-length sections such as two ``<laneSection s="0">``) have no
    area and give no polygon; ``map check`` reports them.
    """
    lanes = net.lanes
    out: list[tuple[str, int, int, Any]] = []
    for gsec in range(len(lanes.section_road)):
        if lanes.section_end[gsec] - lanes.section_start[gsec] < MIN_SECTION_LENGTH:
            continue
        ri = int(lanes.section_road[gsec])
        s = section_samples(net, gsec, step)
        piece = lanes.pieces_in_section(gsec, s)
        x, y, h, _, _, _ = net.plan.at(np.full(len(s), ri), s)
        b = lanes.borders(piece, s)
        nx, ny = -np.sin(h), np.cos(h)
        p0 = piece[0]
        road_id = net.road_ids[ri]
        for outers, ids, types in ((b.left, lanes.lid[p0], lanes.ltype[p0]), (b.right, lanes.rid[p0], lanes.rtype[p0])):
            inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
            for k in range(outers.shape[1]):
                lid = int(ids[k])
                if lid == 0:
                    continue
                if drivable_only and not (types[k] >= 0 and net.drivable_code[types[k]]):
                    continue
                ti, to = inners[:, k], outers[:, k]
                if np.max(np.abs(to - ti)) < 1e-9:
                    continue
                xs = np.concatenate([x + ti * nx, (x + to * nx)[::-1]])
                ys = np.concatenate([y + ti * ny, (y + to * ny)[::-1]])
                out.append((road_id, int(lanes.section_local[gsec]), lid, shapely.Polygon(np.column_stack([xs, ys]))))
    return out


__all__ = ["MIN_SECTION_LENGTH", "lane_polygons", "section_samples"]
