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
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import shapely
from pydantic import Field

from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.errors import FormatError


class EncroachmentsParams(Params):
    """Parameters of ``encroachments``."""

    conflict_areas: tuple[str, ...] | None = Field(
        None, description="explicit conflict areas as WKT polygons in the local frame (default: "
        "intersections of swept paths)")
    min_angle: float = Field(0.35, ge=0, description="smallest angle (rad) between the directions "
                             "of travel at a swept-path intersection")
    max_pet: float = Field(10.0, gt=0, description="largest PET (s) reported")
    max_gap_s: float = Field(1.0, gt=0, description="a longer gap between samples ends a visit")


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
        r = 0.5 * L * np.abs(nx * c + ny * s) + 0.5 * W * np.abs(-nx * s + ny * c)
        proj = P[:, 0][None, :] * nx[:, None] + P[:, 1][None, :] * ny[:, None]
        pmin, pmax = proj.min(1), proj.max(1)
        d0 = nx * cx + ny * cy
        dv = nx * vx + ny * vy
        # overlap: pmin - r <= d0 + dv t <= pmax + r
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (pmin - r - d0) / dv
            b = (pmax + r - d0) / dv
        lo = np.where(dv > 0, a, b)
        hi = np.where(dv > 0, b, a)
        still = dv == 0
        inside = (d0 >= pmin - r) & (d0 <= pmax + r)
        lo = np.where(still, np.where(inside, -np.inf, np.inf), lo)
        hi = np.where(still, np.where(inside, np.inf, -np.inf), hi)
        t_in = np.maximum(t_in, lo)
        t_out = np.minimum(t_out, hi)
    return t_in, t_out


def occupancy(t, x, y, h, L, W, poly_xy, max_gap):
    """``(first_entry, last_exit, entry_index, exit_index)`` of one track in one convex area (NaN
    if it never occupies it). Times are interpolated within frames (constant velocity)."""
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
    from aveas_format.derive.interactions import _Samples, InteractionsParams

    S = _Samples(rec, InteractionsParams())
    starts = np.r_[0, np.flatnonzero(np.diff(S.pid)) + 1]
    ends = np.r_[starts[1:], S.n]
    pids = S.pid[starts]
    tracks = [slice(a, b) for a, b in zip(starts, ends)]
    rows: dict[str, list] = {k: [] for k in ("first", "second", "t_exit", "t_enter", "pet",
                                             "pet_std", "geom")}
    if p.conflict_areas is not None:
        try:
            areas = [shapely.from_wkt(w) for w in p.conflict_areas]
        except shapely.errors.ShapelyError as e:
            raise FormatError(f"derivation encroachments: parameter conflict_areas: {e}") from None
        for area in areas:
            _pairs_in_area(S, tracks, area, list(range(len(tracks))), p, rows)
    else:
        paths = [swept_path(S.x[sl], S.y[sl], S.L[sl.start], S.W[sl.start]) for sl in tracks]
        tree = shapely.STRtree(paths)
        a_idx, b_idx = tree.query(paths, predicate="intersects")
        # directions of travel per track (mean and largest deviation): pairs that travel the same
        # way everywhere cannot cross at min_angle and are skipped before any geometry
        mean_dir = np.empty(len(tracks))
        spread = np.empty(len(tracks))
        for m, sl in enumerate(tracks):
            moving = np.hypot(S.vx[sl], S.vy[sl]) > 0.5
            d = np.where(moving, np.arctan2(S.vy[sl], S.vx[sl]), S.h[sl])
            mean_dir[m] = np.angle(np.exp(1j * d).mean())
            dev = np.abs(np.angle(np.exp(1j * (d - mean_dir[m]))))
            spread[m] = np.quantile(dev, 0.99)
        keep = a_idx < b_idx
        dd = np.abs(np.angle(np.exp(1j * (mean_dir[a_idx] - mean_dir[b_idx]))))
        keep &= dd + spread[a_idx] + spread[b_idx] >= p.min_angle
        for a, b in zip(a_idx[keep].tolist(), b_idx[keep].tolist()):
            inter = shapely.intersection(paths[a], paths[b])
            for part in getattr(inter, "geoms", [inter]):
                if part.is_empty or part.area <= 0 or part.geom_type != "Polygon":
                    continue
                hull = part.convex_hull
                c = np.array(hull.centroid.coords[0])
                ang = []
                for tr in (tracks[a], tracks[b]):
                    k = tr.start + int(np.argmin(np.hypot(S.x[tr] - c[0], S.y[tr] - c[1])))
                    ang.append(np.arctan2(S.vy[k], S.vx[k]) if np.hypot(S.vx[k], S.vy[k]) > 0.1
                               else S.h[k])
                diff = abs(np.angle(np.exp(1j * (ang[0] - ang[1]))))
                if diff < p.min_angle:
                    continue
                _pairs_in_area(S, tracks, hull, [a, b], p, rows)
    n = len(rows["first"])
    order = np.argsort(np.asarray(rows["t_exit"], float), kind="stable") if n else np.zeros(0, int)

    def col(k, typ):
        return pa.array([rows[k][i] for i in order], typ)

    pet = np.asarray([rows["pet"][i] for i in order], float)
    pstd = np.asarray([rows["pet_std"][i] for i in order], float)
    return pa.table({
        "conflict_id": pa.array(np.arange(n, dtype=np.int64)),
        "first_id": pa.array([int(pids[rows["first"][i]]) for i in order], pa.int64()),
        "second_id": pa.array([int(pids[rows["second"][i]]) for i in order], pa.int64()),
        "time_first_exit": col("t_exit", pa.float64()),
        "time_second_enter": col("t_enter", pa.float64()),
        "pet": pa.array(pet, pa.float64(), mask=~np.isfinite(pet)),
        "pet_std": pa.array(pstd, pa.float64(), mask=~np.isfinite(pstd)),
        "geometry": col("geom", pa.binary()),
    })


def _pairs_in_area(S, tracks, area, members, p, rows) -> None:
    """PET rows of every pair of ``members`` (track indices) passing through ``area``."""
    if area.geom_type != "Polygon":
        area = area.convex_hull
    hull = area.convex_hull
    poly = np.asarray(hull.exterior.coords)[:-1]
    if len(poly) < 3:
        return
    bx0, by0, bx1, by1 = hull.bounds
    visits = []
    for m in members:
        sl = tracks[m]
        L, W = S.L[sl.start], S.W[sl.start]
        reach = 0.5 * np.hypot(L, W)
        near = ((S.x[sl] >= bx0 - reach - 10) & (S.x[sl] <= bx1 + reach + 10)
                & (S.y[sl] >= by0 - reach - 10) & (S.y[sl] <= by1 + reach + 10))
        if not near.any():
            continue
        ii = np.flatnonzero(near)
        lo, hi = sl.start + ii[0], sl.start + ii[-1] + 1
        t_in, t_out, ke, kx = occupancy(S.t[lo:hi], S.x[lo:hi], S.y[lo:hi], S.h[lo:hi], L, W, poly,
                                        p.max_gap_s)
        if np.isfinite(t_in):
            visits.append((m, t_in, t_out, lo + ke, lo + kx))
    wkb = shapely.to_wkb(hull)
    for a in range(len(visits)):
        for b in range(a + 1, len(visits)):
            va, vb = visits[a], visits[b]
            first, second = (va, vb) if va[1] <= vb[1] else (vb, va)
            t_exit, t_enter = first[2], second[1]
            both = t_enter <= t_exit  # both occupy the area at once
            pet = np.nan if both else t_enter - t_exit
            if not both and pet > p.max_pet:
                continue
            sd = []
            for idx in (first[4], second[3]):
                v = np.hypot(S.vx[idx], S.vy[idx])
                u = (S.vx[idx] / v, S.vy[idx] / v) if v > 0 else (1.0, 0.0)
                var = ((u[0] * S.sx[idx]) ** 2 + (u[1] * S.sy[idx]) ** 2
                       + 2 * u[0] * u[1] * S.rxy[idx] * S.sx[idx] * S.sy[idx]
                       + 0.25 * S.sL[idx] ** 2)
                sd.append(var / v ** 2 if v > 0 else np.inf)
            rows["first"].append(first[0])
            rows["second"].append(second[0])
            rows["t_exit"].append(t_exit)
            rows["t_enter"].append(t_enter)
            rows["pet"].append(pet)
            rows["pet_std"].append(np.sqrt(sum(sd)) if not both else np.nan)
            rows["geom"].append(wkb)


ENCROACHMENTS = register(Derivation(
    name="encroachments",
    table="derived/encroachments",
    version="1.0.0",
    params=EncroachmentsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y", "heading", "vx", "vy"),
           "participants": ("participant_id", "length", "width")},
    doc="post-encroachment times of crossing paths with entry/exit interpolated within frames",
    method=lambda p: "explicit_areas" if p.conflict_areas is not None else "swept_paths",
))
