"""Pieces every converter uses: reading tabular sources with located errors, moving reference
points, angle conventions, and finishing a recording with its ``source`` block."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aveas_format._version import __version__
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.mapref.build import build_recording, load_map_bytes
from aveas_format.numeric import fmt_num

__all__ = [
    "build_recording", "factorize", "file_sha256", "load_map_bytes", "move_along_heading",
    "navigation_deg_to_heading", "prefetch_sha256", "read_table", "source_block", "wrap_recording",
]


def _sha256(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    buf = bytearray(chunk)  # (one buffer read into again and again: no fresh pages per read)
    view = memoryview(buf)
    with open(path, "rb", buffering=0) as f:
        while n := f.readinto(buf):
            h.update(view[:n])
    return h.hexdigest()


#: digests being computed by :func:`prefetch_sha256`, by (path, size, mtime)
_PENDING: dict[tuple, Any] = {}


def _file_key(path: Path) -> tuple | None:
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return (str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def prefetch_sha256(path: Path) -> None:
    """Start hashing ``path`` in a thread (hashlib releases the GIL on large blocks), for a later
    :func:`file_sha256` of the same unchanged file: a converter calls it before reading a large
    input, so that the digest is not a serial step after the reading."""
    key = _file_key(path)
    if key is None or key in _PENDING:
        return
    from aveas_format.parallel import background

    _PENDING[key] = background(_sha256, Path(path), name="sha256")


def file_sha256(path: Path, chunk: int = 1 << 22) -> str:
    """The SHA-256 of the file ``path`` (hex; the one :func:`prefetch_sha256` started where the file
    is unchanged since)."""
    fut = _PENDING.pop(_file_key(path), None)
    if fut is not None:
        try:
            return fut.result()
        except OSError:
            pass
    return _sha256(path, chunk)


def source_block(converter: str, inputs: Iterable[Path], options: Any, version: str = "1",
                 resolved: dict[str, Any] | None = None) -> dict[str, Any]:
    """The recording.json ``source`` object: converter, versions, input names + SHA-256, options.
    ``resolved``: what the converter decided where an option left it open (``auto``: the unit
    it inferred, the reconstruction it applied), recorded over the options' values."""
    opts = options.model_dump(mode="json") if hasattr(options, "model_dump") else dict(options or {})
    opts.update(resolved or {})
    return {
        "converter": converter,
        "converter_version": f"{version} (aveas-format {__version__})",
        "inputs": [{"file": Path(p).name, "sha256": file_sha256(Path(p))} for p in inputs],
        "options": opts,
    }


def read_table(path: Path, *, required: Sequence[str] = (), numeric: Sequence[str] = (),
               delimiter: str | None = None) -> pa.Table:
    """Read a CSV (any delimiter, sniffed from the header) or Parquet file.

    Errors name the file and, for CSV, the line: a row with the wrong number of fields, a missing
    required column, a non-numeric value in a numeric column (with its line and column).
    """
    path = Path(path)
    if not path.is_file():
        raise RecordingIOError("input not found", path=path)
    if path.suffix.lower() == ".parquet":
        try:
            table = pq.read_table(path)
        except (pa.ArrowException, OSError) as e:
            raise RecordingIOError(f"not a readable Parquet file: {str(e).splitlines()[0]}",
                                   path=path) from None
        _check_required(table, required, path)
        return _numeric(table, numeric, path, header_lines=0)
    if delimiter is None:
        with open(path, "rb") as f:
            head = f.readline().decode("utf-8", "replace")
        delimiter = max((",", ";", "\t"), key=head.count) if head else ","
    try:
        table = pacsv.read_csv(
            path, parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(
                column_types={c: pa.string() for c in numeric}, strings_can_be_null=True),
        )
    except pa.ArrowInvalid as e:
        msg = str(e).splitlines()[0]
        import re

        m = re.search(r"[Rr]ow #(\d+)", str(e))
        line = int(m.group(1)) if m else None
        raise FormatError(f"malformed CSV: {msg}", path=path, line=line) from None
    try:
        table.column_names  # noqa: B018 — decodes the header
    except UnicodeDecodeError:
        raise FormatError("the CSV header is not UTF-8 text", path=path, line=1) from None
    dup = next((c for i, c in enumerate(table.column_names) if c in table.column_names[:i]), None)
    if dup is not None:
        raise FormatError(f"column {dup!r} appears more than once in the header", path=path, line=1)
    reject_non_utf8(table, path, header_lines=1)
    _check_required(table, required, path)
    return _numeric(table, numeric, path, header_lines=1)


def reject_non_utf8(table: pa.Table, path: Path, header_lines: int = 1) -> None:
    """A CSV column that pyarrow typed as binary holds bytes that are not UTF-8 text: raise a
    :class:`FormatError` naming the column and the line of the first such value (instead of an
    ``ArrowInvalid`` from a later cast to string)."""
    for c, col in zip(table.column_names, table.columns):
        if not (pa.types.is_binary(col.type) or pa.types.is_large_binary(col.type)):
            continue
        for i, v in enumerate(col.to_pylist()):
            if v is None:
                continue
            try:
                v.decode("utf-8")
            except UnicodeDecodeError:
                raise FormatError(f"column {c!r}: value is not UTF-8 text", path=path,
                                  line=i + 1 + header_lines) from None


def _check_required(table: pa.Table, required: Sequence[str], path: Path) -> None:
    missing = [c for c in required if c not in table.column_names]
    if missing:
        raise FormatError(f"required column(s) {missing} missing; found {table.column_names}",
                          path=path)


def _numeric(table: pa.Table, numeric: Sequence[str], path: Path, header_lines: int) -> pa.Table:
    for c in numeric:
        if c not in table.column_names:
            continue
        col = table.column(c)
        if pa.types.is_floating(col.type) or pa.types.is_integer(col.type) or pa.types.is_null(col.type):
            col = col.cast(pa.float64())
        else:
            s = pc.utf8_trim_whitespace(col.cast(pa.string()))
            num = _try_float(s)
            if num is None:
                vals = s.to_pylist()
                bad = next(i for i, v in enumerate(vals) if v not in (None, "") and not is_float(v))
                raise FormatError(f"column {c!r}: {vals[bad]!r} is not a number", path=path,
                                  line=bad + 1 + header_lines if header_lines else None,
                                  row=None if header_lines else bad)
            col = num
        table = table.set_column(table.column_names.index(c), c, col)
    return table


def _try_float(s: pa.ChunkedArray) -> pa.ChunkedArray | None:
    try:
        empty = pc.equal(s, "")
        return pc.if_else(empty, pa.scalar(None, pa.string()), s).cast(pa.float64())
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None


def is_float(v: str) -> bool:
    """Does ``float(v)`` accept the string ``v`` (for locating the first value that is not a
    number)?"""
    try:
        float(v)
        return True
    except ValueError:
        return False


# --- reference points and angles -----------------------------------------------------------------

def move_along_heading(x: np.ndarray, y: np.ndarray, heading: np.ndarray, d: np.ndarray | float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Move points by ``d`` metres along their heading (negative = backwards).

    SUMO's front bumper -> footprint centre is ``d = -length / 2``.
    """
    return x + d * np.cos(heading), y + d * np.sin(heading)


def navigation_deg_to_heading(angle_deg: np.ndarray) -> np.ndarray:
    """Navigational degrees (0 = north, clockwise) -> heading (rad, counter-clockwise from +x,
    wrapped to (-pi, pi])."""
    from aveas_format.numeric import wrap_angle

    return wrap_angle(np.pi / 2 - np.radians(angle_deg))


def factorize(values: Sequence[Any] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(codes, uniques) in order of first appearance: source ids -> participant ids 0..n-1."""
    arr = pa.array(np.asarray(values, dtype=object) if not isinstance(values, pa.Array) else values)
    enc = pc.dictionary_encode(arr.cast(pa.string()))
    return enc.indices.to_numpy().astype(np.int64), np.asarray(enc.dictionary.to_pylist(), dtype=object)


def wrap_recording(converter: str, inputs: Sequence[Path], options: Any, *, map_bytes: bytes,
                   participants: dict[str, Any], states: dict[str, Any], version: str = "1",
                   partner: str = "unknown", start_time: str = "1970-01-01T00:00:00Z",
                   resolved: dict[str, Any] | None = None, **kw: Any):
    """Finish a conversion: build the recording (lon/lat and road coordinates through the map,
    defaults filled) with the ``source`` block naming the converter, inputs and options.

    ``partner``/``start_time`` are the converter's defaults (e.g. from the source's metadata); the
    common import options (:class:`~aveas_format.converters.registry.ImportOptions`) override them.
    """
    o = options
    partner = getattr(o, "partner", None) or partner
    meta: dict[str, Any] = {
        "start_time": getattr(o, "start_time", None) or start_time,
        "rights": {"right_of_use": getattr(o, "right_of_use", "research_only"),
                   "license": getattr(o, "license", "unspecified"),
                   "owner": getattr(o, "owner", None) or partner},
    }
    for key in ("recording_id", "title"):
        if getattr(o, key, None):
            meta[key] = getattr(o, key)
    meta.update(kw)
    if getattr(o, "crs", None) and getattr(o, "crs_is_recording_crs", True) and not meta.get("crs"):
        meta["crs"] = o.crs
        meta["check_map_crs"] = True  # the user's CRS must agree with the map's geoReference
    return build_recording(map_source=map_bytes, participants=participants, states=states,
                           partner=partner,
                           source=source_block(converter, inputs, options, version, resolved),
                           **meta)


# --- sensor converters (issue 7): rotations, covariances, velocities, unobserved regions ----------
# Appended helpers shared by ros2_mcap, infra_lidar, infra_lwir and accident.

def utc_iso_from_ns(t_ns: int) -> str:
    """ISO 8601 UTC text (nanosecond precision) of nanoseconds since the Unix epoch."""
    from datetime import datetime, timezone

    sec, ns = divmod(int(t_ns), 1_000_000_000)
    base = datetime.fromtimestamp(sec, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    return f"{base}.{ns:09d}Z"


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) quaternions ``(qx, qy, qz, qw)`` (normalised here;
    an all-zero quaternion counts as identity)."""
    q = np.atleast_2d(np.asarray(q, np.float64))
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 0.0, 1.0]))
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def matrix_yaw(r: np.ndarray) -> np.ndarray:
    """Yaw (rad, CCW from +x) of the body x-axis of (n, 3, 3) rotations, projected on the ground."""
    r = np.asarray(r)
    return np.arctan2(r[..., 1, 0], r[..., 0, 0])


def rotation_2d(theta: np.ndarray) -> np.ndarray:
    """(n, 2, 2) rotation matrices."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=-2)


def rotate_covariance_2d(cov: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """R(theta) C R(theta)^T for (n, 2, 2) covariances."""
    r = rotation_2d(np.asarray(theta, np.float64))
    return np.einsum("nij,njk,nlk->nil", r, cov, r)


def covariance_std_corr(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sx, sy, corr) of (n, 2, 2) covariances; NaN stays NaN (unknown), corr is 0 where a
    standard deviation is 0, and clipped to [-1, 1]."""
    sx = np.sqrt(np.clip(cov[:, 0, 0], 0.0, None))
    sy = np.sqrt(np.clip(cov[:, 1, 1], 0.0, None))
    den = sx * sy
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.where(den > 0, cov[:, 0, 1] / np.where(den > 0, den, 1.0), 0.0)
    corr = np.where(np.isnan(den), np.nan, np.clip(corr, -1.0, 1.0))
    return sx, sy, corr


def nullable(a: np.ndarray) -> pa.Array:
    """A float array with NaN as null (for ``_std``/``_corr`` columns: null = unknown)."""
    return pa.array(np.asarray(a, np.float64), from_pandas=True)


def footprint_corners(x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: np.ndarray,
                      width: np.ndarray) -> np.ndarray:
    """(n, 4, 2) corners (front-left, rear-left, rear-right, front-right) of oriented boxes."""
    c, s = np.cos(heading), np.sin(heading)
    hl, hw = np.asarray(length) / 2.0, np.asarray(width) / 2.0
    out = np.empty((len(x), 4, 2))
    for k, (a, b) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        out[:, k, 0] = x + a * hl * c - b * hw * s
        out[:, k, 1] = y + a * hl * s + b * hw * c
    return out


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
    import pyarrow as pa

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


def class_of(name: str, extra: dict[str, str] | None = None) -> str:
    """One of the 13 classes for a class name of a source (case- and separator-insensitive);
    ``extra`` maps source names first; unknown names become ``other``. Whether the label is a road
    user at all: :func:`aveas_format.converters.labels.label_kind`."""
    from aveas_format.converters.labels import label_kind

    return label_kind(name, extra)[0]


def group_mean(codes: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Mean of ``values`` (n_rows,) or (n_rows, k) per code 0..n-1, NaN-aware (NaN where none)."""
    v = np.asarray(values, np.float64)
    v2 = v.reshape(len(v), -1)
    ok = ~np.isnan(v2)
    out = np.empty((n, v2.shape[1]))
    for j in range(v2.shape[1]):
        s = np.bincount(codes, weights=np.where(ok[:, j], v2[:, j], 0.0), minlength=n)
        c = np.bincount(codes, weights=ok[:, j].astype(float), minlength=n)
        out[:, j] = np.where(c > 0, s / np.where(c > 0, c, 1.0), np.nan)
    return out.reshape((n,) + v.shape[1:])


def group_std(codes: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Standard deviation of ``values`` (1D) per code (NaN where fewer than 2 samples)."""
    v = np.asarray(values, np.float64)
    ok = ~np.isnan(v)
    c = np.bincount(codes, weights=ok.astype(float), minlength=n)
    m = group_mean(codes, v, n)
    d2 = np.where(ok, (v - m[codes]) ** 2, 0.0)
    s = np.bincount(codes, weights=d2, minlength=n)
    return np.where(c > 1, np.sqrt(s / np.maximum(c - 1, 1)), np.nan)


def read_numeric_table(path: Path, *, required: Sequence[str] = (), numeric: Sequence[str] = (),
                       delimiter: str | None = None) -> pa.Table:
    """:func:`read_table` with ``numeric`` columns as float64 (empty -> null); a value that is not a
    number raises a :class:`FormatError` naming the file, CSV line and column."""
    return read_table(path, required=required, numeric=numeric, delimiter=delimiter)


def projected_to_local(x: np.ndarray, y: np.ndarray, source_crs: str, map_crs: str,
                       map_offset: tuple[float, float, float, float] | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points in a projected source CRS (UTM, a world file's CRS, ...) -> the map's local frame
    (its ``geoReference`` ``map_crs`` and header ``<offset>``).

    Returns ``(x, y, rotation)``: ``rotation`` (rad, per point or scalar) is the angle that source
    directions turn by in the local frame: add it to source headings and rotate source vectors by
    it (:func:`rotate`). It holds the header offset's ``hdg`` and, where the two CRSs differ, the
    local grid convergence between them (measured by projecting a point 1 m east of each point).
    """
    from aveas_format.mapref.crs import LocalFrame, crs_equal, parse_crs

    frame = LocalFrame(map_crs, map_offset, warn=False)
    hdg = frame.offset[3]
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if crs_equal(source_crs, map_crs):
        lx, ly = frame.from_projected(x, y)
        return lx, ly, np.full(x.shape, -hdg)
    import pyproj

    tr = pyproj.Transformer.from_crs(parse_crs(source_crs).crs, parse_crs(map_crs).crs,
                                     always_xy=True)
    px, py = (np.asarray(a, np.float64) for a in tr.transform(x, y))
    qx, qy = (np.asarray(a, np.float64) for a in tr.transform(x + 1.0, y))
    rot = np.arctan2(qy - py, qx - px) - hdg
    lx, ly = frame.from_projected(px, py)
    return lx, ly, rot


def rotate(vx: np.ndarray, vy: np.ndarray, angle: np.ndarray | float
           ) -> tuple[np.ndarray, np.ndarray]:
    """Vectors rotated counter-clockwise by ``angle`` (rad)."""
    c, s = np.cos(angle), np.sin(angle)
    return vx * c - vy * s, vx * s + vy * c


def class_pmf(labels: Sequence[str] | np.ndarray, confidence: float = 1.0) -> np.ndarray:
    """(n, 13) PMF matrix for hard class labels: ``confidence`` on the label, the rest spread evenly
    over the other 12 classes (``confidence`` = 1: one-hot)."""
    from aveas_format.schema.pmf import one_hot

    oh = one_hot(np.asarray(labels, dtype=object), "class").astype(np.float64)
    k = oh.shape[1]
    pm = oh * confidence + (1.0 - oh) * (1.0 - confidence) / (k - 1)
    return pm.astype(np.float32)


def sort_states(pid: np.ndarray, t: np.ndarray, path: Path | None = None,
                lines: np.ndarray | None = None, *, ids: Sequence[Any] | np.ndarray | None = None,
                unit: str = "line") -> np.ndarray:
    """Row order sorting by (participant, time); a duplicate (participant, time) is an error naming
    the line (``lines``: the source line of each row; ``unit``: what ``lines`` counts, e.g.
    ``"message"``) of its second occurrence, and the participant's source id (``ids``, indexed by
    ``pid``) where given."""
    order = np.lexsort((t, pid))
    ps, ts = pid[order], t[order]
    dup = np.flatnonzero((ps[1:] == ps[:-1]) & (ts[1:] == ts[:-1]))
    if len(dup):
        i = order[dup[0] + 1]
        who = "participant" if ids is None else f"participant {str(ids[int(pid[i])])!r}"
        raise FormatError(f"{who} sampled twice at time {fmt_num(t[i])}", path=path,
                          **{unit: None if lines is None else int(lines[i])})
    return order


# --- exports: what a re-import needs ---------------------------------------------------------------

def companion_map_path(output: Path, options: Any) -> Path | None:
    """Where an exporter writes the map next to its ``output``: the option ``map_file`` or the
    output's name with ``.xodr``; None where the exporter has no map or ``write_map`` is off. The
    one rule of every exporter that writes a map (the ``export`` command refuses to replace it
    without ``--overwrite``)."""
    if not getattr(options, "write_map", False):
        return None
    output = Path(output)
    return output.parent / (getattr(options, "map_file", None) or f"{output.stem}.xodr")


def companion_map(rec) -> bytes | None:
    """The map to write next to an export: the recording's map, with the recording's ``crs`` as its
    ``<geoReference>`` where the map has none, so that the export's re-import finds the frame
    (FORMAT.md: without a geoReference, ``crs`` alone defines it; the OpenSCENARIO and OSI re-imports
    read it from this map). The rest of the map's bytes are unchanged."""
    import re

    data = rec.map_source
    if data is None:
        return None
    crs = rec.meta.crs
    if not crs or rec.map.header.geo_reference:
        return data
    head = re.search(rb"<header\b[^>]*?(/?)>", data)
    if head is None:
        return data
    geo = b"<geoReference><![CDATA[" + crs.replace("]]>", "").encode() + b"]]></geoReference>"
    if head.group(1):  # <header .../>
        new = head.group(0)[:-2].rstrip() + b">" + geo + b"</header>"
    else:
        new = head.group(0) + geo
    return data[:head.start()] + new + data[head.end():]

# --- timestamps of foreign files: unit and epoch inferred, or given -------------------------------

#: ``timestamp_unit`` option values: ``auto`` infers the unit (see :func:`resolve_timestamps`)
TIMESTAMP_UNITS = ("auto", "s", "ms", "us", "ns")
_NS_PER = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_UNIT_WORD = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
#: Unix times (s) counted as absolute: 1990-01-01 .. 2100-01-01
EPOCH_RANGE_S = (631_152_000, 4_102_444_800)


class Timestamps:
    """Timestamps of a source resolved to seconds since the first: ``seconds`` (float64 array,
    NaN where a value was missing), ``start_ns`` (Unix nanoseconds of the first, or None when the
    source counts from its own start), ``unit`` (s/ms/us/ns, or iso8601), ``epoch`` and ``note``
    (what was decided and why, for the ``source`` block)."""

    def __init__(self, seconds: np.ndarray, start_ns: int | None, unit: str, epoch: bool, note: str):
        self.seconds, self.start_ns, self.unit, self.epoch, self.note = seconds, start_ns, unit, epoch, note

    @property
    def start_time(self) -> str | None:
        return None if self.start_ns is None else utc_iso_from_ns(self.start_ns)

    def resolved(self) -> dict[str, str]:
        """The choice as option values for the ``source`` block (re-running with them repeats it)."""
        return {"timestamp_unit": self.unit, "timestamps": self.note}


def iso_to_ns(text: str) -> int | None:
    """Unix nanoseconds of an ISO 8601 date-time (``Z``, an offset or none = UTC; any number of
    fraction digits), or None when the text is not one."""
    import re
    from datetime import datetime, timezone

    m = re.fullmatch(r"\s*(\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2})?)(?:[.,](\d{1,9})\d*)?"
                     r"(Z|[+-]\d{2}(?::?\d{2})?)?\s*", text)
    if not m:
        return None
    tz = m[3] or "Z"
    tz = "+00:00" if tz == "Z" else (tz + ":00" if len(tz) == 3 else tz if ":" in tz else tz[:3] + ":" + tz[3:])
    try:
        dt = datetime.fromisoformat(m[1].replace(" ", "T") + tz).astimezone(timezone.utc)
    except ValueError:
        return None
    return int(dt.timestamp()) * 1_000_000_000 + int((m[2] or "").ljust(9, "0"))


def timestamp_value(v: Any) -> int | float | str | None:
    """A number (exact int where the text is an integer, so that epoch nanoseconds keep their
    digits), an ISO text kept as text, None where absent or unreadable."""
    if v is None or isinstance(v, bool):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, str):
        t = v.strip()
        if t.lstrip("+-").isdigit():
            return int(t)
        try:
            f = float(t)
            return f if np.isfinite(f) else None
        except ValueError:
            return t if iso_to_ns(t) is not None else None
    return None


def resolve_timestamps(values: Sequence[Any], unit: str = "auto", *, what: str = "timestamps"
                       ) -> Timestamps:
    """Seconds since the first of timestamps whose unit and epoch a format leaves open (OpenLABEL's
    ``frame_properties.timestamp``: numbers or numeric strings, or ISO 8601 texts).

    ``unit`` = ``auto`` infers it: values whose magnitude puts them between 1990 and 2100 as
    seconds, milliseconds, microseconds or nanoseconds since the Unix epoch are read so (the four
    ranges are 1000x apart, so at most one fits); smaller values count from the source's own
    start, in the unit their median spacing suggests (< 5: s, < 5e3: ms, < 5e6: us, else ns — a
    frame period of 0.2 ms .. 5 s). A given ``unit`` fixes the unit; the epoch is still told by
    the magnitude. ISO texts are absolute. Values are kept exact (integers) until the difference
    to the first is taken, so nanosecond epochs lose nothing."""
    if unit not in TIMESTAMP_UNITS:
        raise FormatError(f"timestamp_unit {unit!r}: expected one of {', '.join(TIMESTAMP_UNITS)}")
    vals = [timestamp_value(v) for v in values]
    have = [v for v in vals if v is not None]
    n = len(vals)
    if not have:
        return Timestamps(np.full(n, np.nan), None, unit if unit != "auto" else "s", False,
                          f"no {what}")
    if any(isinstance(v, str) for v in have):
        if not all(isinstance(v, str) for v in have):
            raise FormatError(f"{what} mix ISO 8601 texts and numbers")
        ns = [None if v is None else iso_to_ns(v) for v in vals]
        t0 = min(x for x in ns if x is not None)
        sec = np.array([np.nan if x is None else (x - t0) / 1e9 for x in ns])
        return Timestamps(sec, t0, "iso8601", True, f"{what}: ISO 8601 date-times (UTC)")
    mag = max(abs(float(v)) for v in have)
    srt = np.unique(np.asarray([float(v) for v in have]))
    dts = np.diff(srt)
    spacing = float(np.median(dts)) if len(dts) else None
    how = "given"
    epoch = False
    if unit == "auto":
        how = "inferred from magnitude %.3g" % mag + (f" and spacing {spacing:.3g}" if spacing else "")
        for u in ("s", "ms", "us", "ns"):
            if EPOCH_RANGE_S[0] <= mag * _NS_PER[u] / 1e9 <= EPOCH_RANGE_S[1]:
                unit, epoch = u, True
                break
        else:
            sp = spacing if spacing else 0.0
            unit = "s" if sp < 5 else "ms" if sp < 5e3 else "us" if sp < 5e6 else "ns"
    else:
        epoch = EPOCH_RANGE_S[0] <= mag * _NS_PER[unit] / 1e9 <= EPOCH_RANGE_S[1]
    scale = _NS_PER[unit]
    first = min(have)
    if all(isinstance(v, int) for v in have):
        sec = np.array([np.nan if v is None else (v - first) * scale / 1e9 for v in vals])
        start_ns = first * scale if epoch else None
    else:
        sec = np.array([np.nan if v is None else (float(v) - float(first)) * scale / 1e9 for v in vals])
        start_ns = int(round(float(first) * scale)) if epoch else None
    ref = "since the Unix epoch" if epoch else "since the start of the recording"
    return Timestamps(sec, start_ns, unit, epoch, f"{what}: {_UNIT_WORD[unit]} {ref} ({how})")
