"""The shared step: box batches and a sensor description -> a recording.

A converter reads and maps its source into :class:`~aveas_format.converters.common.boxes.Boxes`
(and describes it with a :class:`~aveas_format.converters.common.boxes.Sensor`); :func:`to_recording`
does the rest, the same way for every source:

1. the rows sorted by (participant, time), the duplicates policy applied (``Boxes.sort``);
2. velocities by central differences where the source has none
   (:func:`aveas_format.numeric.central_differences`, their std propagated from the positions'
   where the boxes have ``x_std``/``y_std``);
3. per participant: the class PMF as the mean of the boxes' PMFs (normalised; the class its most
   probable), the sizes as their mean or median with their spread as std (:class:`Sizes`), where
   the converter did not state them per participant;
4. NaN in an optional column (an unknown value or uncertainty) written as null;
5. the coverage and the ``unobserved`` regions of the sensor (:class:`Footprint`, :class:`Range`);
6. recording.json: acquisition, provenance, the ``source`` block (converter, inputs with their
   SHA-256, options and what the converter resolved), the common import options (partner, start
   time, licence, owner, id, title, CRS) over the source's own values;
7. the map-referencing hand-off (:func:`aveas_format.mapref.build.build_recording`: lon/lat
   through the CRS, road coordinates through the map, the heading from the motion where the
   source has none).

A time-major source read in bounded memory holds its samples in a
:class:`~aveas_format.io.resort.StatesWriter` (:func:`bounded_states`); :func:`write_by_buckets`
does steps 1, 2, 4 and 7 a bucket of whole participants at a time and writes the states as it
goes (no coverage; the participants stated before, or made by the buckets in order).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.boxes import MEASURED, Boxes, Footprint, Range, Sensor, Sizes
from aveas_format.converters.common.provenance import source_block
from aveas_format.errors import FormatError
from aveas_format.io.resort import IMPORT_MEMORY, StatesWriter
from aveas_format.mapref.build import build_recording
from aveas_format.numeric import central_differences
from aveas_format.schema.taxonomy import CLASSES

#: states columns that are never null (FORMAT.md): NaN there stays an error for the validator
_NOT_NULL = ("participant_id", "time", "x", "y", "heading", "vx", "vy")


def to_recording(boxes: Boxes, sensor: Sensor, *, converter: str, inputs: Sequence[Path],
                 options: Any, map_bytes: bytes, participants: Mapping[str, Any] | None = None,
                 events: Mapping[str, Any] | None = None, interior: Mapping[str, Any] | None = None,
                 resolved: Mapping[str, Any] | None = None, version: str = "1"):
    """The recording of ``boxes`` acquired as ``sensor`` describes (the steps of the module doc).

    ``participants``: what the converter states per participant (columns of the participants
    table, one value per participant code 0..m-1: class, sizes, role, attributes...; its own
    ``participant_id`` where the source numbers them); the rest is aggregated from the boxes.
    ``events``/``interior``: tables the source has (their ``participant_id`` are the codes, or the
    given ids). ``converter``, ``inputs``, ``options``, ``resolved``, ``version``: the ``source``
    block (``options`` also carries the common import options)."""
    boxes = boxes.sort()
    parts = participant_columns(boxes, sensor.sizes, participants)
    ids = np.asarray(parts["participant_id"], np.int64)
    states = states_columns(boxes, ids)
    meta: dict[str, Any] = {}
    if sensor.coverage is not None:
        unobserved, coverage, duration = coverage_regions_of(sensor.coverage, boxes, ids, map_bytes)
        meta.update(unobserved=unobserved, coverage=coverage)
        if duration is not None:
            meta["duration_s"] = duration
    if sensor.duration_s is not None:
        meta["duration_s"] = sensor.duration_s
    if sensor.nominal_rate_hz is not None:
        meta["nominal_rate_hz"] = sensor.nominal_rate_hz
    if sensor.crs:
        meta["crs"] = sensor.crs
    if sensor.extras is not None:
        meta["extras"] = dict(sensor.extras)
    return hand_over(converter, inputs, options, map_bytes=map_bytes, participants=parts,
                     states=states, events=events, interior=interior, sensor=sensor,
                     resolved=resolved, version=version, **meta)


def states_columns(boxes: Boxes, ids: np.ndarray) -> dict[str, Any]:
    """The states columns of sorted boxes (steps 2 and 4 of the module doc; ``ids``: the
    participant id of each code)."""
    states: dict[str, Any] = {"participant_id": ids[boxes.pid], "time": boxes.time}
    cols = dict(boxes.columns)
    if "vx" not in cols and "vy" not in cols:
        has_std = "x_std" in cols and "y_std" in cols and "vx_std" not in cols
        vx, vy, vxs, vys = central_differences(boxes.pid, boxes.time, cols["x"], cols["y"],
                                               cols.get("x_std"), cols.get("y_std"), std=has_std)
        cols["vx"], cols["vy"] = vx, vy
        if has_std:
            cols["vx_std"], cols["vy_std"] = vxs, vys
    for k, v in cols.items():
        if k not in MEASURED:
            states[k] = v if k in _NOT_NULL else nullable(v)
    return states


@contextmanager
def bounded_states(output: Path, overwrite: bool, *, key: str, memory: int | None = None
                   ) -> Iterator[StatesWriter]:
    """A :class:`~aveas_format.io.resort.StatesWriter` for an import written to ``output`` in
    bounded memory (:func:`write_by_buckets`): rows beyond ``memory`` bytes (default
    :data:`~aveas_format.io.resort.IMPORT_MEMORY`) spilled to a hidden temporary directory next to the
    output (the states file is moved in, not copied), removed afterwards."""
    import shutil
    import tempfile

    from aveas_format.io.writer import check_target

    work = Path(tempfile.mkdtemp(prefix=".aveas-import.", dir=check_target(Path(output), overwrite)))
    try:
        with StatesWriter(work, memory=memory or IMPORT_MEMORY, key=key) as w:
            yield w
    finally:
        shutil.rmtree(work, ignore_errors=True)


def write_by_buckets(writer: StatesWriter, boxes_of: Callable[[pa.Table], Any], sensor: Sensor,
                     source_ids: Sequence[Any] | None, *, output: Path, overwrite: bool, converter: str,
                     inputs: Sequence[Path], options: Any, map_bytes: bytes,
                     participants: Mapping[str, Any] | Callable[[list], tuple[Sequence[Any], Mapping[str, Any]]],
                     resolved: Mapping[str, Any] | None = None, version: str = "1",
                     workers: int | None = 1, key_map: np.ndarray | None = None, net: Any = None):
    """:func:`to_recording` of the boxes a :class:`~aveas_format.io.resort.StatesWriter` holds
    (a time-major source read in bounded memory, :func:`bounded_states`), written to ``output``:
    ``boxes_of(bucket)`` makes the :class:`Boxes` of a bucket of whole participants (codes among
    all of ``source_ids``), whose states are made as :func:`to_recording` makes them, referenced to
    the map and written to ``states.parquet`` a bucket at a time (spilled buckets in ``workers``
    processes). What needs all boxes at once is not done here: ``participants`` states each
    participant's class and size, and the sensor has no coverage; the duplicates policy
    ``first`` warns once per bucket that has repeats. ``(recording as written, its states, those
    on the map)``; the recording's states are not loaded.

    Participants decided bucket by bucket (a source that drops whole participants, or aggregates
    them, as it makes their boxes): ``participants`` a callable and ``source_ids`` None;
    ``boxes_of(bucket)`` then gives ``(boxes, info)`` with the boxes' codes the final participant
    ids (the buckets are made in order, one at a time: ``workers`` 1), and
    ``participants([info of each bucket])`` gives ``(source_ids, participants)`` after the last.
    ``key_map``: the buckets' order (:meth:`~aveas_format.io.resort.StatesWriter.buckets`); ``net``:
    the map parsed from ``map_bytes`` where the converter has it."""
    import pyarrow.parquet as pq

    from aveas_format.crs import LocalFrame
    from aveas_format.io.writer import write_recording
    from aveas_format.mapref.build import check_crs, states_table
    from aveas_format.opendrive import load_map
    from aveas_format.parallel import processes

    later = callable(participants)
    if later and (source_ids is not None or processes(workers) > 1):
        raise ValueError("write_by_buckets: participants from the buckets need source_ids None and "
                         "one worker (the buckets made in order)")
    if sensor.coverage is not None or not later and not {"class", "length", "width"} <= set(participants):
        raise ValueError("write_by_buckets: the sensor has a coverage, or the participants' class "
                         "and sizes are not stated (both need every box: use to_recording)")
    if not later:
        parts = participant_columns(Boxes([], [], [], [], source_ids=source_ids), sensor.sizes, participants)
        ids = np.asarray(parts["participant_id"], np.int64)
    meta = {k: v for k, v in (("nominal_rate_hz", sensor.nominal_rate_hz), ("crs", sensor.crs or None),
                              ("extras", None if sensor.extras is None else dict(sensor.extras)),
                              ("duration_s", sensor.duration_s)) if v is not None}
    net = net or load_map(map_bytes)  # (the CRS as build_recording decides it: the states are referenced here)
    crs, check = _given_crs(options, meta.get("crs"))
    frame = LocalFrame(check_crs(crs, net.header.geo_reference) if check or not crs else crs,
                       offset=net.header.offset)

    def bucket(t: pa.Table) -> tuple[pa.Table, Any]:
        boxes, info = boxes_of(t) if later else (boxes_of(t), None)
        boxes = boxes.sort()
        b_ids = np.arange(int(boxes.pid.max(initial=-1)) + 1) if later else ids
        return states_table(states_columns(boxes, b_ids), frame, net), info

    states_file, summary, infos = writer.write(Path(writer.spill_dir) / "states.parquet",
                                               transform=bucket, workers=workers, key_map=key_map)
    if later:
        src, given = participants(infos)
        if not {"class", "length", "width"} <= set(given):
            raise ValueError("write_by_buckets: the participants' class and sizes are not stated")
        parts = participant_columns(Boxes([], [], [], [], source_ids=src), sensor.sizes, given)
    if summary["rows"]:
        meta = {**{k: summary[k] for k in ("duration_s", "nominal_rate_hz", "location")}, **meta}
    rec = hand_over(converter, inputs, options, map_bytes=map_bytes, participants=parts, sensor=sensor,
                    states=pq.read_schema(states_file.path).empty_table(), resolved=resolved, version=version,
                    **meta)
    write_recording(rec, output, overwrite=overwrite, states_file=states_file)
    return rec, states_file.rows, summary["on_road"]


def participant_columns(boxes: Boxes, sizes: Sizes, given: Mapping[str, Any] | None
                        ) -> dict[str, Any]:
    """The participants table's columns: ``participant_id`` (the codes, unless given),
    ``source_id``, what ``given`` states, and from the boxes' measurements what it does not: the
    class PMF and class, length/width/height with their std (:class:`Sizes`). A participant whose
    length or width is known from no box is an error naming it and its file."""
    m = boxes.m
    out: dict[str, Any] = {"participant_id": np.arange(m, dtype=np.int64),
                           "source_id": [str(s) for s in boxes.source_ids]}
    out.update(given or {})
    pid = boxes.pid
    if "class_pmf" in boxes and "class_pmf" not in out:
        pmf = group_mean(pid, np.asarray(boxes["class_pmf"], np.float64), m)
        pmf = (pmf / pmf.sum(axis=1, keepdims=True)).astype(np.float32)
        out["class_pmf"] = pmf
        if "class" not in out:
            out["class"] = np.asarray(CLASSES, dtype=object)[np.argmax(pmf, axis=1)]
    for dim in ("length", "width", "height"):
        if dim not in boxes or dim in out:
            continue
        v = np.asarray(boxes[dim], np.float64)
        centre = group_median(pid, v, m) if sizes.statistic == "median" else group_mean(pid, v, m)
        spread = group_std(pid, v, m)
        if sizes.floor is not None:
            spread = np.fmax(np.nan_to_num(spread, nan=0.0), sizes.floor)
        known = np.isfinite(centre) & (centre > 0)
        if dim != "height" and not known.all():
            k = int(np.flatnonzero(~known)[0])
            rows = np.flatnonzero(pid == k)
            where = {"path": boxes.rows.path(int(rows[0]))} if boxes.rows is not None and len(rows) else {}
            raise FormatError(f"participant {str(boxes.source_ids[k])!r} has no positive {dim} in "
                              "any of its boxes", **where)
        out[dim] = nullable(np.where(known, centre, np.nan))
        if f"{dim}_std" not in out:
            out[f"{dim}_std"] = nullable(np.where(known, spread, np.nan))
    for k in ("height", "length_std", "width_std", "height_std"):
        if k in out and not isinstance(out[k], (pa.Array, pa.ChunkedArray)):
            out[k] = nullable(np.asarray(out[k], np.float64))
    return out


def hand_over(converter: str, inputs: Sequence[Path], options: Any, *, map_bytes: bytes,
              participants: Mapping[str, Any], states: Mapping[str, Any], sensor: Sensor,
              resolved: Mapping[str, Any] | None = None, version: str = "1", **meta: Any):
    """The last step of :func:`to_recording`: recording.json's values (the sensor's, the common
    import options over them, the ``source`` block) and the map-referencing hand-off
    (:func:`~aveas_format.mapref.build.build_recording`) of the assembled tables."""
    o = options
    partner = getattr(o, "partner", None) or sensor.partner
    md: dict[str, Any] = {
        "start_time": getattr(o, "start_time", None) or sensor.start_time,
        "rights": {"right_of_use": _given(o, "right_of_use") or sensor.right_of_use
                   or getattr(o, "right_of_use", "research_only"),
                   "license": _given(o, "license") or sensor.license
                   or getattr(o, "license", "unspecified"),
                   "owner": getattr(o, "owner", None) or sensor.owner or partner},
        "method": sensor.method, "provenance": sensor.provenance,
        "acquisition": sensor.acquisition(),
    }
    if getattr(o, "recording_id", None):
        md["recording_id"] = o.recording_id
    title = getattr(o, "title", None) or sensor.title
    if title:
        md["title"] = title
    md.update({k: v for k, v in meta.items() if v is not None})
    crs, check = _given_crs(o, md.get("crs"))
    if check:
        md["crs"], md["check_map_crs"] = crs, True
    return build_recording(map_source=map_bytes, participants=participants, states=states,
                           partner=partner, source=source_block(converter, inputs, options, version,
                                                                dict(resolved or {})), **md)


def _given_crs(options: Any, crs: str | None) -> tuple[str | None, bool]:
    """The recording's CRS before the map is consulted: the user's option (which must agree with
    the map's geoReference: ``True``) wins over ``crs``, the one the source implies (both name the
    map's frame)."""
    if getattr(options, "crs", None) and getattr(options, "crs_is_recording_crs", True):
        return options.crs, True
    return crs, False


def _given(options: Any, name: str) -> Any:
    """An import option's value where the user gave it (not its default), else None."""
    if name in getattr(options, "model_fields_set", ()) and getattr(options, name) not in (None, ""):
        return getattr(options, name)
    return None


# --- coverage -------------------------------------------------------------------------------------

def coverage_regions_of(cov: Footprint | Range, boxes: Boxes, ids: np.ndarray, map_bytes: bytes
                        ) -> tuple[dict[str, Any] | None, str | None, float | None]:
    """``(unobserved table, coverage WKT, duration)`` of a sensor over sorted boxes (see
    :class:`Footprint`, :class:`Range`; duration None: the last sample's time)."""
    from aveas_format.converters.common import coverage as cv

    if isinstance(cov, Footprint):
        t_end = float(np.max(boxes.time)) if len(boxes) else 0.0
        return cv.outside_coverage(map_bytes, cov.wkt, 0.0, t_end, cov.sensor_id), cov.wkt, None
    import shapely

    time = boxes.time
    frame_times = np.unique(time)
    nxt = np.r_[frame_times[1:], frame_times[-1] + cov.period]
    duration = float(nxt[-1])
    area = cv.map_area(map_bytes)
    if "sensor_pose" in boxes:
        pose = np.asarray(boxes["sensor_pose"], np.float64)
    else:
        pose = np.tile(np.asarray(cov.pose, np.float64), (len(boxes), 1))
    moving = is_moving(pose)
    fi = np.searchsorted(frame_times, time)
    at = np.unique(fi, return_index=True)[1] if moving else np.array([0])
    rows: list[dict[str, Any]] = []
    views = []
    for i in at:
        t_start = float(frame_times[fi[i]]) if moving else 0.0
        t_end = float(nxt[fi[i]]) if moving else duration
        sxy = (float(pose[i, 0]), float(pose[i, 1]))
        yaw = float(pose[i, 3])
        rows += cv.coverage_regions(cov.sensor_id, sxy, cov.range_m, yaw, cov.fov, area, t_start,
                                    t_end, observed=cov.observed)
        view = cv.sector_polygon(*sxy, cov.range_m, yaw, cov.fov)
        if cov.observed is not None:
            view = shapely.intersection(view, cov.observed)
        views.append(shapely.intersection(view, area))
    view = shapely.union_all(views)
    coverage = shapely.to_wkt(view, rounding_precision=3) if not view.is_empty else None
    if cov.occlusion:
        rows += _shadows(cov, boxes, ids, pose, fi, nxt, moving)
    return cv.unobserved_table(rows), coverage, duration


def is_moving(pose: np.ndarray) -> bool:
    """Whether a sensor's poses (x, y, z, yaw per box) differ: by more than 1 mm or 1e-4 rad."""
    pose = np.asarray(pose, np.float64)
    return bool(len(pose) and (np.ptp(pose[:, :3], axis=0).max() > 1e-3
                               or np.ptp(np.unwrap(pose[:, 3])) > 1e-4))


def _shadows(cov: Range, boxes: Boxes, ids: np.ndarray, pose: np.ndarray, fi: np.ndarray,
             nxt: np.ndarray, moving: bool) -> list[dict[str, Any]]:
    """The ground shadow of every box seen from the sensor where it stood in the box's frame,
    from the box's time to the next frame."""
    from aveas_format.converters.common.coverage import occlusion_shadows

    n = len(boxes)
    x, y = boxes["x"], boxes["y"]
    heading = np.asarray(boxes["heading"], np.float64)
    length, width = (np.asarray(boxes[k], np.float64) for k in ("length", "width"))
    height = np.asarray(boxes.get("height", np.full(n, np.nan)), np.float64)
    height = np.where(np.isfinite(height), height, cov.default_height)
    shadows: list = [None] * n
    if moving:  # the rows of each frame, seen from the sensor's pose in that frame
        by_frame = np.argsort(fi, kind="stable")
        groups = np.split(by_frame, np.flatnonzero(np.diff(fi[by_frame])) + 1)
    else:
        groups = [np.arange(n)]
    for g in groups:
        s = pose[g[0]]
        for i, geom in zip(g, occlusion_shadows((float(s[0]), float(s[1]), float(s[2])), x[g], y[g],
                                                heading[g], length[g], width[g], height[g],
                                                cov.range_m)):
            shadows[i] = geom
    keep = np.flatnonzero(np.asarray([g is not None for g in shadows]))
    return [{"time_start": float(boxes.time[i]), "time_end": float(nxt[fi[i]]), "kind": "occlusion",
             "geometry": shadows[i], "sensor_id": cov.sensor_id, "occluder_id": int(ids[boxes.pid[i]])}
            for i in keep]


# --- per participant ------------------------------------------------------------------------------

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
    """Sample standard deviation of ``values`` (1D) per code (NaN where fewer than 2 samples)."""
    v = np.asarray(values, np.float64)
    ok = ~np.isnan(v)
    c = np.bincount(codes, weights=ok.astype(float), minlength=n)
    m = group_mean(codes, v, n)
    d2 = np.where(ok, (v - m[codes]) ** 2, 0.0)
    s = np.bincount(codes, weights=d2, minlength=n)
    return np.where(c > 1, np.sqrt(s / np.maximum(c - 1, 1)), np.nan)


def group_median(codes: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Median of ``values`` (1D) per code, NaN-aware (NaN where none): one sort of all values by
    (code, value), no loop over participants."""
    v = np.asarray(values, np.float64)
    ok = ~np.isnan(v)
    c, vv = codes[ok], v[ok]
    order = np.lexsort((vv, c))
    sv = vv[order]
    counts = np.bincount(c, minlength=n)
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    lo = starts + np.maximum(counts - 1, 0) // 2
    hi = starts + counts // 2
    have = counts > 0
    out = np.full(n, np.nan)
    out[have] = (sv[lo[have]] + sv[np.minimum(hi, len(sv) - 1)[have]]) / 2.0
    return out


def nullable(a: Any) -> Any:
    """A float column with NaN as null (null = unknown); other columns as they are."""
    if isinstance(a, (pa.Array, pa.ChunkedArray)):
        return a
    arr = np.asarray(a)
    if arr.ndim == 1 and arr.dtype.kind == "f" and np.isnan(arr).any():
        return pa.array(arr, from_pandas=True)
    return a
