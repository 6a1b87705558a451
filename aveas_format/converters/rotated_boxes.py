"""Rotated-box tracks on a georeferenced image -> recording (the aircraft pipeline: rotation-invariant
detection + DeepSORT-style tracking on a georeferenced orthophoto / stabilised video).

Inputs: a track table (CSV or Parquet) and its georeference: an ESRI world file (``.tfw``,
``.pgw``, ``.jgw``, ``.wld``, ...) with the CRS from a ``.prj`` file or the ``crs`` option, or a GDAL
``.aux.xml`` (``<GeoTransform>`` and ``<SRS>``), or the ``geotransform`` option.

Track table, one row per box and frame (pixel coordinates of the image, u to the right, v down):

- ``track_id``; ``time`` (s) or ``frame`` (with the ``frame_rate`` option: time = frame / rate).
- The box, either ``cx, cy, w, h, angle`` (centre, extent along and across the box's axis, and the
  axis' rotation from +u towards +v, i.e. clockwise on screen as in OpenCV / mmrotate; degrees, or
  radians with ``angle_unit``), or DOTA-style corners ``x1, y1, ..., x4, y4`` in order around the box.
- Class: ``score_<class>`` columns (any of the 13 format classes, or labels named in ``class_map``)
  -> per-row PMF (normalised), or ``class`` with an optional ``score`` (the label's probability, the
  rest spread over the other classes). DOTA labels ``small-vehicle`` -> car and ``large-vehicle``
  -> truck are known; DOTA's other categories (plane, ship, storage-tank, baseball-diamond,
  tennis-court, basketball-court, ground-track-field, harbor, bridge, helicopter, roundabout,
  soccer-ball-field, swimming-pool, container-crane, airport, helipad) are no road users: a track
  whose ``class`` is one is skipped with a count in a warning, unless ``keep_non_road_users``
  (then class other; ``score_<category>`` columns of them count as other). An unknown label is an
  error naming the line. A participant's ``class_pmf`` is the mean of its rows' PMFs.
- Optional per-row pixel noise ``cx_std``, ``cy_std`` (px) and ``cxcy_corr``; else ``pixel_std``.

Georeference conventions: a world file's C, F are the map coordinates of the **centre** of the
upper-left pixel (x = A col + B row + C, y = D col + E row + F for pixel indices col, row); a GDAL
geotransform's GT0, GT3 are those of the upper-left **corner** (X = GT0 + u GT1 + v GT2,
Y = GT3 + u GT4 + v GT5). Box coordinates are continuous pixel coordinates whose origin is the
upper-left corner of the image (``pixel_origin = "corner"``, the usual detector convention: pixel
(0, 0)'s centre is at (0.5, 0.5)) or its first pixel's centre (``"center"``).

What the converter does: box centres go through the affine transform into the georeference's CRS,
then into the map's local frame (through the map's geoReference and header offset, with the local
grid convergence applied to directions); where the map has no geoReference, its frame is the
georeference's CRS. The box axis gives the heading up to 180 deg; the direction of motion (velocity
above ``heading_min_speed``, held while slower) resolves it, so a track that never moves keeps the
orientation nearest +x. Length = the longer box side, width = the shorter (per participant: median
over its frames, std = max(their spread, one pixel)). Velocities come from a local linear
regression of the positions over ``velocity_window`` seconds (exact for constant acceleration inside
a track), with their std from the regression.

Uncertainty: the centre's pixel covariance (``pixel_std`` or the per-row columns) is propagated
through the affine transform and the rotation into the local frame: ``x_std``, ``y_std``,
``xy_corr``; ``heading_std`` = ``angle_std_deg``; ``vx_std``/``vy_std``/``vxvy_corr`` from the
regression. Method ``aerial``, provenance ``natural``, role ``observed``; lights and interior are
not observable. ``coverage`` is the image footprint when ``image_size`` is given; the map's area
outside it is then an ``outside_coverage`` region of ``unobserved`` for the whole recording
(occlusions are not in the data and not claimed).

Tested on: fixtures made from an analytic truth (world files, GDAL ``.aux.xml``, DOTA-style corner
columns and categories; tests/converters/test_rotated_boxes.py). No real detector output or DOTA
label file is in ``../shared/data`` (the DOTA dev-kit's example labels carry no licence).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Footprint, Rows, Sensor, Sizes
from aveas_format.converters.common.geometry import projected_to_local
from aveas_format.converters.common.tables import factorize, header_names, read_table
from aveas_format.converters.labels import NOT_ROAD_USER, LabelFilter, label_kind
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes
from aveas_format.safeio import xml_parser
from aveas_format.schema.taxonomy import CLASSES

WORLD_FILE_SUFFIXES = (".tfw", ".tifw", ".pgw", ".pngw", ".jgw", ".jpgw", ".j2w", ".gfw", ".bpw",
                       ".wld")
DEFAULT_CLASS_MAP = {"small-vehicle": "car", "small_vehicle": "car", "large-vehicle": "truck",
                     "large_vehicle": "truck", "person": "pedestrian", "cyclist": "bicycle",
                     "motorbike": "motorcycle"}
_CORNERS = tuple(f"{a}{i}" for i in range(1, 5) for a in ("x", "y"))
_CENTRE = ("cx", "cy", "w", "h", "angle")


class RotatedBoxOptions(ImportOptions):
    frame_rate: float | None = None
    """Frames per second, where the table has ``frame`` instead of ``time``."""
    crs_is_recording_crs: ClassVar[bool] = False
    crs: str | None = None
    """CRS (EPSG/PROJ/WKT) of the georeference, where no .prj / .aux.xml gives it (``--crs``);
    projected into the map's frame where the map has a geoReference, else the recording's CRS."""
    geotransform: tuple[float, float, float, float, float, float] | None = None
    """GDAL geotransform (GT0..GT5, upper-left pixel corner) instead of a world file."""
    pixel_origin: Literal["corner", "center"] = "corner"
    """Origin of the box pixel coordinates: the image's upper-left corner or its first pixel's centre."""
    angle_unit: Literal["deg", "rad"] = "deg"
    """Unit of the ``angle`` column."""
    pixel_std: float = 1.0
    """1-sigma error of the box centre per pixel axis (px), where no cx_std/cy_std columns."""
    angle_std_deg: float = 2.0
    """1-sigma error of the box orientation (deg)."""
    velocity_window: float = 0.5
    """Width (s) of the local linear regression that estimates velocities."""
    heading_min_speed: float = 1.0
    """Speed (m/s) above which the direction of motion picks the heading among the box's two."""
    class_map: dict[str, str] = {}
    """Source class labels -> format classes (adds to the DOTA defaults)."""
    keep_non_road_users: bool = False
    """Import tracks whose ``class`` is no road user (DOTA's plane, ship, storage-tank, harbor,
    ...; see docs/converters.md "Labels that are not road users") as class other; by default
    they are skipped with a count in a warning."""
    image_size: tuple[int, int] | None = None
    """Image width and height (px): the footprint becomes the recording's coverage."""
    platform: str | None = None
    """acquisition.platform (default: 'aerial camera, GSD ... m')."""


# --- georeference --------------------------------------------------------------------------------

def read_world_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(A 2x2, c) of an ESRI world file, for corner-based pixel coordinates: X = A @ (u, v) + c."""
    lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines()]
    vals: list[float] = []
    for i, ln in enumerate(lines, 1):
        if not ln:
            continue
        try:
            vals.append(float(ln))
        except ValueError:
            raise FormatError(f"world file value {ln!r} is not a number", path=path, line=i) from None
    if len(vals) != 6:
        raise FormatError(f"a world file has 6 numbers (A, D, B, E, C, F), found {len(vals)}",
                          path=path)
    a, d, b, e, c, f = vals
    A = np.array([[a, b], [d, e]])
    # C, F are the centre of pixel (0, 0), i.e. corner coordinates (0.5, 0.5)
    c0 = np.array([c, f]) - A @ np.array([0.5, 0.5])
    return A, c0


def geotransform_affine(gt: tuple[float, ...] | list[float]) -> tuple[np.ndarray, np.ndarray]:
    """(A 2x2, c) of a GDAL geotransform (corner-based)."""
    g = [float(v) for v in gt]
    return np.array([[g[1], g[2]], [g[4], g[5]]]), np.array([g[0], g[3]])


def read_aux_xml(path: Path) -> tuple[tuple[np.ndarray, np.ndarray] | None, str | None]:
    from lxml import etree

    try:
        root = etree.parse(str(path), xml_parser())
    except (OSError, etree.XMLSyntaxError) as e:
        raise FormatError(f"cannot parse GDAL .aux.xml: {e}", path=path,
                          line=getattr(e, "lineno", None)) from None
    gt_el = root.find(".//GeoTransform")
    srs_el = root.find(".//SRS")
    affine = None
    if gt_el is not None:
        parts = [p for p in re.split(r"[,\s]+", gt_el.text or "") if p]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            vals = []
        if len(vals) != 6:
            raise FormatError(f"<GeoTransform> needs 6 numbers, got {gt_el.text!r}", path=path,
                              line=gt_el.sourceline)
        affine = geotransform_affine(vals)
    srs = (srs_el.text or "").strip() if srs_el is not None else None
    return affine, srs or None


def _georeference(inputs: list[Path], options: RotatedBoxOptions
                  ) -> tuple[np.ndarray, np.ndarray, str, list[Path], list[Path]]:
    """(A, c, crs, table files, georeference files)."""
    tables, geo = [], []
    affine = None
    crs = options.crs
    crs_from: Path | None = None
    for p in inputs:
        name = p.name.lower()
        if p.suffix.lower() in WORLD_FILE_SUFFIXES:
            affine = read_world_file(p)
            geo.append(p)
        elif name.endswith(".aux.xml"):
            aff, srs = read_aux_xml(p)
            affine = aff or affine
            if not crs and srs:
                crs, crs_from = srs, p
            geo.append(p)
        elif p.suffix.lower() == ".prj":
            if not crs:
                crs, crs_from = p.read_text(errors="replace").strip(), p
            geo.append(p)
        else:
            tables.append(p)
    if options.geotransform is not None:
        affine = geotransform_affine(options.geotransform)
    if affine is None:
        raise FormatError("no georeference: pass a world file (.tfw/.pgw/.jgw/.wld), a GDAL "
                          ".aux.xml or the geotransform option", path=tables[0] if tables else None)
    A, c = affine
    if abs(np.linalg.det(A)) < 1e-12:
        raise FormatError("the georeference's pixel size is zero (singular affine transform)",
                          path=geo[0] if geo else None)
    if not crs:
        raise FormatError("the georeference has no CRS: pass a .prj file or the crs option",
                          path=geo[0] if geo else None)
    if not tables:
        raise RecordingIOError("no track table among the inputs", path=inputs[0])
    _check_crs(crs, crs_from)
    return A, c, crs, tables, geo


def _check_crs(crs: str, source: Path | None) -> None:
    """Read the georeference's CRS now, so that an unreadable one is reported with its file (the
    .prj / .aux.xml it came from; none for the crs option)."""
    from pyproj.exceptions import CRSError

    from aveas_format.crs import parse_crs

    try:
        parse_crs(crs)
    except (FormatError, CRSError, ValueError) as e:
        where = "the crs option" if source is None else "the georeference"
        raise FormatError(f"{where}: unreadable CRS {crs[:200]!r}: {str(e).splitlines()[0]}",
                          path=source) from None


# --- boxes ---------------------------------------------------------------------------------------

def _boxes(t: pa.Table, options: RotatedBoxOptions, A: np.ndarray, c: np.ndarray, path: Path):
    """Per row: world centre (X, Y), box axis direction (world, rad mod pi), length, width (m)."""
    names = set(t.column_names)
    shift = 0.5 if options.pixel_origin == "center" else 0.0
    if set(_CENTRE) <= names:
        u = column_numpy(t, "cx") + shift
        v = column_numpy(t, "cy") + shift
        w, h = column_numpy(t, "w"), column_numpy(t, "h")
        ang = column_numpy(t, "angle")
        if options.angle_unit == "deg":
            ang = np.radians(ang)
        du, dv = np.cos(ang), np.sin(ang)           # along w
        ax_w = A @ np.vstack([du, dv])
        ax_h = A @ np.vstack([-dv, du])
        len_w = w * np.hypot(*ax_w)
        len_h = h * np.hypot(*ax_h)
        X = A[0, 0] * u + A[0, 1] * v + c[0]
        Y = A[1, 0] * u + A[1, 1] * v + c[1]
        along_w = len_w >= len_h
        axis = np.where(along_w, np.arctan2(ax_w[1], ax_w[0]), np.arctan2(ax_h[1], ax_h[0]))
        length = np.where(along_w, len_w, len_h)
        width = np.where(along_w, len_h, len_w)
    elif set(_CORNERS) <= names:
        px = np.stack([column_numpy(t, f"x{i}") + shift for i in range(1, 5)])
        py = np.stack([column_numpy(t, f"y{i}") + shift for i in range(1, 5)])
        wx = A[0, 0] * px + A[0, 1] * py + c[0]
        wy = A[1, 0] * px + A[1, 1] * py + c[1]
        X, Y = wx.mean(axis=0), wy.mean(axis=0)
        ea = np.array([wx[1] - wx[0] + wx[2] - wx[3], wy[1] - wy[0] + wy[2] - wy[3]]) / 2
        eb = np.array([wx[2] - wx[1] + wx[3] - wx[0], wy[2] - wy[1] + wy[3] - wy[0]]) / 2
        la, lb = np.hypot(*ea), np.hypot(*eb)
        along_a = la >= lb
        axis = np.where(along_a, np.arctan2(ea[1], ea[0]), np.arctan2(eb[1], eb[0]))
        length, width = np.where(along_a, la, lb), np.where(along_a, lb, la)
    else:
        raise FormatError(f"the table needs box columns {list(_CENTRE)} or {list(_CORNERS)}; found "
                          f"{t.column_names}", path=path)
    bad = np.flatnonzero(~(np.isfinite(X) & np.isfinite(Y) & np.isfinite(axis) & (width > 0)))
    if len(bad):
        raise FormatError("box is empty, degenerate or has missing values", path=path,
                          line=int(bad[0]) + 2)
    return X, Y, axis, length, width


def _road_users(t: pa.Table, options: RotatedBoxOptions, path: Path) -> pa.Table:
    """The rows of tracks whose ``class`` (its first row's) is a road user; DOTA's other
    categories (plane, ship, storage-tank, ...) are skipped with a warning unless
    ``keep_non_road_users`` (then they are class other)."""
    if "class" not in t.column_names or "track_id" not in t.column_names:
        return t
    labels = LabelFilter(options.keep_non_road_users,
                         {**DEFAULT_CLASS_MAP, **{k.lower(): v for k, v in options.class_map.items()}})
    tid = t.column("track_id").cast(pa.string()).to_pylist()
    cls = t.column("class").cast(pa.string()).fill_null("").to_pylist()
    first: dict[str, str] = {}
    for i, c in zip(tid, cls):
        first.setdefault(i, c)
    keep_track = {i: labels(c) is not None for i, c in first.items()}
    keep = np.fromiter((keep_track[i] for i in tid), bool, len(tid))
    note = labels.note("tracks")
    if note:
        warnings.warn(f"rotated-boxes {path.name}: {note}", stacklevel=3)
    if not keep.any():
        raise FormatError(f"no road user among the tracks ({note})", path=path)
    return t if keep.all() else t.filter(pa.array(keep))


def _row_pmf(t: pa.Table, options: RotatedBoxOptions, path: Path) -> np.ndarray:
    cmap = {**DEFAULT_CLASS_MAP, **{k.lower(): v for k, v in options.class_map.items()},
            **{c: c for c in CLASSES}}
    for k, v in cmap.items():
        if v not in CLASSES:
            raise FormatError(f"class_map maps {k!r} to {v!r}, which is not one of {list(CLASSES)}")
    n = t.num_rows
    k = len(CLASSES)
    score_cols = [c for c in t.column_names if c.startswith("score_")]
    if score_cols:
        pm = np.zeros((n, k))
        for col in score_cols:
            label = col[len("score_"):].lower()
            if label not in cmap and label_kind(label)[1] == NOT_ROAD_USER:
                cmap[label] = label_kind(label)[0]  # its probability mass: class other
            if label not in cmap:
                raise FormatError(f"column {col!r}: class {label!r} unknown; map it with the "
                                  "class_map option", path=path)
            s = np.nan_to_num(column_numpy(t, col))
            if (s < 0).any():
                i = int(np.flatnonzero(s < 0)[0])
                raise FormatError(f"column {col!r}: negative score", path=path, line=i + 2)
            pm[:, CLASSES.index(cmap[label])] += s
        tot = pm.sum(axis=1, keepdims=True)
        return np.where(tot > 0, pm / np.where(tot > 0, tot, 1), 1.0 / k)
    if "class" in t.column_names:
        labels, uniq = factorize(t.column("class").cast(pa.string()).fill_null("").combine_chunks())
        idx = np.empty(len(uniq), np.int64)
        for j, lab in enumerate(uniq):
            key = str(lab).strip().lower()
            kind_cls, kind = label_kind(key)
            if key not in cmap and kind == NOT_ROAD_USER:  # kept (keep_non_road_users)
                cmap[key] = kind_cls
            if key not in cmap:
                line = int(np.flatnonzero(labels == j)[0]) + 2
                raise FormatError(f"column 'class': {lab!r} is not a known class; map it with the "
                                  "class_map option", path=path, line=line)
            idx[j] = CLASSES.index(cmap[key])
        score = np.clip(np.nan_to_num(column_numpy(t, "score"), nan=1.0), 0, 1) if "score" in \
            t.column_names else np.ones(n)
        pm = np.repeat(((1.0 - score) / (k - 1))[:, None], k, axis=1)
        pm[np.arange(n), idx[labels]] = score
        return pm
    raise FormatError("the table needs a 'class' column or 'score_<class>' columns", path=path)


def local_linear_velocity(pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray,
                          window: float, max_offset: int = 64
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Velocity of each sample by a least-squares line through the samples of the same participant
    within ``window / 2`` seconds (rows sorted by participant and time).

    Returns ``(vx, vy, g)``: ``g`` = 1 / sqrt(sum (t_j - mean t)^2), so that a position noise of
    sigma (independent per sample) gives a velocity std of ``sigma * g`` (NaN where a participant
    has a single sample in the window; its velocity is 0).
    """
    n = len(t)
    half = window / 2.0 + 1e-9
    s0 = np.ones(n)
    st = np.zeros(n)
    stt = np.zeros(n)
    sx = np.zeros(n)
    sy = np.zeros(n)
    stx = np.zeros(n)
    sty = np.zeros(n)
    for sign in (1, -1):
        for j in range(1, max_offset + 1):
            if j >= n:
                break
            if sign > 0:
                i, k = np.arange(n - j), np.arange(j, n)
            else:
                i, k = np.arange(j, n), np.arange(n - j)
            dt = t[k] - t[i]
            ok = (pid[k] == pid[i]) & (np.abs(dt) <= half)
            if not ok.any():
                break
            i, k, dt = i[ok], k[ok], dt[ok]
            dx, dy = x[k] - x[i], y[k] - y[i]
            s0[i] += 1
            st[i] += dt
            stt[i] += dt * dt
            sx[i] += dx
            sy[i] += dy
            stx[i] += dt * dx
            sty[i] += dt * dy
    den = s0 * stt - st * st
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = den > 1e-12
        vx = np.where(ok, (s0 * stx - st * sx) / den, 0.0)
        vy = np.where(ok, (s0 * sty - st * sy) / den, 0.0)
        g = np.where(ok, np.sqrt(s0 / den), np.nan)
    return vx, vy, g


def _is_rotated_boxes(path: Path, head: bytes) -> bool:
    """A track table of boxes in pixels (centre and angle, or four corners) or a GDAL .aux.xml."""
    if path.name.lower().endswith(".aux.xml"):
        return b"<PAMDataset" in head or b"<GeoTransform" in head
    names = header_names(path, head)
    return "track_id" in names and (set(_CENTRE) <= names or set(_CORNERS) <= names)


@converter("rotated-boxes", description="Rotated-box tracks in image pixels (aircraft/drone "
           "detection + tracking) with a world file or GDAL geotransform",
           patterns=("*.csv", "*.parquet", "*.tfw", "*.pgw", "*.jgw", "*.wld", "*.prj", "*.aux.xml"),
           method="aerial", options=RotatedBoxOptions, sniff=_is_rotated_boxes)
def convert_rotated_boxes(inputs: list[Path], *, map_source, options: RotatedBoxOptions):
    from aveas_format.opendrive import load_map

    A, c, crs, tables, geo = _georeference(inputs, options)
    if len(tables) != 1:
        raise FormatError(f"expected one track table, got {len(tables)}: "
                          f"{', '.join(p.name for p in tables)}")
    path = tables[0]
    tab, t = _read_tracks(path, options)
    map_bytes = load_map_bytes(map_source)
    header = load_map(map_bytes).header
    boxes = _boxes_in_map(tab, t, path, options, A, c, crs, header)
    gsd = math.sqrt(abs(np.linalg.det(A)))
    coverage = None
    if options.image_size is not None:
        wpx, hpx = options.image_size
        cu = np.array([0.0, wpx, wpx, 0.0, 0.0])
        cv = np.array([0.0, 0.0, hpx, hpx, 0.0])
        fx, fy = A[0, 0] * cu + A[0, 1] * cv + c[0], A[1, 0] * cu + A[1, 1] * cv + c[1]
        if header.geo_reference:
            fx, fy, _ = projected_to_local(fx, fy, crs, header.geo_reference, header.offset)
        coverage = Footprint("POLYGON ((" + ", ".join(f"{float(a)!r} {float(b)!r}" for a, b in zip(fx, fy))
                             + "))", "aerial_camera")
    rate = options.frame_rate
    sensor = Sensor(
        method="aerial", platform=options.platform or f"aerial camera, GSD {gsd:.3g} m",
        sensors=[{"id": "aerial_camera", "kind": "rgb_camera", **({"rate_hz": rate} if rate else {})}],
        not_observable=["light_", "interior"], coverage=coverage,
        crs=None if header.geo_reference else crs,
        sizes=Sizes(statistic="median", floor=gsd * options.pixel_std),
        extras={"georeference": {"crs": crs, "affine_corner": [*A.ravel().tolist(), *c.tolist()]}})
    return to_recording(boxes, sensor, converter="rotated-boxes", inputs=[path, *geo],
                        options=options, map_bytes=map_bytes,
                        participants={"attributes": [json.dumps({"boxes": int(k)})
                                                     for k in boxes.counts()]})


def _read_tracks(path: Path, options: RotatedBoxOptions) -> tuple[pa.Table, np.ndarray]:
    """The track table with its numeric columns as numbers, the tracks that are no road user
    left out, and each row's time (s)."""
    numeric = ("time", "frame", "track_id", *_CENTRE, *_CORNERS, "score", "cx_std", "cy_std",
               "cxcy_corr")
    probe = read_table(path)
    numeric = numeric + tuple(c_ for c_ in probe.column_names if c_.startswith("score_"))
    if "track_id" not in probe.column_names:
        raise FormatError(f"required column(s) ['track_id'] missing; found {probe.column_names}",
                          path=path)
    tab = read_table(path, numeric=[c_ for c_ in numeric if c_ != "track_id"])
    if tab.num_rows == 0:
        raise FormatError("no rows", path=path)
    tab = _road_users(tab, options, path)
    if "time" in tab.column_names:
        t = column_numpy(tab, "time")
    elif "frame" in tab.column_names:
        if not options.frame_rate:
            raise FormatError("the table has 'frame' but no 'time': pass the frame_rate option",
                              path=path)
        t = column_numpy(tab, "frame") / options.frame_rate
    else:
        raise FormatError("the table needs a 'time' (s) or 'frame' column", path=path)
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise FormatError("time/frame is empty or not a number", path=path, line=int(bad[0]) + 2)
    tid_col = tab.column("track_id")
    if tid_col.null_count:
        i = int(np.flatnonzero(tid_col.is_null().to_numpy(zero_copy_only=False))[0])
        raise FormatError("track_id is empty", path=path, line=i + 2)
    return tab, t


def _boxes_in_map(tab: pa.Table, t: np.ndarray, path: Path, options: RotatedBoxOptions, A: np.ndarray,
                  c: np.ndarray, crs: str, header) -> Boxes:
    """The boxes (sorted) in the map's frame: centres through the affine transform and into the
    map's CRS, the pixel covariance propagated (J = R(rot) A), the velocity by local linear
    regression, the heading the box axis that points along the motion."""
    from aveas_format.mapref.build import heading_from_velocity
    from aveas_format.numeric import wrap_angle

    # participants in order of first appearance
    pid, source_ids = factorize(tab.column("track_id").combine_chunks())
    X, Y, axis, length, width = _boxes(tab, options, A, c, path)
    pmf_rows = _row_pmf(tab, options, path)
    su, sv = (column_numpy(tab, c_, nonfinite=options.pixel_std, missing=options.pixel_std)
              for c_ in ("cx_std", "cy_std"))
    ruv = np.nan_to_num(column_numpy(tab, "cxcy_corr", missing=0.0))
    if header.geo_reference:
        x, y, rot = projected_to_local(X, Y, crs, header.geo_reference, header.offset)
    else:
        x, y, rot = X, Y, np.zeros(tab.num_rows)
    cr, sr = np.cos(rot), np.sin(rot)
    j00 = cr * A[0, 0] - sr * A[1, 0]
    j01 = cr * A[0, 1] - sr * A[1, 1]
    j10 = sr * A[0, 0] + cr * A[1, 0]
    j11 = sr * A[0, 1] + cr * A[1, 1]
    cuu, cvv, cuv = su * su, sv * sv, ruv * su * sv
    cxx = j00 * j00 * cuu + 2 * j00 * j01 * cuv + j01 * j01 * cvv
    cyy = j10 * j10 * cuu + 2 * j10 * j11 * cuv + j11 * j11 * cvv
    cxy = j00 * j10 * cuu + (j00 * j11 + j01 * j10) * cuv + j01 * j11 * cvv
    x_std, y_std = np.sqrt(cxx), np.sqrt(cyy)
    with np.errstate(divide="ignore", invalid="ignore"):
        xy_corr = np.clip(np.where(x_std * y_std > 0, cxy / (x_std * y_std), 0.0), -1, 1)
    boxes = Boxes(
        pid, t, x, y, source_ids=[str(s) for s in source_ids],
        rows=Rows([path], place=np.arange(tab.num_rows) + 2), heading=axis + rot,
        x_std=x_std, y_std=y_std, xy_corr=xy_corr.astype(np.float32),
        heading_std=np.full(tab.num_rows, math.radians(options.angle_std_deg)),
        length=length, width=width, class_pmf=pmf_rows,
        source_frame=(column_numpy(tab, "frame").astype(np.int64) if "frame" in tab.column_names
                      else None)).sort()
    vx, vy, g = local_linear_velocity(boxes.pid, boxes.time, boxes["x"], boxes["y"],
                                      options.velocity_window)
    axis = boxes["heading"]
    ref = heading_from_velocity(boxes.pid, vx, vy, options.heading_min_speed)
    boxes["heading"] = wrap_angle(np.where(np.cos(axis - ref) < 0, axis + np.pi, axis))
    nan = np.isnan(g)
    boxes["vx"], boxes["vy"] = vx, vy
    boxes["vx_std"], boxes["vy_std"] = boxes["x_std"] * g, boxes["y_std"] * g
    boxes["vxvy_corr"] = np.where(nan, np.nan, boxes["xy_corr"]).astype(np.float32)
    return boxes
