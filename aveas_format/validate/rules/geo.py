"""Geo-referencing: the CRS, its agreement with the map, lon/lat vs x/y, location and coverage."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import shapely

from aveas_format.errors import FormatError
from aveas_format.crs import crs_equal, parse_crs
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, collector, rule


@rule("geo.crs_unparseable", "error", "recording.json crs cannot be read",
      "recording.json: crs {value!r} cannot be read: {error}",
      enforces="docs/format.md §3: crs is the PROJ/EPSG string of the local frame")
def crs_unparseable(ctx: Context) -> Iterator[Hit]:
    """recording.json ``crs`` is not a CRS that PROJ can read and transform to WGS 84 (known
    malformed variants are read leniently, see ``aveas_format.crs``)."""
    if ctx.meta is None:
        return
    try:
        parse_crs(ctx.meta.crs)
    except FormatError as e:
        yield Hit(file="recording.json", column="crs", value=ctx.meta.crs, error=e.message)


@rule("geo.crs_mismatch", "error", "crs differs from the map's geoReference",
      "recording.json: crs {value!r} differs from the map's geoReference {expected!r}",
      enforces="docs/format.md §3: crs is equal to the map's geoReference where the map has one")
def crs_mismatch(ctx: Context) -> Iterator[Hit]:
    """The map has a ``<geoReference>`` and recording.json ``crs`` describes another CRS (a
    documented lenient reading of a malformed geoReference counts as equal)."""
    net = ctx.network
    if ctx.meta is None or net is None or not net.header.geo_reference:
        return
    try:
        parse_crs(ctx.meta.crs)
        parse_crs(net.header.geo_reference)
    except FormatError:
        return  # geo.crs_unparseable / map.opendrive_error report these
    if not crs_equal(ctx.meta.crs, net.header.geo_reference):
        yield Hit(file="recording.json", column="crs", value=ctx.meta.crs,
                  expected=net.header.geo_reference)


@rule("geo.lonlat_mismatch", "error", "lon/lat disagree with x/y",
      "states.parquet: row {row}: lon/lat lie {value} m from x/y through crs (tolerance "
      "{tolerance} m)",
      enforces="docs/format.md §5: lon, lat are the same point in WGS 84, consistent with x, y through "
               "crs", scope="rows")
def lonlat_mismatch(ctx: Context) -> Iterator[Hits]:
    """A state's lon/lat, projected into the local frame (crs + the map's header offset), lies more
    than ``[geo] lonlat_tolerance_m`` (0.1 m) from its x/y: lon and lat swapped, another datum, or
    positions changed without updating lon/lat."""
    sv, frame = ctx.states_view, ctx.frame
    if sv is None or frame is None:
        return
    x, y, lon, lat = sv.col("x"), sv.col("y"), sv.col("lon"), sv.col("lat")
    if x is None or y is None or lon is None or lat is None:
        return
    ok = np.isfinite(lon) & np.isfinite(lat) & np.isfinite(x) & np.isfinite(y)
    with np.errstate(invalid="ignore"):
        px, py = frame.from_wgs84(np.where(ok, lon, 0.0), np.where(ok, lat, 0.0))
    d = np.hypot(px - x, py - y)
    tol = ctx.config.geo.lonlat_tolerance_m
    bad = ok & ~(d <= tol)
    if bad.any():
        i = np.flatnonzero(bad)
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "x": x[i], "y": y[i],
                                         "value": np.round(d[i], 3)},
                   const={"file": "states.parquet", "table": "states", "column": "lon,lat",
                          "tolerance": tol})


def coverage_polygon(ctx: Context):
    """The coverage as a shapely geometry, or None (absent or not a valid WKT polygon)."""
    key = "geo.coverage"
    if key not in ctx.cache:
        g = None
        if ctx.meta is not None and ctx.meta.coverage:
            try:
                g = shapely.from_wkt(ctx.meta.coverage)
            except Exception:  # noqa: BLE001 — unobserved.coverage_invalid reports it
                g = None
            if g is not None and (g.geom_type not in ("Polygon", "MultiPolygon") or g.is_empty
                                  or not g.is_valid):
                g = None
        if g is not None:
            shapely.prepare(g)
        ctx.cache[key] = g
    return ctx.cache[key]


def _merge_bbox(parts: list[np.ndarray]) -> np.ndarray | None:
    if not parts:
        return None
    b = np.vstack(parts)
    return np.array([b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max()])


@collector("geo.states_bbox", merge=_merge_bbox)
def _states_bbox(ctx: Context) -> np.ndarray | None:
    """(xmin, ymin, xmax, ymax) of the finite state positions of one batch."""
    sv = ctx.states_view
    xs, ys = (sv.col("x"), sv.col("y")) if sv is not None else (None, None)
    if xs is None or ys is None:
        return None
    ok = np.isfinite(xs) & np.isfinite(ys)
    if not ok.any():
        return None
    return np.array([xs[ok].min(), ys[ok].min(), xs[ok].max(), ys[ok].max()])


@rule("geo.location_outside_coverage", "error", "location is not inside the covered area",
      "recording.json: location (lon {lon}, lat {lat}) lies {value} m outside {area}",
      enforces="docs/format.md §3: location is the WGS 84 centroid of the covered area",
      needs=("geo.states_bbox",))
def location_outside_coverage(ctx: Context) -> Iterator[Hit]:
    """recording.json ``location``, projected into the local frame, lies outside the coverage
    polygon (or, without coverage, outside the bounding box of the states' positions) by more than
    10 % of the area's size: a location of another site or with lon/lat swapped."""
    frame = ctx.frame
    if ctx.meta is None or frame is None:
        return
    loc = ctx.meta.location
    x, y = frame.from_wgs84(np.array([loc.lon]), np.array([loc.lat]))
    cov = coverage_polygon(ctx)
    if cov is not None:
        area, name = cov, "the coverage"
    else:
        bbox = ctx.collected.get("geo.states_bbox")
        if bbox is None:
            return
        area = shapely.box(*bbox)
        name = "the bounding box of the states"
    b = area.bounds
    margin = 0.1 * max(b[2] - b[0], b[3] - b[1], 10.0)
    d = float(shapely.distance(area, shapely.Point(x[0], y[0])))
    if d > margin:
        yield Hit(file="recording.json", column="location", lon=loc.lon, lat=loc.lat,
                  x=float(x[0]), y=float(y[0]), value=round(d, 1), area=name)


@rule("geo.state_outside_coverage", "warning", "State outside the covered area",
      "states.parquet: row {row}: participant {participant_id} at x,y = {x},{y} lies outside "
      "recording.json coverage ({n_samples} samples of this participant)", scope="rows",
      enforces=("docs/format.md §3: coverage is the area observed at any time, so observed states "
                "SHOULD lie inside it"))
def state_outside_coverage(ctx: Context) -> Iterator[Hits]:
    """A state lies more than ``[geo] coverage_margin_m`` outside the coverage polygon, which by
    definition contains everything observed. One finding per participant (its first such sample)."""
    sv = ctx.states_view
    cov = coverage_polygon(ctx)
    if sv is None or cov is None:
        return
    x, y = sv.col("x"), sv.col("y")
    if x is None or y is None:
        return
    m = ctx.config.geo.coverage_margin_m
    area = cov.buffer(m) if m > 0 else cov
    shapely.prepare(area)
    b = area.bounds
    ok = np.isfinite(x) & np.isfinite(y)
    out = ok & ((x < b[0]) | (x > b[2]) | (y < b[1]) | (y > b[3]))
    cand = np.flatnonzero(ok & ~out)
    if len(cand):
        inside = shapely.contains_xy(area, x[cand], y[cand])
        out[cand[~inside]] = True
    if out.any():
        idx = np.flatnonzero(out)
        firsts = np.r_[0, np.flatnonzero(np.diff(sv.seg[idx])) + 1]
        counts = np.diff(np.r_[firsts, len(idx)])
        i = idx[firsts]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "x": np.round(x[i], 2),
                                         "y": np.round(y[i], 2), "n_samples": counts},
                   const={"file": "states.parquet", "table": "states", "column": "x,y"})
