"""``derived/encroachments``: post-encroachment times (PET) of participants crossing paths.

Conflict areas are, by default, the intersections of the participants' *swept paths* (the area
their footprints cover over the whole track: the centre line buffered by half the width, plus the
first and last footprints), limited to pairs whose directions of travel at the intersection differ
by at least ``min_angle`` (crossing, merging and turning conflicts rather than car following).
Each connected part of an intersection is one conflict area, taken as its convex hull. Conflict
areas can also be given explicitly (``conflict_areas``, WKT polygons; e.g. the overlap of two
lanes at a junction).

A participant *occupies* an area while its footprint (an oriented rectangle) intersects it. Entry
and exit times are found within the frame where the occupancy changes: between two samples the
rectangle translates at the constant velocity of the two positions, and the contact interval with
the convex area is exact (separating axes), so times are not rounded to frames. For a pair in one
area: the *first* participant enters first; ``time_first_exit`` is its last exit,
``time_second_enter`` the other's first entry and ``pet = time_second_enter - time_first_exit``;
``pet`` is null ("undefined") when both occupy the area at once. ``pet_std`` propagates the
position standard deviations along the direction of motion through the speeds at exit and entry:
``pet_std² = (σ_first/v_first)² + (σ_second/v_second)²`` with ``σ² = σ_pos² + (σ_length/2)²``.

The computation is columnar: the swept-path intersections, their parts and convex hulls are bulk
shapely calls; the occupancy of every (area, track) entry is one set of numpy operations over the
concatenated sample windows near the areas (polygons padded to a common vertex count); the pairs
of visits in an area come from a ragged index expansion. Per-track loops remain only where shapely
builds the swept paths.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import shapely
from pydantic import Field

from aveas_format.derive._samples import Samples, ragged
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.errors import FormatError
from aveas_format.schema.columns import MUST, col, gaussian
from aveas_format.schema.tables import derived_table


class EncroachmentsParams(Params):
    """Parameters of ``encroachments``."""

    conflict_areas: tuple[str, ...] | None = Field(
        None, description="explicit conflict areas as WKT polygons in the local frame (default: "
        "intersections of swept paths)")
    min_angle: float = Field(0.35, ge=0, description="smallest angle (rad) between the directions "
                             "of travel at a swept-path intersection")
    max_pet: float = Field(10.0, gt=0, description="largest PET (s) reported")
    max_gap_s: float = Field(1.0, gt=0, description="a longer gap between samples ends a visit")


def track_directions(S, tracks: list[slice]) -> tuple[np.ndarray, np.ndarray]:
    """Per track: the mean direction of travel (heading where it stands) and the 99th percentile
    of the deviations from it."""
    mean_dir = np.empty(len(tracks))
    spread = np.empty(len(tracks))
    for m, sl in enumerate(tracks):  # per track (few), each vectorised over its samples
        moving = np.hypot(S.vx[sl], S.vy[sl]) > 0.5
        d = np.where(moving, np.arctan2(S.vy[sl], S.vx[sl]), S.h[sl])
        mean_dir[m] = np.angle(np.exp(1j * d).mean())
        dev = np.abs(np.angle(np.exp(1j * (d - mean_dir[m]))))
        spread[m] = np.quantile(dev, 0.99)
    return mean_dir, spread


def _axis_interval(nx, ny, pmin, pmax, cx, cy, c, s, L, W, vx, vy):
    """Times (lo, hi) during which a box (centre cx, cy; heading cos/sin c, s; length L, width W)
    moving at (vx, vy) overlaps a polygon's projection [pmin, pmax] on the axis (nx, ny):
    ``pmin - r <= d0 + dv t <= pmax + r`` with the box's half-extent r on that axis."""
    r = 0.5 * L * np.abs(nx * c + ny * s) + 0.5 * W * np.abs(-nx * s + ny * c)
    d0 = nx * cx + ny * cy
    dv = nx * vx + ny * vy
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # (a speed ~0 on the axis: +-inf)
        a = (pmin - r - d0) / dv
        b = (pmax + r - d0) / dv
    lo = np.where(dv > 0, a, b)
    hi = np.where(dv > 0, b, a)
    still = dv == 0
    inside = (d0 >= pmin - r) & (d0 <= pmax + r)
    lo = np.where(still, np.where(inside, -np.inf, np.inf), lo)
    hi = np.where(still, np.where(inside, np.inf, -np.inf), hi)
    return lo, hi


def _box_polygon_interval(cx, cy, h, L, W, vx, vy, poly_xy):
    """Contact interval ``[t_in, t_out]`` (relative times) of rectangles translating with (vx, vy)
    against one static convex polygon (vertices ``poly_xy``), elementwise; ``t_in > t_out`` where
    there is no contact."""
    c, s = np.cos(h), np.sin(h)
    P = np.asarray(poly_xy, float)
    edges = np.roll(P, -1, axis=0) - P
    normals = np.stack([-edges[:, 1], edges[:, 0]], 1)
    normals = normals[np.hypot(normals[:, 0], normals[:, 1]) > 1e-12]
    normals /= np.hypot(normals[:, 0], normals[:, 1])[:, None]
    t_in = np.full(cx.shape, -np.inf)
    t_out = np.full(cx.shape, np.inf)
    axes = [(c, s), (-s, c)] + [(np.full(cx.shape, n[0]), np.full(cx.shape, n[1])) for n in normals]
    for nx, ny in axes:
        proj = P[:, 0][None, :] * nx[:, None] + P[:, 1][None, :] * ny[:, None]
        lo, hi = _axis_interval(nx, ny, proj.min(1), proj.max(1), cx, cy, c, s, L, W, vx, vy)
        t_in = np.maximum(t_in, lo)
        t_out = np.minimum(t_out, hi)
    return t_in, t_out


def occupancy(t, x, y, h, L, W, poly_xy, max_gap):
    """``(first_entry, last_exit, entry_index, exit_index)`` of one track in one convex area (NaN
    if it never occupies it). Times are interpolated within frames (constant velocity).

    The scalar form of what :func:`_occupancy_rows` computes for many tracks and areas at once
    (kept as its reference and for single-track use)."""
    n = len(t)
    if n == 0:
        return np.nan, np.nan, -1, -1
    zero = np.zeros(n)
    lo, hi = _box_polygon_interval(x, y, h, np.full(n, L), np.full(n, W), zero, zero, poly_xy)
    occ = lo <= hi  # occupied at the sample (static test)
    if not occ.any():
        # it may pass through between two samples
        if n < 2:
            return np.nan, np.nan, -1, -1
    dt = np.diff(t)
    vx = np.diff(x) / np.where(dt > 0, dt, 1.0)
    vy = np.diff(y) / np.where(dt > 0, dt, 1.0)
    a, b = _box_polygon_interval(x[:-1], y[:-1], h[:-1], np.full(n - 1, L), np.full(n - 1, W),
                                 vx, vy, poly_xy)
    ok = (dt > 0) & (dt <= max_gap)
    a_c, b_c = np.maximum(a, 0.0), np.minimum(b, dt)
    touch = ok & (a_c <= b_c)
    entries = np.r_[np.where(occ[:1], t[:1], np.nan), np.where(touch, t[:-1] + a_c, np.nan)]
    exits = np.r_[np.where(touch, t[:-1] + b_c, np.nan), np.where(occ[-1:], t[-1:], np.nan)]
    if not np.isfinite(entries).any():
        return np.nan, np.nan, -1, -1
    ie = int(np.nanargmin(entries))
    ix = int(np.nanargmax(exits))
    return float(entries[ie]), float(exits[ix]), max(ie - 1, 0), min(ix, n - 1)


def swept_path(x, y, L, W):
    """The area a footprint covers along a track: buffered centre line plus end footprints."""
    pts = np.column_stack([x, y])
    if len(pts) < 2 or np.allclose(pts, pts[0]):
        return shapely.Point(pts[0]).buffer(0.5 * max(L, W))
    line = shapely.LineString(pts)
    body = line.buffer(0.5 * W, cap_style="flat", join_style="round", quad_segs=2)
    caps = []
    for k, j in ((0, 1), (-1, -2)):
        d = pts[k] - pts[j]
        nrm = np.hypot(*d)
        if nrm == 0:
            continue
        u = d / nrm
        v = np.array([-u[1], u[0]])
        c = pts[k]
        corners = [c + 0.5 * L * u + 0.5 * W * v, c + 0.5 * L * u - 0.5 * W * v,
                   c - 0.5 * L * u - 0.5 * W * v, c - 0.5 * L * u + 0.5 * W * v]
        caps.append(shapely.Polygon(corners))
    return shapely.union_all([body, *caps])


def compute(rec, p: EncroachmentsParams) -> pa.Table:
    """The ``derived/encroachments`` table of ``rec``."""
    S = Samples(rec)
    starts = np.r_[0, np.flatnonzero(np.diff(S.pid)) + 1]
    ends = np.r_[starts[1:], S.n]
    pids = S.pid[starts]
    tracks = [slice(a, b) for a, b in zip(starts, ends)]
    if p.conflict_areas is not None:
        try:
            areas = [shapely.from_wkt(w) for w in p.conflict_areas]
        except shapely.errors.ShapelyError as e:
            raise FormatError(f"derivation encroachments: parameter conflict_areas: {e}") from None
        areas = np.asarray(areas, dtype=object)
        # every track is a member of every area (in track order)
        area_of = np.repeat(np.arange(len(areas)), len(tracks))
        member = np.tile(np.arange(len(tracks)), len(areas))
    else:
        areas, area_of, member = _swept_areas(S, tracks, p)
    out = _area_pairs(S, starts, ends, areas, area_of, member, p)
    order = np.argsort(out["t_exit"], kind="stable")
    out = {k: v[order] for k, v in out.items()}
    n = len(order)
    pet, pstd = out["pet"], out["pet_std"]
    return pa.table({
        "conflict_id": pa.array(np.arange(n, dtype=np.int64)),
        "first_id": pa.array(pids[out["first"]].astype(np.int64), pa.int64()),
        "second_id": pa.array(pids[out["second"]].astype(np.int64), pa.int64()),
        "time_first_exit": pa.array(out["t_exit"], pa.float64()),
        "time_second_enter": pa.array(out["t_enter"], pa.float64()),
        "pet": pa.array(pet, pa.float64(), mask=~np.isfinite(pet)),
        "pet_std": pa.array(pstd, pa.float64(), mask=~np.isfinite(pstd)),
        "geometry": pa.array(list(out["geom"]), pa.binary()),
    })


def _segment_first_extreme(values: np.ndarray, seg_start: np.ndarray, largest: bool
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Per segment (non-empty, starting at ``seg_start``, contiguous): the position (within the
    segment) of the first smallest (``largest``: largest) finite value, as ``np.nanargmin``
    (``np.nanargmax``) gives it, and whether the segment has a finite value at all."""
    fill = -np.inf if largest else np.inf
    v = np.where(np.isfinite(values), values, fill)
    ext = (np.maximum if largest else np.minimum).reduceat(v, seg_start)
    seg = np.repeat(np.arange(len(seg_start)), np.diff(np.r_[seg_start, len(v)]))
    hit = np.flatnonzero((v == ext[seg]) & np.isfinite(v))
    found = np.zeros(len(seg_start), bool)
    pos = np.zeros(len(seg_start), np.int64)
    segs, first = np.unique(seg[hit], return_index=True)
    found[segs] = True
    pos[segs] = hit[first] - seg_start[segs]
    return pos, found


def _swept_areas(S, tracks: list[slice], p: EncroachmentsParams
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Conflict areas from intersections of swept paths: ``(areas, area_of, member)``, the convex
    hulls of the intersections' parts whose directions of travel differ by at least
    ``min_angle``, and for each (area, member track) entry its area index and track index (two
    per area, the pair's tracks in index order)."""
    paths = np.asarray([swept_path(S.x[sl], S.y[sl], S.L[sl.start], S.W[sl.start])
                        for sl in tracks], dtype=object)
    empty = (np.zeros(0, object), np.zeros(0, np.int64), np.zeros(0, np.int64))
    if len(paths) < 2:
        return empty
    tree = shapely.STRtree(paths)
    a_idx, b_idx = tree.query(paths)  # overlapping bounding boxes; exact test below
    # directions of travel per track (mean and largest deviation): pairs that travel the same way
    # everywhere cannot cross at min_angle and are skipped before any geometry
    mean_dir, spread = track_directions(S, tracks)
    keep = a_idx < b_idx
    dd = np.abs(np.angle(np.exp(1j * (mean_dir[a_idx] - mean_dir[b_idx]))))
    keep &= dd + spread[a_idx] + spread[b_idx] >= p.min_angle
    a_idx, b_idx = a_idx[keep], b_idx[keep]
    shapely.prepare(paths)
    touching = shapely.intersects(paths[a_idx], paths[b_idx])
    a_idx, b_idx = a_idx[touching], b_idx[touching]
    if not len(a_idx):
        return empty
    inter = shapely.intersection(paths[a_idx], paths[b_idx])
    parts, which = shapely.get_parts(inter, return_index=True)
    good = (~shapely.is_empty(parts)) & (shapely.get_type_id(parts) == 3)
    good[good] = shapely.area(parts[good]) > 0
    parts, which = parts[good], which[good]
    if not len(parts):
        return empty
    hulls = shapely.convex_hull(parts)
    cen = shapely.get_coordinates(shapely.centroid(hulls))
    # direction of each track at its sample nearest to the area's centroid
    ta, tb = a_idx[which], b_idx[which]
    starts = np.array([sl.start for sl in tracks], np.int64)
    lens = np.array([sl.stop - sl.start for sl in tracks], np.int64)
    ang = np.empty((2, len(parts)))
    for r, tr in enumerate((ta, tb)):
        for lo, hi in _chunks(lens[tr], 2_000_000):
            seg, pos = ragged(lens[tr[lo:hi]])
            k = starts[tr[lo:hi]][seg] + pos
            c = cen[lo:hi][seg]
            d = np.hypot(S.x[k] - c[:, 0], S.y[k] - c[:, 1])
            first = np.cumsum(lens[tr[lo:hi]]) - lens[tr[lo:hi]]
            near, _ = _segment_first_extreme(d, first, largest=False)
            kk = starts[tr[lo:hi]] + near
            ang[r, lo:hi] = np.where(np.hypot(S.vx[kk], S.vy[kk]) > 0.1,
                                     np.arctan2(S.vy[kk], S.vx[kk]), S.h[kk])
    diff = np.abs(np.angle(np.exp(1j * (ang[0] - ang[1]))))
    ok = ~(diff < p.min_angle)
    hulls, ta, tb = hulls[ok], ta[ok], tb[ok]
    m = len(hulls)
    return hulls, np.repeat(np.arange(m), 2), np.column_stack([ta, tb]).ravel()


def _chunks(lengths: np.ndarray, budget: int) -> list[tuple[int, int]]:
    """Consecutive ranges ``[lo, hi)`` of items, cut where the running sum of ``lengths``
    crosses a multiple of ``budget`` (so a range holds about ``budget`` elements, at least one
    item)."""
    lengths = np.asarray(lengths, np.int64)
    if not len(lengths):
        return []
    group = (np.cumsum(lengths) - lengths) // max(int(budget), 1)
    cut = np.r_[0, np.flatnonzero(np.diff(group)) + 1, len(lengths)]
    return list(zip(cut[:-1].tolist(), cut[1:].tolist()))


def _area_pairs(S, starts: np.ndarray, ends: np.ndarray, areas: np.ndarray, area_of: np.ndarray,
                member: np.ndarray, p: EncroachmentsParams) -> dict[str, np.ndarray]:
    """PET rows of every pair of member tracks passing through the same area, columnar.

    ``area_of``/``member`` list the (area, track) entries, grouped by area; within an area the
    pairs follow the order of the entries. Rows come in that order (areas, then pairs)."""
    cols = ("first", "second", "t_exit", "t_enter", "pet", "pet_std", "geom")
    out = {k: np.zeros(0, np.int64 if k in ("first", "second") else object if k == "geom"
                       else float) for k in cols}
    if not len(areas) or not len(area_of):
        return out
    areas = np.asarray(areas, dtype=object)
    poly_areas = shapely.get_type_id(areas) == 3
    areas = np.where(poly_areas, areas, shapely.convex_hull(areas))
    hulls = shapely.convex_hull(areas)
    is_poly = shapely.get_type_id(hulls) == 3
    ring = shapely.get_exterior_ring(np.where(is_poly, hulls, None))
    xy, ridx = shapely.get_coordinates(ring, return_index=True)
    nv = np.bincount(ridx, minlength=len(hulls)) - 1  # closing vertex dropped
    nv = np.where(is_poly, nv, 0)
    usable = nv >= 3
    vmax = int(nv.max()) if len(nv) else 0
    if vmax < 3:
        return out
    # vertices padded with the last one (duplicate vertices change no projection range; the
    # zero-length edges they add are skipped like degenerate edges)
    P = np.zeros((len(hulls), vmax, 2))
    ring_first = np.r_[0, np.cumsum(np.bincount(ridx, minlength=len(hulls)))[:-1]]
    jj = np.minimum(np.arange(vmax)[None, :], np.maximum(nv - 1, 0)[:, None])
    has = np.bincount(ridx, minlength=len(hulls)) > 0
    P[has] = xy[(ring_first[:, None] + jj)[has]]
    edges = np.roll(P, -1, axis=1) - P
    # the closing edge of a padded polygon runs from the last padded vertex to the first
    normals = np.stack([-edges[..., 1], edges[..., 0]], -1)
    nrm = np.hypot(normals[..., 0], normals[..., 1])
    nvalid = nrm > 1e-12
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = normals / nrm[..., None]
    bounds = shapely.bounds(hulls)
    wkb = shapely.to_wkb(hulls)

    sel = usable[area_of]
    area_of, member = area_of[sel], member[sel]
    # --- the window of samples near each area, per entry --------------------------------------
    L = S.L[starts[member]]
    W = S.W[starts[member]]
    lens = (ends - starts)[member]
    win_lo = np.full(len(member), -1, np.int64)
    win_hi = np.full(len(member), -1, np.int64)
    for lo, hi in _chunks(lens, 4_000_000):
        seg, pos = ragged(lens[lo:hi])
        e = lo + seg
        k = starts[member[e]] + pos
        reach = 0.5 * np.hypot(L[e], W[e])
        bx0, by0, bx1, by1 = bounds[area_of[e]].T
        near = ((S.x[k] >= bx0 - reach - 10) & (S.x[k] <= bx1 + reach + 10)
                & (S.y[k] >= by0 - reach - 10) & (S.y[k] <= by1 + reach + 10))
        hit = np.flatnonzero(near)
        if len(hit):
            es = e[hit]
            u, f = np.unique(es, return_index=True)
            win_lo[u] = k[hit][f]
            u2, f2 = np.unique(es[::-1], return_index=True)
            win_hi[u2] = k[hit][::-1][f2] + 1
    seen = win_lo >= 0
    area_of, member, L, W, win_lo, win_hi = (a[seen] for a in
                                             (area_of, member, L, W, win_lo, win_hi))
    if not len(member):
        return out
    # --- occupancy of every entry (static at the samples, moving between them) ----------------
    n = win_hi - win_lo
    t_in = np.full(len(member), np.nan)
    t_out = np.full(len(member), np.nan)
    k_in = np.zeros(len(member), np.int64)
    k_out = np.zeros(len(member), np.int64)
    for lo, hi in _chunks(n, 2_000_000):
        r = _occupancy_rows(S, win_lo[lo:hi], n[lo:hi], area_of[lo:hi], L[lo:hi], W[lo:hi], P,
                            normals, nvalid, p.max_gap_s)
        t_in[lo:hi], t_out[lo:hi], k_in[lo:hi], k_out[lo:hi] = r
    vis = np.isfinite(t_in)
    area_of, member, t_in, t_out, k_in, k_out = (a[vis] for a in
                                                 (area_of, member, t_in, t_out, k_in, k_out))
    if not len(member):
        return out
    # --- pairs of visits in one area, in entry order -----------------------------------------
    grp_end = np.searchsorted(area_of, area_of, side="right")
    cnt = grp_end - np.arange(len(area_of)) - 1
    ia, off = ragged(cnt)
    ib = ia + 1 + off
    fa = t_in[ia] <= t_in[ib]
    first = np.where(fa, ia, ib)
    second = np.where(fa, ib, ia)
    t_exit, t_enter = t_out[first], t_in[second]
    both = t_enter <= t_exit
    pet = np.where(both, np.nan, t_enter - t_exit)
    keep = both | ~(pet > p.max_pet)
    first, second, t_exit, t_enter, pet, both = (a[keep] for a in
                                                 (first, second, t_exit, t_enter, pet, both))
    sd = np.zeros(len(first))
    for idx in (k_out[first], k_in[second]):
        v = np.hypot(S.vx[idx], S.vy[idx])
        pos = v > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            u0 = np.where(pos, S.vx[idx] / v, 1.0)
            u1 = np.where(pos, S.vy[idx] / v, 0.0)
            var = ((u0 * S.sx[idx]) ** 2 + (u1 * S.sy[idx]) ** 2
                   + 2 * u0 * u1 * S.rxy[idx] * S.sx[idx] * S.sy[idx] + 0.25 * S.sL[idx] ** 2)
            sd = sd + np.where(pos, var / v ** 2, np.inf)
    return {"first": member[first], "second": member[second], "t_exit": t_exit,
            "t_enter": t_enter, "pet": pet, "pet_std": np.where(both, np.nan, np.sqrt(sd)),
            "geom": wkb[area_of[first]]}


def _occupancy_rows(S, lo: np.ndarray, n: np.ndarray, area: np.ndarray, L: np.ndarray,
                    W: np.ndarray, P: np.ndarray, normals: np.ndarray, nvalid: np.ndarray,
                    max_gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """First entry, last exit and the sample indices of the entry and exit frames of windows of
    samples (``lo``, ``n``) in convex areas (padded vertices ``P``), all at once: the columnar
    form of :func:`occupancy` (NaN entry where a window never occupies its area)."""
    seg, pos = ragged(n)
    k = lo[seg] + pos
    a = area[seg]
    zero = np.zeros(len(k))
    s_lo, s_hi = _box_polygons_interval(S.x[k], S.y[k], S.h[k], L[seg], W[seg], zero, zero, a,
                                        P, normals, nvalid)
    occ = s_lo <= s_hi
    last = pos == n[seg] - 1
    iv = np.flatnonzero(~last)  # intervals from sample iv to iv + 1
    ki, kn = k[iv], k[iv] + 1
    dt = S.t[kn] - S.t[ki]
    step = np.where(dt > 0, dt, 1.0)
    vx = (S.x[kn] - S.x[ki]) / step
    vy = (S.y[kn] - S.y[ki]) / step
    ia, ib = _box_polygons_interval(S.x[ki], S.y[ki], S.h[ki], L[seg[iv]], W[seg[iv]], vx, vy,
                                    a[iv], P, normals, nvalid)
    ok = (dt > 0) & (dt <= max_gap)
    a_c, b_c = np.maximum(ia, 0.0), np.minimum(ib, dt)
    touch = ok & (a_c <= b_c)
    first_row = pos == 0
    entries = np.where(first_row & occ, S.t[k], np.nan)
    entries[iv + 1] = np.where(touch, S.t[ki] + a_c, np.nan)
    exits = np.where(last & occ, S.t[k], np.nan)
    exits[iv] = np.where(touch, S.t[ki] + b_c, np.nan)
    seg_start = np.cumsum(n) - n
    ie, has_in = _segment_first_extreme(entries, seg_start, largest=False)
    ix, has_out = _segment_first_extreme(exits, seg_start, largest=True)
    t_in = np.where(has_in, entries[seg_start + ie], np.nan)
    # an entry without an exit (occupied across a gap only): the last occupied sample
    t_out = np.where(has_out, exits[seg_start + ix], t_in)
    ix = np.where(has_out, ix, ie)
    return (t_in, t_out, lo + np.maximum(ie - 1, 0), lo + np.minimum(ix, n - 1))


def _box_polygons_interval(cx, cy, h, L, W, vx, vy, area, P, normals, nvalid):
    """:func:`_box_polygon_interval` with one polygon per row: row ``i`` against the convex
    polygon ``P[area[i]]`` (vertices padded by repetition, edge normals ``normals`` valid where
    ``nvalid``)."""
    c, s = np.cos(h), np.sin(h)
    t_in = np.full(cx.shape, -np.inf)
    t_out = np.full(cx.shape, np.inf)
    nv = P.shape[1]
    # projection ranges of each polygon on its own edge normals (per polygon, not per row)
    projn = (P[:, None, :, 0] * normals[:, :, None, 0] + P[:, None, :, 1] * normals[:, :, None, 1])
    nmin, nmax = projn.min(2), projn.max(2)
    for j in range(-2, nv):
        if j < 0:
            nx, ny = (c, s) if j == -2 else (-s, c)
            pmin = np.full(cx.shape, np.inf)
            pmax = np.full(cx.shape, -np.inf)
            for q in range(nv):
                proj = P[area, q, 0] * nx + P[area, q, 1] * ny
                pmin = np.minimum(pmin, proj)
                pmax = np.maximum(pmax, proj)
        else:
            nx, ny = normals[area, j, 0], normals[area, j, 1]
            pmin, pmax = nmin[area, j], nmax[area, j]
        lo, hi = _axis_interval(nx, ny, pmin, pmax, cx, cy, c, s, L, W, vx, vy)
        if j >= 0:
            valid = nvalid[area, j]
            lo = np.where(valid, lo, -np.inf)
            hi = np.where(valid, hi, np.inf)
        t_in = np.maximum(t_in, lo)
        t_out = np.minimum(t_out, hi)
    return t_in, t_out


TABLE = derived_table(
    "encroachments",
    doc="Post-encroachment times: one row per pair of participants passing through a common "
    "conflict area.",
    key=("conflict_id",),
    sort=("conflict_id",),
    columns=(
        col("conflict_id", "int64", MUST, "conflict id, unique", minimum=0, nullable=False),
        col("first_id", "int64", MUST, "participant that leaves the conflict area first", minimum=0,
            nullable=False),
        col("second_id", "int64", MUST, "participant that enters it second", minimum=0,
            nullable=False),
        col("time_first_exit", "float64", MUST, "time the first participant leaves the area", "s"),
        col("time_second_enter", "float64", MUST, "time the second participant enters the area", "s"),
        *gaussian("pet", "s", MUST, "post-encroachment time", minimum=0.0),
        col("geometry", "binary", MUST, "conflict area, WKB polygon, local frame"),
    ),
)

ENCROACHMENTS = register(Derivation(
    name="encroachments",
    spec=TABLE,
    version="1.0.0",
    params=EncroachmentsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y", "heading", "vx", "vy"),
           "participants": ("participant_id", "length", "width")},
    doc="post-encroachment times of crossing paths with entry/exit interpolated within frames",
    method=lambda p: "explicit_areas" if p.conflict_areas is not None else "swept_paths",
))
