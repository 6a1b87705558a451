"""The traffic's flow field, from which :mod:`.tracks` builds a map: where traffic runs in one
direction (carriageways) and where directions cross (junctions).

Points (sampled from moving vehicles) fall into square cells of ``cell`` metres and twelve heading
bins of 30 degrees. In a cell, a direction counts when it holds at least ``share`` of the cell's
points; a **junction cell** holds two that differ by 60 to 120 degrees (traffic crosses or turns;
opposite directions and lane changes do not). Junction cells grown by ``grow`` cells form the
junction areas (each the convex hull of its cells plus ``margin`` metres). Outside them, the
(cell, heading bin) pairs of enough points, linked to those up to ``reach`` cells away whose
headings differ by at most one bin (neighbouring lanes, whose centres are more than a cell apart,
join), form the **carriageways** (connected components): traffic of one direction, however
many lanes, with its curves. All of it is counting (``numpy.bincount``) and one connected-components
call; nothing loops over points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

N_BINS = 12


@dataclass
class Flow:
    """The result of :func:`flow_field`: per point its carriageway (-1: none) and junction (-1:
    none), and the junction areas (shapely polygons)."""

    carriageway: np.ndarray
    junction: np.ndarray
    junction_areas: list
    n_carriageways: int


def _bins(heading: np.ndarray) -> np.ndarray:
    return np.floor(np.mod(heading, 2 * np.pi) / (2 * np.pi / N_BINS)).astype(np.int64) % N_BINS


def flow_field(x: np.ndarray, y: np.ndarray, heading: np.ndarray, *, cell: float = 2.0, share: float = 0.15,
               min_points: int = 5, grow: int = 2, margin: float = 4.0, min_carriageway_points: int = 30,
               reach: int = 2) -> Flow:
    """Carriageways and junctions of points moving in ``heading`` (see the module doc)."""
    import shapely
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    x0, y0 = float(np.min(x)) - 2 * cell, float(np.min(y)) - 2 * cell
    ci = np.floor((x - x0) / cell).astype(np.int64)
    cj = np.floor((y - y0) / cell).astype(np.int64)
    nx, ny = int(ci.max()) + 3, int(cj.max()) + 3
    b = _bins(heading)
    cellid = cj * nx + ci
    counts = np.bincount(cellid * N_BINS + b, minlength=nx * ny * N_BINS).reshape(ny, nx, N_BINS)
    total = counts.sum(-1)
    sig = (counts >= np.maximum(min_points, share * total[..., None]))
    # junction cells: two significant directions 60-120 degrees apart
    junc = np.zeros((ny, nx), dtype=bool)
    for d in (2, 3, 4):
        junc |= (sig & np.roll(sig, d, axis=-1)).any(-1)
    if grow:
        junc = ndimage.binary_dilation(junc, iterations=grow)
    labels, nj = ndimage.label(junc, structure=np.ones((3, 3)))
    areas = []
    inside = np.zeros((ny, nx), dtype=np.int64) - 1
    for k in range(1, nj + 1):
        jj, ii = np.nonzero(labels == k)
        pts = np.column_stack([x0 + (ii + 0.5) * cell, y0 + (jj + 0.5) * cell])
        if len(pts) < 4:
            continue
        hull = shapely.buffer(shapely.convex_hull(shapely.multipoints(pts)), margin + cell / 2)
        areas.append(hull)
    # cells whose centre lies in a junction area
    if areas:
        gj, gi = np.mgrid[0:ny, 0:nx]
        cx, cy = (x0 + (gi + 0.5) * cell).ravel(), (y0 + (gj + 0.5) * cell).ravel()
        for k, a in enumerate(areas):
            xmin, ymin, xmax, ymax = a.bounds
            cand = np.flatnonzero((cx >= xmin) & (cx <= xmax) & (cy >= ymin) & (cy <= ymax))
            hit = cand[shapely.contains_xy(a, cx[cand], cy[cand])]
            inside.ravel()[hit] = k
    point_junction = inside.ravel()[cellid]
    # carriageways: (cell, bin) nodes outside junctions, linked to neighbours one bin apart
    node_ok = sig & (inside[..., None] < 0)
    jj, ii, bb = np.nonzero(node_ok)
    node_index = -np.ones((ny, nx, N_BINS), dtype=np.int64)
    node_index[jj, ii, bb] = np.arange(len(jj))
    rows, cols = [], []
    span = range(-reach, reach + 1)
    for dj in span:
        for di in span:
            for db in (-1, 0, 1):
                if dj == di == db == 0:
                    continue
                j2, i2, b2 = jj + dj, ii + di, (bb + db) % N_BINS
                ok = (j2 >= 0) & (j2 < ny) & (i2 >= 0) & (i2 < nx)
                other = np.full(len(jj), -1)
                other[ok] = node_index[j2[ok], i2[ok], b2[ok]]
                keep = other >= 0
                rows.append(np.flatnonzero(keep))
                cols.append(other[keep])
    r, c = np.concatenate(rows), np.concatenate(cols)
    n = len(jj)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(n, n))
    ncomp, comp = connected_components(graph, directed=False)
    point_node = node_index.reshape(-1, N_BINS)[cellid, b]
    # a point in a weak (cell, bin) takes the neighbouring bin's node where there is one
    for db in (1, -1):
        miss = point_node < 0
        point_node[miss] = node_index.reshape(-1, N_BINS)[cellid[miss], (b[miss] + db) % N_BINS]
    point_comp = np.where(point_node >= 0, comp[np.maximum(point_node, 0)], -1)
    point_comp[point_junction >= 0] = -1
    # small components are noise
    sizes = np.bincount(point_comp[point_comp >= 0], minlength=ncomp)
    big = np.flatnonzero(sizes >= min_carriageway_points)
    remap = -np.ones(ncomp + 1, dtype=np.int64)
    remap[big] = np.arange(len(big))
    point_comp = np.where(point_comp >= 0, remap[np.maximum(point_comp, 0)], -1)
    return Flow(point_comp, point_junction, areas, len(big))


__all__ = ["Flow", "N_BINS", "flow_field"]
