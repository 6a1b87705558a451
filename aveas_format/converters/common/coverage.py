"""What a sensor did not observe, as rows of the ``unobserved`` table: the map's surroundings
outside an aerial footprint, outside a sensor's range or field of view, and the ground shadows that
boxes cast seen from a mounted sensor."""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.geometry import footprint_corners


def sector_polygon(cx: float, cy: float, radius: float, yaw: float = 0.0,
                   fov: float = 2 * np.pi, n: int = 128):
    """A shapely polygon: the disk (``fov`` >= 2 pi) or circular sector of a sensor."""
    import shapely

    if fov >= 2 * np.pi - 1e-9:
        return shapely.Point(cx, cy).buffer(radius, quad_segs=max(n // 4, 8))
    a = yaw + np.linspace(-fov / 2, fov / 2, n)
    pts = np.c_[cx + radius * np.cos(a), cy + radius * np.sin(a)]
    return shapely.Polygon(np.vstack([[cx, cy], pts]))


def _areal(geom):
    """The polygonal part of ``geom`` (made valid; slivers under 1e-6 m² dropped) as a Polygon or
    MultiPolygon, None when nothing is left."""
    import shapely

    geom = shapely.make_valid(geom)
    polys = [g for g in getattr(geom, "geoms", [geom]) if g.geom_type == "Polygon" and g.area > 1e-6]
    if not polys:
        return None
    return polys[0] if len(polys) == 1 else shapely.MultiPolygon(polys)


def coverage_regions(sensor_id: str, sensor_xy: tuple[float, float], range_m: float,
                     yaw: float, fov: float, area, time_start: float, time_end: float,
                     observed=None) -> list[dict[str, Any]]:
    """Unobserved rows of a static sensor over [time_start, time_end]: ``area`` (a shapely polygon,
    e.g. the map's extent) outside the sensor's range disk is ``sensor_range``; inside the disk but
    outside the field of view (or outside ``observed``, a polygon such as a camera's ground
    footprint) is ``field_of_view``. Empty differences are left out."""
    import shapely

    disk = sector_polygon(sensor_xy[0], sensor_xy[1], range_m)
    view = sector_polygon(sensor_xy[0], sensor_xy[1], range_m, yaw, fov)
    if observed is not None:
        view = shapely.intersection(view, observed)
    rows = []
    for kind, geom in (("sensor_range", shapely.difference(area, disk)),
                       ("field_of_view", shapely.difference(shapely.intersection(area, disk), view))):
        geom = _areal(geom)
        if geom is None:
            continue
        rows.append({"time_start": float(time_start), "time_end": float(time_end), "kind": kind,
                     "geometry": shapely.to_wkb(geom), "sensor_id": sensor_id, "occluder_id": None})
    return rows


def occlusion_shadows(sensor_xyz: tuple[float, float, float], x: np.ndarray, y: np.ndarray,
                      heading: np.ndarray, length: np.ndarray, width: np.ndarray,
                      height: np.ndarray, range_m: float) -> np.ndarray:
    """Ground shadows (WKB polygons, object array; None where empty) that boxes cast seen from a
    sensor at ``sensor_xyz`` (mount height z above the ground of the boxes).

    A corner at ground distance d from the sensor hides the ground up to d * H / (H - h) (similar
    triangles, sensor height H, box height h); boxes as tall as the sensor or taller hide
    everything up to ``range_m``. The shadow is the convex hull of the footprint and the projected
    corners, minus the footprint, clipped to the range disk. Vectorised with shapely 2."""
    import shapely

    n = len(x)
    if n == 0:
        return np.empty(0, dtype=object)
    sx, sy, sh = sensor_xyz
    corners = footprint_corners(x, y, heading, length, width)            # (n, 4, 2)
    d = corners - np.array([sx, sy])
    dist = np.linalg.norm(d, axis=2)
    h = np.asarray(height, np.float64)[:, None] * np.ones((1, 4))
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(h < sh - 1e-6, sh / (sh - h), np.inf)
    reach = np.minimum(dist * k, range_m)
    scale = np.where(dist > 0, reach / np.where(dist > 0, dist, 1.0), 1.0)
    far = np.array([sx, sy]) + d * scale[..., None]
    pts = np.concatenate([corners, far], axis=1)                          # (n, 8, 2)
    hull = shapely.convex_hull(shapely.multipoints(pts))
    foot = shapely.polygons(np.concatenate([corners, corners[:, :1]], axis=1))
    disk = sector_polygon(sx, sy, range_m)
    shadow = shapely.intersection(shapely.difference(hull, foot), disk)
    shadow = shapely.make_valid(shadow)
    keep = ~shapely.is_empty(shadow) & (shapely.area(shadow) > 1e-6)
    types = shapely.get_type_id(shadow)
    keep &= np.isin(types, (3, 6))  # Polygon, MultiPolygon
    out = np.full(n, None, dtype=object)
    out[keep] = shapely.to_wkb(shadow[keep])
    return out


def unobserved_table(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The ``unobserved`` table (columns) of region rows as :func:`coverage_regions` makes them;
    None for no rows."""
    if not rows:
        return None
    return {
        "region_id": np.arange(len(rows), dtype=np.int64),
        "time_start": np.array([r["time_start"] for r in rows], np.float64),
        "time_end": np.array([r["time_end"] for r in rows], np.float64),
        "kind": [r["kind"] for r in rows],
        "geometry": pa.array([r["geometry"] for r in rows], pa.binary()),
        "sensor_id": [r.get("sensor_id") for r in rows],
        "occluder_id": pa.array([r.get("occluder_id") for r in rows], pa.int64()),
    }


def outside_coverage(map_bytes: bytes, coverage_wkt: str, time_start: float, time_end: float,
                     sensor_id: str) -> dict[str, Any] | None:
    """An aerial view's unobserved table: the map's area (:func:`map_area`) outside the image's
    ground footprint ``coverage_wkt``, kind ``outside_coverage``, for the whole recording (None
    where the footprint covers it all). Occlusions (bridges, trees) are not known to such sources."""
    import shapely

    geom = _areal(shapely.difference(map_area(map_bytes), shapely.from_wkt(coverage_wkt)))
    if geom is None:
        return None
    return unobserved_table([{"time_start": float(time_start), "time_end": float(time_end),
                              "kind": "outside_coverage", "geometry": shapely.to_wkb(geom),
                              "sensor_id": sensor_id}])


def map_area(map_bytes: bytes, margin: float = 20.0):
    """A shapely box around the map's road surfaces (+ ``margin`` m): the area in which converters
    report sensor-range and field-of-view limits."""
    import shapely

    from aveas_format.opendrive import load_map

    xmin, ymin, xmax, ymax = load_map(map_bytes).bounds
    return shapely.box(xmin - margin, ymin - margin, xmax + margin, ymax + margin)
