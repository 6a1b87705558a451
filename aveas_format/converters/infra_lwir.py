"""Infrastructure LWIR thermal camera: pixel tracks + surveyed landmarks -> recording.

Inputs:

- **Pixel tracks**: MOTChallenge text files (no header, ``frame,id,bb_left,bb_top,bb_width,
  bb_height,conf,...``; 9 columns are read as MOT16/17/20 ground truth ``...,conf,class,visibility``
  with the documented class ids: 1 pedestrian, 3 car, 4 bicycle, 5 motorbike (motorcycle), 6 non
  motorized vehicle (pushable_pullable) are road users; 2 person on vehicle (the rider of a
  labelled vehicle), 7 static person, 8 distractor, 9 occluder, 10 occluder on the ground, 11
  occluder full and 12 reflection are not, and are skipped with a count in a warning unless
  ``keep_non_road_users`` (then 2 and 7 are pedestrians, the rest other); 13 crowd (MOT20, a
  region) is never imported. ``conf`` (MOT's "consider in evaluation" flag) is not a filter: cars
  carry 0 there), or a CSV with a header: ``frame`` (or ``time`` in s), ``id``/``track_id``,
  ``bb_left``, ``bb_top``, ``bb_width``, ``bb_height`` (or ``left, top, width, height``),
  optional ``conf`` and ``class`` (a name; names that are no road user are skipped alike).
- **Landmarks** (a CSV recognised by its columns ``u, v, x, y``, or option ``landmarks``): pixel
  positions of surveyed ground points and their map coordinates (the OpenDRIVE local frame).

Ground reference: the plane homography pixel -> map is estimated from the landmarks (at least 4):
a normalised DLT, then Gauss-Newton on the 8 free entries (h33 = 1) minimising the landmarks' map
residuals, each weighted by ``1 / (landmark_map_std^2 + landmark_pixel_std^2 |dX/du|^2)``. Its
covariance is ``(J^T W J)^-1``, scaled up by the reduced chi-square where that exceeds 1.

Reference point: the ground contact point is the bottom centre of the box; as that is the near
edge of the participant, the point is moved away from the camera (along the ground direction of the
image's up axis) by half the footprint's extent in that direction (from the class's default
size and the heading), to the footprint centre (``ground_point="bottom_centre"`` keeps it).
Uncertainty: the box edges have ``pixel_std`` each (bottom centre: u std ``pixel_std / sqrt 2``, v
std ``pixel_std``); position covariance ``J_p C_px J_p^T + J_h C_h J_h^T`` with the homography's
Jacobians. Velocity by central differences (std from the position stds), heading from the direction
of motion (std ``|v_std| / speed``, held below 0.5 m/s). Thermal cameras measure no size: length,
width and height are the class's defaults with a 15 % std.

Unobserved regions: the ground footprint of the image (``image_size``, up to the row where the
ground lies ``range_m`` from the bottom centre's ground point) -> the map's extent outside it is
``field_of_view``, beyond ``range_m`` ``sensor_range``. Time = (frame - 1) / ``rate_hz``.
Provenance ``natural``, method ``infrastructure_lwir``.

Tested on: ``tests/data/third_party/mot17_09_gt_excerpt.txt`` (MOT17-09 ground truth: a
pedestrian, a reflection, a static person; tests/realdata/test_mot.py) and MOT files written here
from an analytic camera (tests/converters/test_infra_lwir.py). The landmarks are ours: MOT has no
ground reference.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Range, Rows, Sensor
from aveas_format.converters.common.geometry import covariance_std_corr
from aveas_format.converters.common.tables import (factorize, header_names, is_float, read_table,
                                                   reject_non_utf8)
from aveas_format.converters.labels import MOT_CLASS_IDS, LabelFilter, class_of
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes
from aveas_format.numeric import central_differences
from aveas_format.schema.taxonomy import CLASSES

CLS = {c: i for i, c in enumerate(CLASSES)}
#: default footprint (length, width, height) per class, m
CLASS_SIZE = {
    "animal": (1.0, 0.5, 0.8), "bicycle": (1.8, 0.6, 1.7), "bus": (12.0, 2.55, 3.2),
    "car": (4.5, 1.8, 1.5), "pedestrian": (0.5, 0.5, 1.75), "mobility_device": (1.0, 0.6, 1.5),
    "motorcycle": (2.2, 0.8, 1.4), "other": (4.0, 1.8, 1.5), "pushable_pullable": (1.0, 0.6, 1.0),
    "railvehicle": (30.0, 2.65, 3.5), "trailer": (8.0, 2.5, 3.0), "truck": (10.0, 2.5, 3.5),
    "van": (5.2, 2.0, 2.2),
}


class InfraLwirOptions(ImportOptions):
    landmarks: Path | None = None
    """Landmark CSV (u, v, x, y); default: the input with those columns."""
    rate_hz: float = 25.0
    """Frame rate of the camera (time = (frame - 1) / rate_hz)."""
    image_size: tuple[int, int] = (640, 512)
    """Image width and height in pixels (field of view)."""
    pixel_std: float = 1.0
    """1-sigma of each box edge (px)."""
    landmark_pixel_std: float = 0.5
    """1-sigma of the landmarks' pixel positions (px)."""
    landmark_map_std: float = 0.05
    """1-sigma of the landmarks' surveyed map positions (m)."""
    default_class: str = "car"
    """Class of tracks without a class."""
    class_map: dict[str, str] = {}
    """Source class name (or MOTChallenge class id) -> one of the 13 classes; a mapped label is a
    road user."""
    keep_non_road_users: bool = False
    """Import tracks whose class is no road user (MOTChallenge 2 person on vehicle, 7 static
    person, 8 distractor, 9-11 occluders, 12 reflection; see docs/converters.md "Labels that are
    not road users"); 13 crowd (a region) is never imported."""
    ground_point: Literal["footprint_centre", "bottom_centre"] = "footprint_centre"
    """Move the box's bottom centre to the footprint centre, or keep it."""
    range_m: float = 150.0
    """Farthest ground distance (from the image bottom centre's ground point) counted as observed."""
    sensor_id: str = "lwir"
    """Sensor id (acquisition.sensors, unobserved.sensor_id)."""


# --- homography ------------------------------------------------------------------------------------

def _apply(h: np.ndarray, u: np.ndarray, v: np.ndarray):
    w = h[2, 0] * u + h[2, 1] * v + h[2, 2]
    return (h[0, 0] * u + h[0, 1] * v + h[0, 2]) / w, (h[1, 0] * u + h[1, 1] * v + h[1, 2]) / w, w


def _jacobians(h: np.ndarray, u: np.ndarray, v: np.ndarray):
    """X, Y and their Jacobians w.r.t. (u, v) (n,2,2) and the 8 entries h11..h32 (n,2,8)."""
    X, Y, w = _apply(h, u, v)
    jp = np.empty((len(u), 2, 2))
    jp[:, 0, 0] = (h[0, 0] - X * h[2, 0]) / w
    jp[:, 0, 1] = (h[0, 1] - X * h[2, 1]) / w
    jp[:, 1, 0] = (h[1, 0] - Y * h[2, 0]) / w
    jp[:, 1, 1] = (h[1, 1] - Y * h[2, 1]) / w
    one = np.ones_like(u)
    p = np.stack([u, v, one], -1) / w[:, None]
    jh = np.zeros((len(u), 2, 8))
    jh[:, 0, 0:3] = p
    jh[:, 1, 3:6] = p
    jh[:, 0, 6:8] = -X[:, None] * p[:, :2]
    jh[:, 1, 6:8] = -Y[:, None] * p[:, :2]
    return X, Y, jp, jh


def _normaliser(pts: np.ndarray) -> np.ndarray:
    c = pts.mean(axis=0)
    d = np.sqrt(((pts - c) ** 2).sum(axis=1)).mean()
    s = np.sqrt(2) / d if d > 0 else 1.0
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def estimate_homography(uv: np.ndarray, xy: np.ndarray, pixel_std: float = 0.5,
                        map_std: float = 0.05, path: Path | None = None):
    """(H (3,3) with h33 = 1, covariance (8,8) of h11..h32, RMS residual in m) from >= 4
    landmark pairs pixel -> map (see the module doc)."""
    n = len(uv)
    if n < 4:
        raise FormatError(f"{n} landmarks; the ground homography needs at least 4", path=path)
    tu, tx = _normaliser(uv), _normaliser(xy)
    a = np.c_[uv, np.ones(n)] @ tu.T
    b = np.c_[xy, np.ones(n)] @ tx.T
    rows = np.zeros((2 * n, 9))
    rows[0::2, 0:3] = a
    rows[0::2, 6:9] = -b[:, 0:1] * a
    rows[1::2, 3:6] = a
    rows[1::2, 6:9] = -b[:, 1:2] * a
    _, sv, vt = np.linalg.svd(rows)
    if sv[-2] < 1e-9 * sv[0]:
        raise FormatError("the landmarks do not determine a homography (collinear or repeated "
                          "points)", path=path)
    hn = vt[-1].reshape(3, 3)
    h = np.linalg.inv(tx) @ hn @ tu
    if abs(h[2, 2]) < 1e-12:
        raise FormatError("degenerate homography (h33 = 0)", path=path)
    h = h / h[2, 2]
    u, v = uv[:, 0], uv[:, 1]
    for _ in range(10):  # Gauss-Newton, weighted
        X, Y, jp, jh = _jacobians(h, u, v)
        var = map_std ** 2 + pixel_std ** 2 * (jp ** 2).sum(axis=(1, 2)) / 2
        wgt = np.repeat(1.0 / var, 2)
        r = np.c_[xy[:, 0] - X, xy[:, 1] - Y].ravel()
        j = jh.reshape(2 * n, 8)
        jtw = j.T * wgt
        try:
            step = np.linalg.solve(jtw @ j, jtw @ r)
        except np.linalg.LinAlgError:
            raise FormatError("the landmarks do not determine a homography", path=path) from None
        h = h + np.r_[step, 0.0].reshape(3, 3)
        if np.abs(step).max() < 1e-12 * (1 + np.abs(h).max()):
            break
    X, Y, jp, jh = _jacobians(h, u, v)
    var = map_std ** 2 + pixel_std ** 2 * (jp ** 2).sum(axis=(1, 2)) / 2
    wgt = np.repeat(1.0 / var, 2)
    r = np.c_[xy[:, 0] - X, xy[:, 1] - Y].ravel()
    j = jh.reshape(2 * n, 8)
    cov = np.linalg.inv((j.T * wgt) @ j)
    dof = 2 * n - 8
    if dof > 0:
        chi2 = float((r ** 2 * wgt).sum() / dof)
        cov = cov * max(1.0, chi2)
    if np.any(_apply(h, u, v)[2] <= 0) and np.any(_apply(h, u, v)[2] >= 0):
        raise FormatError("landmarks lie on both sides of the horizon", path=path)
    return h, cov, float(np.sqrt((r ** 2).mean()))


# --- readers ---------------------------------------------------------------------------------------

def _is_landmarks(path: Path) -> bool:
    if path.suffix.lower() not in (".csv", ".txt", ".parquet"):
        return False
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        names = set(pq.read_schema(path).names)
    else:
        with open(path, encoding="utf-8", errors="replace") as f:
            head = f.readline()
        names = {c.strip().lower() for c in head.replace(";", ",").replace("\t", ",").split(",")}
    return {"u", "v", "x", "y"} <= names


def _read_landmarks(path: Path):
    t = read_table(path, required=("u", "v", "x", "y"), numeric=("u", "v", "x", "y"))
    uv = np.c_[column_numpy(t, "u"), column_numpy(t, "v")]
    xy = np.c_[column_numpy(t, "x"), column_numpy(t, "y")]
    bad = ~np.isfinite(np.c_[uv, xy]).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FormatError("landmark with a missing value", path=path, line=i + 2)
    return uv, xy


def _read_mot(path: Path) -> pa.Table:
    """A MOTChallenge text file (no header) as a table with named columns."""
    with open(path, "rb") as f:
        head = f.read(4096)
    if len(head) < 4096 and not head.strip():
        raise FormatError("no rows: the MOT file is empty", path=path)
    try:
        raw = pacsv.read_csv(path, read_options=pacsv.ReadOptions(autogenerate_column_names=True),
                             convert_options=pacsv.ConvertOptions(strings_can_be_null=True))
    except pa.ArrowInvalid as e:
        import re

        m = re.search(r"[Rr]ow #(\d+)", str(e))
        raise FormatError(f"malformed MOT file: {str(e).splitlines()[0]}", path=path,
                          line=int(m.group(1)) if m else None) from None
    reject_non_utf8(raw, path, header_lines=0)
    k = raw.num_columns
    if k < 6:
        raise FormatError(f"a MOT line needs at least 6 fields (frame,id,bb_left,bb_top,bb_width,"
                          f"bb_height), found {k}", path=path, line=1)
    names = ["frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf"]
    names += (["class", "visibility"] if k == 9 else ["wx", "wy", "wz"])
    names = names[:k] + [f"c{i}" for i in range(len(names), k)]
    raw = raw.rename_columns(names)
    for c in names[:6]:
        col = raw.column(c)
        if not (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)):
            vals = col.cast(pa.string()).to_pylist()
            bad = next((i for i, v in enumerate(vals) if v is None or not is_float(v)), 0)
            raise FormatError(f"field {names.index(c) + 1} ({c}): {vals[bad]!r} is not a number",
                              path=path, line=bad + 1)
        if col.null_count:
            bad = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
            raise FormatError(f"field {names.index(c) + 1} ({c}) is empty", path=path, line=bad + 1)
    return raw


def _read_tracks(path: Path, opts: InfraLwirOptions):
    """(time, track ids, class names, u_bottom_centre, v_bottom, source line of each row) of one
    file."""
    with open(path, encoding="utf-8", errors="replace") as f:
        head = f.readline()
    has_header = any(c.isalpha() for c in head.split(",")[0])
    if path.suffix.lower() == ".parquet" or has_header:
        t0 = read_table(path)
        names = set(t0.column_names)

        def pick(*cands):
            for c in cands:
                if c in names:
                    return c
            raise FormatError(f"tracks CSV needs a column {' or '.join(map(repr, cands))}; found "
                              f"{t0.column_names}", path=path)

        tc = pick("frame", "time")
        idc = pick("id", "track_id")
        lc, tpc = pick("bb_left", "left"), pick("bb_top", "top")
        wc, hc = pick("bb_width", "width", "w"), pick("bb_height", "height", "h")
        t = read_table(path, numeric=(tc, lc, tpc, wc, hc))
        cls = (t.column("class").cast(pa.string()).to_pylist() if "class" in names
               else [opts.default_class] * t.num_rows)
        frame_based = tc == "frame"
        header = 1
    else:
        t = _read_mot(path)
        tc, idc, lc, tpc, wc, hc = "frame", "id", "bb_left", "bb_top", "bb_width", "bb_height"
        if "class" in t.column_names:
            cls = [MOT_CLASS_IDS.get(int(c), f"class {int(c)}") if c is not None else opts.default_class
                   for c in t.column("class").to_pylist()]
        else:
            cls = [opts.default_class] * t.num_rows
        frame_based = True
        header = 0
    tv = column_numpy(t, tc)
    left, top, w, h = column_numpy(t, lc), column_numpy(t, tpc), column_numpy(t, wc), column_numpy(t, hc)
    for c, arr in ((tc, tv), (lc, left), (tpc, top), (wc, w), (hc, h)):
        bad = ~np.isfinite(arr) | ((arr <= 0) if c in (wc, hc) else False)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            what = "must be positive" if np.isfinite(arr[i]) else "is missing"
            raise FormatError(f"column {c!r}: value {what}", path=path, line=i + 1 + header)
    time = (tv - 1.0) / opts.rate_hz if frame_based else tv
    ids = t.column(idc).cast(pa.string()).to_pylist()
    return time, ids, cls, left + w / 2.0, top + h, np.arange(len(tv)) + 1 + header


def _road_users(ids: list, cls_names: list, o: InfraLwirOptions) -> tuple[np.ndarray, str | None]:
    """Per row: whether its track is imported (one label per track, its first row's); and the
    note of what was skipped (MOTChallenge labels distractors, occluders, reflections, static
    persons and crowds too)."""
    labels = LabelFilter(o.keep_non_road_users, o.class_map)
    first: dict[str, str] = {}
    for i, c in zip(ids, cls_names):
        first.setdefault(i, c)
    keep_track = {i: labels(c) is not None for i, c in first.items()}
    return np.fromiter((keep_track[i] for i in ids), bool, len(ids)), labels.note("tracks")


# --- the converter ---------------------------------------------------------------------------------

def _is_lwir_input(path: Path, head: bytes) -> bool:
    """A MOTChallenge text file (no header: at least 6 numbers a line), a tracks CSV of pixel
    boxes, or a landmark table (u, v, x, y)."""
    names = header_names(path, head)
    if {"u", "v", "x", "y"} <= names or (names & {"bb_left", "left"} and names & {"bb_top", "top"}):
        return True
    fields = head.split(b"\n", 1)[0].strip().split(b",")
    return len(fields) >= 6 and all(is_float(v.decode("ascii", "replace")) for v in fields[:6])


@converter("infra-lwir", description="Infrastructure LWIR thermal camera: MOT-style pixel tracks + "
           "landmark table -> ground-plane homography", patterns=("*.txt", "*.csv"),
           method="infrastructure_lwir", options=InfraLwirOptions, sniff=_is_lwir_input)
def convert_infra_lwir(inputs: list[Path], *, map_source, options: InfraLwirOptions):
    o = options
    if o.class_map:  # MOTChallenge class ids as keys: their documented names
        o = o.model_copy(update={"class_map": {
            MOT_CLASS_IDS.get(int(k), k) if str(k).strip().isdigit() else k: v
            for k, v in o.class_map.items()}})
    if o.default_class not in CLASSES:
        raise FormatError(f"default_class {o.default_class!r} is not one of {list(CLASSES)}")
    lm_path, track_paths = _split_inputs(inputs, o)
    uv_l, xy_l = _read_landmarks(lm_path)
    H, cov_h, rms = estimate_homography(uv_l, xy_l, o.landmark_pixel_std, o.landmark_map_std, lm_path)
    w_side = _apply(H, np.array([o.image_size[0] / 2.0]), np.array([float(o.image_size[1])]))[2][0]
    boxes, classes = _ground_boxes(track_paths, H, cov_h, w_side, o)
    size = np.asarray([CLASS_SIZE[c] for c in classes])
    m = len(classes)
    pmf = np.zeros((m, len(CLASSES)), np.float32)
    pmf[np.arange(m), [CLS[c] for c in classes]] = 1.0
    participants = {
        "class": classes, "class_pmf": pmf,
        "length": size[:, 0], "width": size[:, 1], "height": size[:, 2],
        "length_std": 0.15 * size[:, 0], "width_std": 0.15 * size[:, 1],
        "height_std": 0.15 * size[:, 2],
        "attributes": [json.dumps({"size": "class default"})] * m,
    }
    observed, bottom = _ground_footprint(H, w_side, o)
    sensor = Sensor(
        method="infrastructure_lwir", platform="infrastructure LWIR thermal camera",
        sensors=[{"id": o.sensor_id, "kind": "lwir_camera", "rate_hz": o.rate_hz,
                  "description": f"{o.image_size[0]}x{o.image_size[1]} px; ground homography from "
                                 f"{len(uv_l)} landmarks, RMS residual {rms:.3f} m"}],
        not_observable=["light_", "interior", "z"],
        coverage=Range(o.sensor_id, o.range_m, 1.0 / o.rate_hz, pose=(*bottom, 0.0, 0.0),
                       observed=observed),
        extras={"ground_homography": H.ravel().tolist(),
                "ground_homography_cov_diag": np.diag(cov_h).tolist()})
    return to_recording(boxes, sensor, converter="infra-lwir",
                        inputs=inputs + ([lm_path] if lm_path not in inputs else []),
                        options=options, map_bytes=load_map_bytes(map_source),
                        participants=participants)


def _split_inputs(inputs: list[Path], o: InfraLwirOptions) -> tuple[Path, list[Path]]:
    """The landmark table (option ``landmarks``, or the input with columns u, v, x, y) and the
    pixel track files."""
    lm_path = o.landmarks
    track_paths = []
    for p in inputs:
        if lm_path is None and _is_landmarks(p):
            lm_path = p
        elif p != lm_path:
            track_paths.append(p)
    if lm_path is None:
        raise FormatError("no landmark table (a CSV with columns u, v, x, y) among the inputs and "
                          "no option landmarks", path=inputs[0])
    if not Path(lm_path).is_file():
        raise RecordingIOError("landmark table not found", path=lm_path)
    if not track_paths:
        raise FormatError("no pixel track file among the inputs", path=inputs[0])
    return Path(lm_path), track_paths


def _ground_boxes(track_paths: list[Path], H: np.ndarray, cov_h: np.ndarray, w_side: float,
                  o: InfraLwirOptions) -> tuple[Boxes, list[str]]:
    """The boxes (sorted) on the ground and each participant's class: the bottom centre of each
    pixel box through the homography (its covariance from the box edges' and the homography's),
    moved to the footprint centre (``ground_point``), velocities by central differences, the
    heading from the motion."""
    from aveas_format.mapref.build import heading_from_velocity

    parts = [_read_tracks(p, o) for p in track_paths]
    time = np.concatenate([p[0] for p in parts])
    ids = sum((p[1] for p in parts), [])
    cls_names = sum((p[2] for p in parts), [])
    u = np.concatenate([p[3] for p in parts])
    v = np.concatenate([p[4] for p in parts])
    lines = np.concatenate([p[5] for p in parts])
    files = np.concatenate([np.full(len(p[0]), k) for k, p in enumerate(parts)])
    on_ground = np.sign(_apply(H, u, v)[2]) == np.sign(w_side)
    if not on_ground.all():
        i = int(np.flatnonzero(~on_ground)[0])
        raise FormatError(f"box of track {ids[i]!r} at time {time[i]:.3f} s has its bottom above the "
                          "horizon of the ground homography", path=track_paths[int(files[i])],
                          line=int(lines[i]))
    keep, note = _road_users(ids, cls_names, o)
    if note:
        import warnings

        warnings.warn(f"infra-lwir: {note}", stacklevel=3)
    if not keep.all():
        if not keep.any():
            raise FormatError(f"no road user among the tracks ({note})", path=track_paths[0])
        idx = np.flatnonzero(keep)
        time, u, v, lines, files = time[idx], u[idx], v[idx], lines[idx], files[idx]
        ids = [ids[i] for i in idx]
        cls_names = [cls_names[i] for i in idx]
    pid, uniq = factorize(ids)
    X, Y, jp, jh = _jacobians(H, u, v)
    cpx = np.diag([o.pixel_std ** 2 / 2.0, o.pixel_std ** 2])
    sx, sy, rho = covariance_std_corr(np.einsum("nij,jk,nlk->nil", jp, cpx, jp)
                                      + np.einsum("nij,jk,nlk->nil", jh, cov_h, jh))
    # (the policy: a track with two boxes in one frame is an error)
    boxes = Boxes(pid, time, X, Y, source_ids=[str(s) for s in uniq],
                  rows=Rows(track_paths, file=files, place=lines), x_std=sx, y_std=sy,
                  xy_corr=rho).sort()
    u, v = u[boxes.order], v[boxes.order]
    classes = [class_of(c, o.class_map)
               for c in np.asarray(cls_names, dtype=object)[boxes.order][boxes.first_rows()]]
    pid, t, X, Y = boxes.pid, boxes.time, boxes["x"], boxes["y"]

    def kinematics(x, y):
        vx, vy, vxs, vys = central_differences(pid, t, x, y, boxes["x_std"], boxes["y_std"])
        return vx, vy, vxs, vys, heading_from_velocity(pid, vx, vy)

    vx, vy, vxs, vys, hd = kinematics(X, Y)
    if o.ground_point == "footprint_centre":
        # away from the camera: the ground direction of the image's up axis at the contact point
        X2, Y2, _ = _apply(H, u, v - 1.0)
        a = np.c_[X2 - X, Y2 - Y]
        a /= np.linalg.norm(a, axis=1, keepdims=True)
        phi = np.arctan2(a[:, 1], a[:, 0])
        size = np.asarray([CLASS_SIZE[c] for c in classes])
        L, W = size[pid, 0], size[pid, 1]
        ext = L / 2 * np.abs(np.cos(hd - phi)) + W / 2 * np.abs(np.sin(hd - phi))
        boxes["x"], boxes["y"] = X + ext * a[:, 0], Y + ext * a[:, 1]
        vx, vy, vxs, vys, hd = kinematics(boxes["x"], boxes["y"])
    speed = np.hypot(vx, vy)
    with np.errstate(divide="ignore", invalid="ignore"):
        hstd = np.minimum(np.where(speed >= 0.5, np.hypot(vxs, vys) / speed, np.nan), np.pi)
    boxes["heading"], boxes["heading_std"] = hd, hstd
    boxes["vx"], boxes["vy"], boxes["vx_std"], boxes["vy_std"] = vx, vy, vxs, vys
    if t.min() < 0:
        boxes.time = t - t.min()
    return boxes, classes


def _ground_footprint(H: np.ndarray, w_side: float, o: InfraLwirOptions):
    """The image's ground footprint (a shapely polygon) up to the row where the ground lies
    ``range_m`` from the image bottom centre's ground point, and that point."""
    import shapely

    iw, ih = o.image_size
    bx, by, _ = _apply(H, np.array([iw / 2.0]), np.array([float(ih)]))
    vs = np.linspace(ih, 0.0, 4 * ih + 1)
    cols = np.array([0.0, iw / 2.0, float(iw)])
    uu, vv = np.meshgrid(cols, vs)
    gx, gy, gw = _apply(H, uu.ravel(), vv.ravel())
    ok = (np.sign(gw) == np.sign(w_side)).reshape(uu.shape)
    dist = np.hypot(gx - bx[0], gy - by[0]).reshape(uu.shape)
    good = (ok & (dist <= o.range_m)).all(axis=1)
    top_row = vs[np.flatnonzero(~good)[0] - 1] if (~good).any() else 0.0
    border_u = np.r_[np.linspace(0, iw, 50), np.full(50, iw), np.linspace(iw, 0, 50), np.zeros(50)]
    border_v = np.r_[np.full(50, ih), np.linspace(ih, top_row, 50), np.full(50, top_row),
                     np.linspace(top_row, ih, 50)]
    fx, fy, _ = _apply(H, border_u, border_v)
    return shapely.make_valid(shapely.Polygon(np.c_[fx, fy])), (float(bx[0]), float(by[0]))
