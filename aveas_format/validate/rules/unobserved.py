"""Unobserved regions and coverage: valid polygons, intervals, extent, states inside them."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import shapely

from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, rule
from aveas_format.validate.views import ints, num

_F = {"file": "unobserved.parquet", "table": "unobserved"}


def _geoms(ctx: Context):
    """(geometries or None per row, problem text per row) of unobserved.geometry (cached)."""
    if "unobserved.geoms" in ctx.cache:
        return ctx.cache["unobserved.geoms"]
    out = None
    u = ctx.table("unobserved")
    if u is not None and "geometry" in u.column_names and (
            str(u.column("geometry").type) in ("binary", "large_binary")):
        raw = u.column("geometry").to_numpy(zero_copy_only=False)
        geoms = np.full(len(raw), None, dtype=object)
        why = np.full(len(raw), None, dtype=object)
        for k, b in enumerate(raw):  # per region, not per state: regions are few
            if b is None:
                why[k] = "is null"
                continue
            try:
                g = shapely.from_wkb(b)
            except Exception as e:  # noqa: BLE001 — shapely raises GEOSException and others
                why[k] = f"is not WKB ({str(e).splitlines()[0][:80]})"
                continue
            if g.geom_type not in ("Polygon", "MultiPolygon"):
                why[k] = f"is a {g.geom_type}, not a Polygon or MultiPolygon"
            elif g.is_empty:
                why[k] = "is empty"
            elif not g.is_valid:
                why[k] = f"is not a valid polygon ({shapely.is_valid_reason(g)})"
            else:
                geoms[k] = g
        out = (geoms, why)
    ctx.cache["unobserved.geoms"] = out
    return out


@rule("unobserved.invalid_geometry", "error", "Invalid unobserved region",
      "unobserved.parquet: row {row}: region {region_id}: geometry {why}",
      enforces="docs/format.md §6: geometry is a valid WKB Polygon or MultiPolygon")
def invalid_geometry(ctx: Context) -> Iterator[Hits]:
    """A region's geometry is not WKB, not a (Multi)Polygon, empty, or invalid (self-intersecting
    ring, ...)."""
    g = _geoms(ctx)
    if g is None:
        return
    geoms, why = g
    bad = np.array([w is not None for w in why], dtype=bool)
    if bad.any():
        rows = np.flatnonzero(bad)
        rid = num(ctx.table("unobserved"), "region_id")
        yield Hits(total=len(rows), arrays={"row": rows, "why": why[rows],
                                            "region_id": rid[rows].astype(np.int64) if rid is not None
                                            else rows},
                   const={**_F, "column": "geometry"})


@rule("unobserved.time_order", "error", "Region ends before it starts",
      "unobserved.parquet: row {row}: time_end {time_end} s is before time_start {time} s",
      enforces="docs/format.md §6: validity interval, start <= end")
def time_order(ctx: Context) -> Iterator[Hits]:
    """A region's ``time_end`` is before its ``time_start``."""
    u = ctx.table("unobserved")
    ts, te = num(u, "time_start", "unobserved"), num(u, "time_end", "unobserved")
    if ts is None or te is None:
        return
    bad = te < ts
    if bad.any():
        rows = np.flatnonzero(bad)
        yield Hits(total=len(rows), arrays={"row": rows, "time": ts[rows], "time_end": te[rows]},
                   const={**_F, "column": "time_end"})


@rule("unobserved.outside_map", "warning", "Region outside the map",
      "unobserved.parquet: row {row}: region {region_id} lies entirely outside the map's extent "
      "{extent}",
      enforces=quality("regions_in_frame"))
def outside_map(ctx: Context) -> Iterator[Hits]:
    """A region does not intersect the map's extent (the bounding box of its road surfaces, with a
    margin of 10 % of its size): a region in another frame (lon/lat instead of local x/y?)."""
    g, net = _geoms(ctx), ctx.network
    if g is None or net is None:
        return
    geoms, _ = g
    b = net.bounds
    m = 0.1 * max(b[2] - b[0], b[3] - b[1], 10.0)
    box = shapely.box(b[0] - m, b[1] - m, b[2] + m, b[3] + m)
    valid = np.array([x is not None for x in geoms], dtype=bool)
    if not valid.any():
        return
    hit = np.zeros(len(geoms), bool)
    hit[valid] = shapely.intersects(box, np.array(list(geoms[valid]), dtype=object))
    bad = valid & ~hit
    if bad.any():
        rows = np.flatnonzero(bad)
        rid = num(ctx.table("unobserved"), "region_id")
        yield Hits(total=len(rows), arrays={"row": rows, "region_id": rid[rows].astype(np.int64)
                                            if rid is not None else rows},
                   const={**_F, "column": "geometry",
                          "extent": "({:.1f}, {:.1f}, {:.1f}, {:.1f})".format(*b)})


@rule("unobserved.state_inside", "warning", "Observed state inside an unobserved region",
      "states.parquet: row {row}: participant {participant_id} at x,y = {x},{y} is inside "
      "unobserved region {region_id} ({kind}) at {time} s but not marked interpolated "
      "({n_samples} samples)", scope="rows",
      enforces=quality("unobserved_states"))
def state_inside(ctx: Context) -> Iterator[Hits]:
    """A state that is not ``interpolated`` lies inside an unobserved region during the region's
    interval: either the region is wrong or the state was not measured. The interval is read
    half-open, [time_start, time_end) (a zero-length one holds at its instant), and a state must be
    inside by more than z sigma of its position. One finding per participant and region."""
    sv, g = ctx.states_view, _geoms(ctx)
    if sv is None or g is None:
        return
    u = ctx.table("unobserved")
    ts, te = num(u, "time_start", "unobserved"), num(u, "time_end", "unobserved")
    x, y = sv.col("x"), sv.col("y")
    if ts is None or te is None or x is None or y is None:
        return
    geoms, _ = g
    rid = ints(u, "region_id")
    kinds = u.column("kind").cast("string").to_pylist() if "kind" in u.column_names else \
        [None] * u.num_rows
    interp = sv.col("interpolated")
    measured = ~(np.nan_to_num(interp) > 0) if interp is not None else np.ones(sv.n, bool)
    sx, sy = sv.col("x_std"), sv.col("y_std")
    sig = np.hypot(np.nan_to_num(sx), np.nan_to_num(sy)) if sx is not None and sy is not None \
        else np.zeros(sv.n)
    margin = ctx.config.kinematics.z * sig
    tol = ctx.config.time.tolerance_s
    rows_all, regions_all = [], []
    for k, geom in enumerate(geoms):  # regions are few; each test is vectorised over the states
        if geom is None:
            continue
        b = geom.bounds
        during = (sv.t >= ts[k] - tol) & (sv.t < te[k]) if te[k] > ts[k] else \
            np.abs(sv.t - ts[k]) <= tol
        cand = np.flatnonzero(measured & during & (x >= b[0]) & (x <= b[2]) & (y >= b[1]) &
                              (y <= b[3]))
        if not len(cand):
            continue
        inside = cand[shapely.contains_xy(geom, x[cand], y[cand])]
        if len(inside) and margin[inside].any():  # clearly inside: farther than z sigma from the edge
            d = shapely.distance(geom.boundary, shapely.points(x[inside], y[inside]))
            inside = inside[d > margin[inside]]
        if len(inside):
            rows_all.append(inside)
            regions_all.append(np.full(len(inside), k))
    if not rows_all:
        return
    idx = np.concatenate(rows_all)
    reg = np.concatenate(regions_all)
    order = np.lexsort((idx, reg, sv.seg[idx]))
    idx, reg = idx[order], reg[order]
    key = sv.seg[idx] * (len(geoms) + 1) + reg
    first = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
    counts = np.diff(np.r_[first, len(idx)])
    i, r = idx[first], reg[first]
    o = np.argsort(sv.row[i], kind="stable")
    i, r, counts = i[o], r[o], counts[o]
    yield Hits(total=len(i), arrays={
        "row": sv.row[i], "participant_id": sv.pid[i], "time": sv.t[i], "x": np.round(x[i], 2),
        "y": np.round(y[i], 2), "region_id": rid[r] if rid is not None else r,
        "kind": np.array(kinds, dtype=object)[r], "n_samples": counts},
        const={"file": "states.parquet", "table": "states", "column": "x,y"})


@rule("unobserved.table_missing", "warning", "No unobserved.parquet",
      "unobserved.parquet: the recording has no unobserved regions table",
      enforces=("docs/format.md §1: unobserved.parquet SHOULD list the regions not observed "
                "(occlusions, sensor limits)"))
def table_missing(ctx: Context) -> Iterator[Hit]:
    """The recording has no unobserved.parquet: docs/format.md §1 says it SHOULD list the regions not
    observed (occlusions, sensor limits), so that users can tell 'nobody there' from 'not seen'."""
    if ctx.meta is None:
        return
    if "unobserved" not in ctx.table_names:
        yield Hit(file="unobserved.parquet", table="unobserved")


@rule("unobserved.coverage_missing", "warning", "No coverage polygon",
      "recording.json: coverage is missing: the observed area is unknown",
      enforces="docs/format.md §3: coverage (the area observed at any time) SHOULD be given")
def coverage_missing(ctx: Context) -> Iterator[Hit]:
    """recording.json has no ``coverage``: docs/format.md §3 says it SHOULD give the area observed at any
    time (everything else is unobserved)."""
    if ctx.meta is not None and not ctx.meta.coverage:
        yield Hit(file="recording.json", column="coverage")


@rule("unobserved.coverage_invalid", "error", "coverage is not a valid WKT polygon",
      "recording.json: coverage {why}",
      enforces="docs/format.md §3: coverage is a WKT polygon in the local frame")
def coverage_invalid(ctx: Context) -> Iterator[Hit]:
    """recording.json ``coverage`` is not parseable WKT, not a (Multi)Polygon, empty or invalid."""
    if ctx.meta is None or not ctx.meta.coverage:
        return
    try:
        g = shapely.from_wkt(ctx.meta.coverage)
    except Exception as e:  # noqa: BLE001 — shapely raises GEOSException
        yield Hit(file="recording.json", column="coverage",
                  why=f"is not WKT ({str(e).splitlines()[0][:80]})")
        return
    if g is None or g.geom_type not in ("Polygon", "MultiPolygon"):
        yield Hit(file="recording.json", column="coverage",
                  why=f"is a {getattr(g, 'geom_type', 'null')}, not a Polygon")
    elif g.is_empty:
        yield Hit(file="recording.json", column="coverage", why="is empty")
    elif not g.is_valid:
        yield Hit(file="recording.json", column="coverage",
                  why=f"is not valid: {shapely.is_valid_reason(g)}")
