"""OpenLABEL -> recording (the import): AVEAS-profile files, this library's own (lossless through
the ``aveas_format`` extension) and generic ASAM OpenLABEL with cuboids.

:func:`import_openlabel` is the registered importer (``openlabel``): it streams the file
(:mod:`.stream`) and finds the map; :func:`openlabel_to_recording` takes a parsed document. Both run
:func:`_openlabel_to_recording` in steps: the CRS; the frames into per-box columns
(:class:`~aveas_format.converters.openlabel.frames._FrameRows`); frame times and participant ids;
the boxes into states columns (duplicates dropped, world -> the map's local frame, vehicle -> world
frame, the file's road coordinates, the extension's exact values); participants; the events,
interior, environment tables and conditions (from the extension, else the profile's events and
contexts); the recording's metadata; :func:`build_recording`; the derived tables of our own export.
"""

from __future__ import annotations

import math
import warnings
from collections import defaultdict
from contextlib import closing
from decimal import Decimal
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Literal

import numpy as np
import pyarrow as pa
from pydantic import Field

from aveas_format.converters.common.provenance import prefetch_sha256, source_block
from aveas_format.converters.common.timestamps import TIMESTAMP_UNITS, resolve_timestamps
from aveas_format.mapref.build import load_map_bytes
from aveas_format.converters.labels import LabelFilter, implausible_size, label_kind
from aveas_format.converters.openlabel.findings import (_check_objects, _claims_profile, _jpath,
                                                        _report_frame_findings)
from aveas_format.converters.openlabel.parts import import_openlabel_to
from aveas_format.converters.openlabel.frames import (_MISSING, _FrameData, _Frames, _FrameRows, _rep_list,
                                                      _rep_take, _static_cuboids, _utm_crs)
from aveas_format.converters.openlabel.profile import (
    EXT,
    LIGHTS,
    TYPE_TO_CLASS,
    _attrs,
    _body_std,
    _first,
    _no_gc,
    _rot_world,
    _to_utc,
)
from aveas_format.converters.openlabel.stream import (COLUMNAR, _check_stream, _load_doc, _NotStrictJSON, _Rescan,
                                                      _stream_doc)
from aveas_format.converters.openlabel.tables import _recording_metadata, _restore_derived, _tables
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, report_source
from aveas_format.numeric import small_pages
from aveas_format.parallel import background
from aveas_format.schema.taxonomy import CLASSES

#: states from which side work of the import's tail runs in a thread (WGS 84 coordinates)
_THREADED_MIN = 1 << 16


class OpenLabelImportOptions(ImportOptions):
    world_crs: str | None = None
    """CRS (PROJ/EPSG) of the root coordinate system of generic files, e.g. EPSG:32630; default:
    read from a ``geo_utm`` root named like ``utm-30t``, else the root is the map frame."""
    method: str | None = None
    """Acquisition method (default: from ``acquisition_method``; ``road_vehicle`` where a generic
    file has an ego object, else ``infrastructure_camera``)."""
    rate_hz: float = 10.0
    """Frame rate of files without frame timestamps."""
    road_coordinates: str = "auto"
    """``file`` (take the file's road coordinates), ``map`` (compute them through the map) or
    ``auto`` (the file's where it has them, else the map's)."""
    provenance: str | None = None
    """natural / staged / simulated (default: from the file; ``staged`` where the scenario
    context says so, else natural)."""
    timestamp_unit: Literal[TIMESTAMP_UNITS] = "auto"
    """Unit of ``frame_properties.timestamp``: s, ms, us or ns; ``auto`` infers it from the values'
    magnitude (since the Unix epoch when they fall between 1990 and 2100) and spacing (since the
    start otherwise); the choice is recorded in the ``source`` block."""
    workers: int = Field(0, ge=0, exclude=True)
    """Processes reading the blocks of frames of a large file (0: one per core; 1: in this
    process; CLI ``--workers``); the recording is the same whatever the number (not recorded in
    the ``source`` block)."""
    keep_non_road_users: bool = False
    """Import objects whose type is no road user (barriers, signs, static persons...; see
    docs/converters.md "Labels that are not road users"), as class other; ignore-type objects
    (KITTI's DontCare) are never imported."""


def _find_map(path: Path, ol: dict[str, Any], map_source, options) -> bytes:
    if map_source is not None:
        return load_map_bytes(map_source)
    name = (ol.get("metadata") or {}).get("opendrive")
    if name:
        cand = (path.parent / str(name))
        if cand.is_file():
            return cand.read_bytes()
        # case-insensitive match next to the file
        for q in path.parent.iterdir():
            if q.name.lower() == str(name).lower():
                return q.read_bytes()
    raise FormatError("no map: pass --map MAP.xodr (metadata.opendrive "
                      + (f"{name!r} is not next to the file)" if name else "is absent)"), path=path)


@converter("openlabel", description="ASAM OpenLABEL 1.0 JSON (AVEAS profile and generic cuboids)",
           patterns=("*.json", "*.json.gz", "*.json.zst"), method=None, options=OpenLabelImportOptions,
           needs_map=False, provides=("partner", "start_time", "license"), writes=import_openlabel_to,
           sniff=(b'"openlabel"',))
def import_openlabel(inputs: list[Path], *, map_source, options: OpenLabelImportOptions, parts=None):
    """``parts``: an import that writes its recording itself (:func:`.parts.import_openlabel_to`)."""
    if len(inputs) != 1:
        raise FormatError(f"openlabel: expected one input file, got {len(inputs)}")
    path = Path(inputs[0])
    import importlib.util

    if importlib.util.find_spec("ijson") is None:  # a dependency; without it: read whole, as before
        warnings.warn("ijson is not installed: the OpenLABEL file is read whole (pip install ijson, "
                      "a dependency of aveas-format)",
                      stacklevel=2)
    else:
        with _no_gc(), small_pages():
            try:
                try:
                    try:  # without the structural pre-scan of the frames, where it can
                        ol, frames = _stream_doc(path, prescan=False)
                        map_bytes = _find_map(path, ol, map_source, options)
                        return _openlabel_to_recording(ol, map_bytes, options=options, path=path,
                                                       frames=frames, parts=parts)
                    except _Rescan:
                        pass
                    ol, frames = _stream_doc(path)
                    map_bytes = _find_map(path, ol, map_source, options)
                    return _openlabel_to_recording(ol, map_bytes, options=options, path=path,
                                                   frames=frames, parts=parts)
                except (_NotStrictJSON, FormatError) as e:
                    if isinstance(e, _NotStrictJSON) or str(e.message).startswith(
                            ("broken JSON", "not UTF-8", "JSON ")):
                        raise
                    _check_stream(path)
                    raise
                except Exception:
                    # as when the file was parsed whole: a JSON error anywhere in the file comes
                    # before what the frames read so far made of it (checked only on failure)
                    _check_stream(path)
                    raise
            except _NotStrictJSON:
                pass
    with _no_gc():
        ol = _load_doc(path)
    map_bytes = _find_map(path, ol, map_source, options)
    return openlabel_to_recording(ol, map_bytes, options=options, path=path)


def openlabel_to_recording(ol: dict[str, Any], map_bytes: bytes, *, options=None, path: Path | None = None):
    """A recording from a parsed OpenLABEL document (the object under ``openlabel``)."""
    with _no_gc():
        return _openlabel_to_recording(ol, map_bytes, options=options, path=path)


def _openlabel_to_recording(ol: dict[str, Any], map_bytes: bytes, *, options=None,
                            path: Path | None = None, frames=None, parts=None):
    """``frames``: a function yielding ``(key, frame)`` in file order (the streamed import); else
    the frames are ``ol["frames"]``. Both go through :class:`_FrameRows`. ``parts``: an import
    that writes its recording itself (:class:`.parts.Parts`; the states are then not in the
    recording returned, but in ``parts.states_file``)."""
    from aveas_format.mapref.build import build_recording
    from aveas_format.crs import LocalFrame
    from aveas_format.opendrive import load_map

    options = options or OpenLabelImportOptions()
    if "openlabel" in ol and isinstance(ol["openlabel"], dict):
        ol = ol["openlabel"]
    md = ol.get("metadata") or {}
    ext = md.get(EXT) if isinstance(md.get(EXT), dict) else None
    rmeta = dict((ext or {}).get("recording") or {})
    net = load_map(map_bytes)
    crs = _crs(net, rmeta, md, path)
    local = LocalFrame(crs, offset=net.header.offset, warn=False)

    # frames (streamed one at a time, or from the dict) into per-box columns, and time
    objects = ol.get("objects") or {}
    acc = _FrameRows(objects, _Frames(ol.get("coordinate_systems")), path)
    acc.profile = _claims_profile(md, objects)
    acc.parts = parts
    if frames is None:
        for k, fr in (ol.get("frames") or {}).items():
            acc.add(k, fr)
    else:  # blocks of frames in columns (the profile's layout) or one frame at a time
        # (closed before an error leaves: the workers done, none writing into the spill then)
        with closing(frames(columnar=not acc.static_cuboids, workers=options.workers,
                            spill_to=acc.spill_target)) as got:
            for k, fr in got:
                if path is not None and not acc.keys:  # (the input's digest in a thread from here
                    prefetch_sha256(path)              # on: the worker processes are forked by now)
                if k is COLUMNAR:
                    acc.add_columns(fr)
                else:
                    acc.add(k, fr)
        if "objects" not in ol or ol["objects"] is not objects:  # read after the frames (no pre-scan)
            objects = ol.get("objects") or {}
            if _static_cuboids(objects):  # (their boxes come from the frames' transforms)
                raise _Rescan
            acc.objects, acc.profile = objects, _claims_profile(md, objects)
    fd = acc.finish()
    _report_frame_findings(fd, path)
    fnum, time_of, start_time, resolved = _frame_times(fd.fkeys, fd.stamps, ext, md, options, path)
    uids = list(objects)
    uids += fd.seen_in_frames
    # (what the states are made with besides the boxes)
    ctx = SimpleNamespace(ol=ol, ext=ext, objects=objects, options=options, path=path, local=local, net=net)
    got = None
    if fd.rows is None:  # (spilled: the states written in parts, or None: read back into memory)
        got = parts.write_states(fd, uids, time_of, start_time, ctx)
        if got is None:
            fd = acc.finish(materialise=True)
    if got is None:
        got = _states_in_memory(fd, uids, time_of, start_time, resolved, ctx)
    uids, obj_ext, pid_of, states, n, start_time, use_file, meta_kw = got
    interior = fd.interior(pid_of, time_of)

    participants, ego_seen = _participants(uids, objects, pid_of, obj_ext, fd.sizes, ext, fd.frame_types)
    _check_objects(uids, objects, fd.frame_types, _claims_profile(md, objects), path)
    if n == 0:
        states = {c: pa.array([], pa.int64() if c == "participant_id" else pa.float64())
                  for c in ("participant_id", "time", "x", "y", "heading", "vx", "vy")}
    tables, conditions, staged = _tables(ol, ext, {fnum[k]: time_of[k] for k in fd.fkeys}, pid_of,
                                         interior)
    meta_args, kw = _recording_metadata(options, md, rmeta, ext, path, n, ego_seen, staged, conditions)
    kw = {**meta_kw, **kw}  # (the states' duration, rate and location where they were written in parts)
    rec = build_recording(
        map_source=map_bytes, participants=participants, states=states, **tables, crs=crs,
        **meta_args, start_time=start_time,
        recording_id=options.recording_id or rmeta.get("recording_id"),
        reference=not use_file,
        source=source_block("openlabel", [path] if path is not None else [], options,
                            resolved=resolved),
        **kw)
    if ext is not None:
        _restore_derived(rec, ext, path)
    return rec


def _states_in_memory(fd: _FrameData, uids: list[str], time_of: dict, start_time: str,
                      resolved: dict[str, str], ctx: SimpleNamespace) -> tuple:
    """``(uids, obj_ext, pid_of, states columns, n, start_time, use_file, {})``: the boxes of all
    frames (``fd.rows``) into the states' columns at once."""
    objects, ext, options, path = ctx.objects, ctx.ext, ctx.options, ctx.path
    if ext is None:  # a foreign file: objects that are no road users, sentinel sizes
        uids = _drop_non_participants(fd, objects, uids, options, path)
    obj_ext, pid_of = _participant_ids(objects, uids)

    # per object and frame: one state per box
    rows = _box_rows(fd, pid_of, time_of)
    n = len(rows["time"])
    if n == 0 and uids:
        raise _no_boxes_error(objects, path)
    start_time = _box_timestamps(rows, ext, options, start_time, resolved)
    state_ext = _drop_repeats(rows, fd, path)
    n = len(rows["time"])
    x, y, heading = _to_local(rows, ctx.ol, ctx.local, options.world_crs)
    # (WGS 84 in a thread while the other columns are made: PROJ releases the GIL)
    lonlat = background(ctx.local.to_wgs84, x, y, name="wgs84") if n >= _THREADED_MIN else None
    states = _state_columns(rows, x, y, heading, fd.has_vel)
    use_file = options.road_coordinates == "file" or (options.road_coordinates == "auto" and fd.has_road)
    if use_file and n:
        _file_road_coordinates(states, rows, ctx.net, state_ext)
    _apply_state_extension(states, state_ext)
    del rows, state_ext  # the per-box columns are in ``states`` now
    fd.rows = fd.ext = None
    same_xy = states["x"] is x and states["y"] is y and "lon" not in states and "lat" not in states
    states = _state_arrays(states, ext)
    if lonlat is not None:
        lon, lat = lonlat.result()
        if same_xy:  # (else the extension changed them: build_recording's from the final ones)
            states["lon"], states["lat"] = pa.array(lon), pa.array(lat)
    return uids, obj_ext, pid_of, states, n, start_time, use_file, {}


# ================================================================================================
# CRS, time, participant ids
# ================================================================================================

def _crs(net, rmeta: dict[str, Any], md: dict[str, Any], path: Path | None) -> str:
    """The CRS: the map's ``<geoReference>``, else the recording's, else ``projection_string``."""
    from aveas_format.crs import parse_crs

    crs = net.header.geo_reference or rmeta.get("crs")
    if not crs:
        ps = md.get("projection_string")
        if ps:
            try:
                parse_crs(ps)
                crs = ps
            except FormatError:
                report_source("source.openlabel.bad_metadata", f"projection_string {ps!r} is not a usable CRS",
                              stacklevel=3, file=str(path) if path is not None else None,
                              json_path="$.openlabel.metadata.projection_string")
    if not crs:
        raise FormatError("neither the map (<geoReference>) nor metadata.projection_string gives "
                          "a usable CRS", path=path)
    return crs


def _frame_times(fkeys: list, stamps: dict[Any, Any], ext: dict[str, Any] | None, md: dict[str, Any],
                 options: OpenLabelImportOptions, path: Path | None = None
                 ) -> tuple[dict, dict, str, dict[str, str]]:
    """``(frame number by key, time by key, start_time, resolved)``: in our own files the frames'
    timestamps are seconds since ``acquisition_date``; in foreign files their unit and epoch are
    inferred (:func:`~aveas_format.converters.common.resolve_timestamps`; ``timestamp_unit``
    fixes the unit); without a timestamp on every frame, frame numbers at ``rate_hz``.
    ``resolved`` records the choice for the ``source`` block."""
    fnum = {k: (int(k) if str(k).lstrip("-").isdigit() else i) for i, k in enumerate(fkeys)}
    start_time = None
    resolved: dict[str, str] = {}
    if ext and ext.get("start_time"):
        start_time = ext["start_time"]
        time_of = {k: float(stamps[k]) if isinstance(stamps[k], (int, float, Decimal)) else 0.0 for k in fkeys}
    else:
        ts = resolve_timestamps([stamps[k] for k in fkeys], options.timestamp_unit,
                                what="frame_properties.timestamp") if fkeys else None
        if ts is not None and np.isfinite(ts.seconds).all():
            time_of = dict(zip(fkeys, ts.seconds.tolist()))
            start_time = ts.start_time
            resolved = ts.resolved()
        else:
            f0 = min(fnum.values()) if fnum else 0
            time_of = {k: (fnum[k] - f0) / options.rate_hz for k in fkeys}
            missing = "no frame has" if ts is None or np.isnan(ts.seconds).all() else "not every frame has"
            resolved = {"timestamps": f"{missing} a timestamp: frame numbers at rate_hz "
                                      f"{options.rate_hz:g}"}
        if start_time is None and md.get("acquisition_date"):
            try:
                start_time = _to_utc(str(md["acquisition_date"]))
            except FormatError:
                report_source("source.openlabel.bad_metadata",
                              f"metadata.acquisition_date {md['acquisition_date']!r} is not an ISO "
                              "8601 time: ignored", stacklevel=3,
                              file=str(path) if path is not None else None,
                              json_path="$.openlabel.metadata.acquisition_date")
    start_time = options.start_time or start_time or "1970-01-01T00:00:00Z"
    return fnum, time_of, start_time, resolved


def _drop_non_participants(fd: _FrameData, objects: dict[str, Any], uids: list[str],
                           options: OpenLabelImportOptions, path: Path | None) -> list[str]:
    """The objects to import: not those whose type is no road user (unless
    ``keep_non_road_users``) or an ignore type (KITTI's DontCare), nor boxes with a sentinel or
    impossible size (a -1000, a 0): each is dropped from the frames' rows, with one warning
    saying how many and why. An object left without boxes is dropped when it had any."""
    keep_uid, report_skipped = _object_filter(fd, objects, uids, options, path)
    report_skipped()
    rows = fd.rows
    if len(rows["uidx"]):
        keep, dropped = _box_filter(rows, keep_uid, fd.uid_names)
        if dropped.any():
            first = int(np.argmax(dropped))
            _report_bad_sizes(int(dropped.sum()), {fd.uid_names[i] for i in np.unique(rows["uidx"][dropped])},
                              fd.fkeys[int(rows["rank"][first])], fd.uid_names[int(rows["uidx"][first])], path)
        if not keep.all():
            had = set(np.unique(rows["uidx"]).tolist())
            left = set(np.unique(rows["uidx"][keep]).tolist())
            for i in had - left:
                keep_uid[fd.uid_names[i]] = False
            idx = np.flatnonzero(keep)
            for c in list(rows):
                rows[c] = rows[c][idx]
            fd.ext = {c: _rep_take(r, idx) for c, r in fd.ext.items()}
    return _kept_uids(fd, uids, keep_uid)


def _object_filter(fd: _FrameData, objects: dict[str, Any], uids: list[str],
                   options: OpenLabelImportOptions, path: Path | None) -> tuple[dict[str, bool], Any]:
    """``(whether each object is imported by its type, a function reporting those that are not)``."""
    labels = LabelFilter(options.keep_non_road_users)
    keep_uid: dict[str, bool] = {}
    first_skipped = None
    for u in uids:
        obj = objects.get(u) if isinstance(objects.get(u), dict) else {}
        od = obj.get("object_data") if isinstance(obj.get("object_data"), dict) else {}
        otype = obj.get("type") or (od.get("type") if isinstance(od.get("type"), str) else None) \
            or fd.frame_types.get(u) or "other"
        keep_uid[u] = labels(otype) is not None
        if first_skipped is None and not keep_uid[u]:
            first_skipped = u

    def report() -> None:
        note = labels.note("objects")
        if note:  # (the file is the finding's location)
            report_source("source.openlabel.skipped_object", "OpenLABEL: " + note,
                          count=sum(labels.skipped.values()), stacklevel=4,
                          file=str(path) if path is not None else None, uid=first_skipped,
                          json_path=_jpath("objects", first_skipped, "type"))
    return keep_uid, report


def _box_filter(rows: dict[str, np.ndarray], keep_uid: dict[str, bool], names: list[str]
                ) -> tuple[np.ndarray, np.ndarray]:
    """``(the boxes kept, those dropped for their size)`` of objects kept by type."""
    by_index = np.asarray([keep_uid.get(u, True) for u in names], bool)
    keep = by_index[rows["uidx"]]
    bad = implausible_size(np.c_[rows["dl"], rows["dw"], rows["dh"]])
    return keep & ~bad, keep & bad


def _report_bad_sizes(count: int, who: set[str], frame: Any, uid: str, path: Path | None) -> None:
    who_ = sorted(who)
    report_source("source.openlabel.bad_size",
                  f"OpenLABEL: dropped {count} boxes with a sentinel or impossible size "
                  f"(<= 0, not finite or > 400 m) of object(s) {', '.join(who_[:5])}"
                  + (" ..." if len(who_) > 5 else ""), count=count, stacklevel=4,
                  file=str(path) if path is not None else None, frame=frame, uid=uid,
                  json_path=_jpath("frames", frame, "objects", uid, "object_data", "cuboid"))


def _kept_uids(fd: _FrameData, uids: list[str], keep_uid: dict[str, bool]) -> list[str]:
    """The objects imported; ``fd.sizes`` of those, without implausible sizes."""
    for u in list(fd.sizes):
        if not keep_uid.get(u, True):
            del fd.sizes[u]
        else:
            arr = np.asarray(fd.sizes[u], float).reshape(-1, 3)
            fd.sizes[u] = arr[~implausible_size(arr)].tolist()
    return [u for u in uids if keep_uid.get(u, True)]


def _participant_ids(objects: dict[str, Any], uids: list[str]) -> tuple[dict, dict[str, int]]:
    """``(extension item by object, participant id by object)``: the ids our own export wrote, else
    the object keys where all are numbers, else 0, 1, ... in order."""
    obj_ext = {}
    for u in uids:
        size_items = _attrs((objects.get(u) or {}).get("object_data")).get("dimensions/size") or []
        e = size_items[0].get(EXT) if size_items and isinstance(size_items[0].get(EXT), dict) else None
        obj_ext[u] = e
    if all(e is not None and "participant_id" in e for e in obj_ext.values()) and uids:
        pid_of = {u: int(obj_ext[u]["participant_id"]) for u in uids}
    elif all(str(u).isdigit() for u in uids):
        pid_of = {u: int(u) for u in uids}
    else:
        pid_of = {u: i for i, u in enumerate(uids)}
    return obj_ext, pid_of


# ================================================================================================
# the boxes -> states columns
# ================================================================================================

def _box_rows(fd: _FrameData, pid_of: dict[str, int], time_of: dict) -> dict[str, np.ndarray]:
    """The per-box columns of the frames, with ``participant_id`` and ``time`` in place of the
    object and frame indices."""
    rows = fd.rows
    uidx, rank = rows["uidx"], rows["rank"]  # (kept: where the findings are)
    rows["participant_id"] = np.asarray([pid_of.get(u, 0) for u in fd.uid_names])[uidx] \
        if fd.uid_names else np.asarray([])
    rows["time"] = np.asarray([time_of[k] for k in fd.fkeys], float)[rank] if fd.fkeys else np.asarray([])
    return rows


def _no_boxes_error(objects: dict[str, Any], path: Path | None) -> FormatError:
    static = sum(1 for o in objects.values()
                 if isinstance(o, dict) and isinstance(o.get("object_data"), dict)
                 and "cuboid" in o["object_data"])
    flat = sum(1 for o in objects.values()
               if isinstance(o, dict) and isinstance(o.get("object_data"), dict)
               and o["object_data"].get("bbox") and not o["object_data"].get("cuboid"))
    hint = (f" ({static} object(s) carry a static cuboid in object_data, which has no time: "
            "a trajectory needs frames)" if static else
            f" ({flat} objects carry 2D boxes (bbox) only: image coordinates, no position on the "
            "ground)" if flat else "")
    return FormatError(f"no frame has a cuboid for any object{hint}", path=path)


def _box_timestamps(rows: dict[str, np.ndarray], ext: dict[str, Any] | None,
                    options: OpenLabelImportOptions, start_time: str, resolved: dict[str, str]) -> str:
    """Per-box measurement timestamps (cuboid attribute "timestamp", absolute) beat the frame's:
    the ASAM example repeats frame timestamps while its boxes' differ. Sets ``rows["time"]``
    (and ``resolved``); returns the start time."""
    cts = np.asarray(rows["cub_ts"], float)
    if ext is None and len(rows["time"]) and np.isfinite(cts).all():
        ts = resolve_timestamps(cts.tolist(), options.timestamp_unit,
                                what="cuboid attribute timestamp")
        if ts.epoch:
            rows["time"] = ts.seconds
            resolved.update(ts.resolved())
            if not options.start_time:
                start_time = ts.start_time
    return start_time


def _drop_repeats(rows: dict[str, np.ndarray], fd: _FrameData, path: Path | None,
                  dropped: list | None = None) -> dict[str, tuple]:
    """One state per participant and time: later duplicates are dropped (from ``rows``, in place,
    and from the extension columns ``fd.ext``, returned), reported at the first one dropped; or,
    given a list ``dropped``, ``(count, index of the first, frame, object)`` appended to it."""
    state_ext = fd.ext
    n = len(rows["time"])
    if n:
        pid, t = np.asarray(rows["participant_id"]), np.asarray(rows["time"], float)
        order = np.lexsort((t, pid))  # (stable: the first of equal keys first)
        ps, ts = pid[order], t[order]
        repeat = (ps[1:] == ps[:-1]) & (ts[1:] == ts[:-1])
        if repeat.any():
            keep = np.sort(order[np.concatenate([[True], ~repeat])])
            dup = np.ones(n, bool)
            dup[keep] = False
            i = int(np.argmax(dup))
            frame, uid = fd.fkeys[int(rows["rank"][i])], fd.uid_names[int(rows["uidx"][i])]
            if dropped is not None:
                dropped.append((n - len(keep), i, frame, uid))
            else:
                _report_repeats(n - len(keep), frame, uid, path)
            for c in list(rows):
                rows[c] = rows[c][keep]
            state_ext = {c: _rep_take(r, keep) for c, r in state_ext.items()}
    return state_ext


def _report_repeats(count: int, frame: Any, uid: str, path: Path | None) -> None:
    report_source("source.openlabel.duplicate_state",
                  f"OpenLABEL: {count} boxes repeat a (participant, time) and were "
                  f"dropped (first: frame {frame}, object {uid})", count=count,
                  stacklevel=4, file=str(path) if path is not None else None, frame=frame,
                  uid=uid, json_path=_jpath("frames", frame, "objects", uid))


def _to_local(rows: dict[str, np.ndarray], ol: dict[str, Any], local, root_crs: str | None,
              roots: set | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Box centres and yaw in the map's local frame: through WGS84 where the root coordinate system
    has a CRS (``world_crs``, or a UTM root's name), else the root is the map frame. ``roots``:
    the root coordinate systems of all boxes (default: of ``rows``)."""
    from aveas_format.crs import parse_crs
    from aveas_format.numeric import wrap_angle

    n = len(rows["time"])
    px, py = np.asarray(rows["px"], float), np.asarray(rows["py"], float)
    yaw = np.asarray(rows["yaw"], float)
    if roots is None:
        roots = {r for r in rows["csroot"] if r}
    wcrs = root_crs
    if wcrs is None and len(roots) == 1:
        r = next(iter(roots))
        wcrs = _utm_crs(r, ((ol.get("coordinate_systems") or {}).get(r) or {}).get("type"))
    if wcrs is not None and n:
        import pyproj

        tr = pyproj.Transformer.from_crs(parse_crs(wcrs).crs, "EPSG:4326", always_xy=True)
        lon, lat = tr.transform(px, py)
        lon2, lat2 = tr.transform(px + np.cos(yaw), py + np.sin(yaw))
        x, y = local.from_wgs84(np.asarray(lon), np.asarray(lat))
        x2, y2 = local.from_wgs84(np.asarray(lon2), np.asarray(lat2))
        heading = np.arctan2(y2 - y, x2 - x)
    else:
        x, y, heading = px, py, yaw
    return x, y, wrap_angle(heading)


def _state_columns(rows: dict[str, np.ndarray], x: np.ndarray, y: np.ndarray, heading: np.ndarray,
                   has_vel: bool, has_acc: bool | None = None) -> dict[str, Any]:
    """The states' columns from the profile's attributes: position, velocity and acceleration
    (vehicle -> world frame) with their 1-sigma, yaw rate, lights. ``has_acc``: every box has an
    acceleration (default: every box of ``rows``)."""
    n = len(rows["time"])
    pid = np.asarray(rows["participant_id"], np.int64)
    t = np.asarray(rows["time"], float)
    states: dict[str, Any] = {"participant_id": pid, "time": t, "x": x, "y": y, "heading": heading,
                              "z": np.asarray(rows["pz"], float)}
    if has_vel and n:
        vx, vy = _rot_world(np.asarray(rows["vu"], float), np.asarray(rows["vv"], float), heading)
        states["vx"], states["vy"] = vx, vy
        yr = np.asarray(rows["yr"], float)
        if np.isfinite(yr).any():
            states["yaw_rate"] = yr
        au, av = np.asarray(rows["au"], float), np.asarray(rows["av"], float)
        if has_acc is None:
            has_acc = bool(np.isfinite(au).all() and np.isfinite(av).all())
        if has_acc:
            states["ax"], states["ay"] = _rot_world(au, av, heading)
        for c in ("x_std", "y_std", "z_std", "heading_std"):
            a = np.asarray(rows[c], float)
            if np.isfinite(a).any():
                states[c] = a
        su, sv = np.asarray(rows["vu_std"], float), np.asarray(rows["vv_std"], float)
        if np.isfinite(su).any():
            sx, sy = _body_std(su, sv, None, -heading)  # vehicle -> world (independent components)
            states["vx_std"], states["vy_std"] = sx, sy
        ysd = np.asarray(rows["yr_std"], float)
        if np.isfinite(ysd).any():
            states["yaw_rate_std"] = ysd
        su, sv = np.asarray(rows["au_std"], float), np.asarray(rows["av_std"], float)
        if np.isfinite(su).any() and "ax" in states:
            states["ax_std"], states["ay_std"] = _body_std(su, sv, None, -heading)
    for c in LIGHTS:
        a = np.asarray(rows[c], float)
        if not np.isnan(a).all():
            states[c] = pa.array(a, mask=np.isnan(a), type=pa.float32())
    return states


def _file_road_coordinates(states: dict[str, Any], rows: dict[str, np.ndarray], net,
                           state_ext: dict[str, tuple] | None = None) -> None:
    """The file's road coordinates into ``states`` (the lane offset from ``lane_position`` and the
    lane's width in the map, except where this library's extension item gives it: it replaces
    the map's value there, :func:`_apply_state_extension`)."""
    n = len(rows["time"])
    road = pa.array(rows["road_id"], pa.string(), from_pandas=True)
    states["road_id"] = road
    lanes = pa.array(rows["lane_id"], pa.int16(), from_pandas=True)
    states["lane_id"] = lanes
    states["road_s"] = np.asarray(rows["road_s"], float)
    states["road_t"] = np.asarray(rows["road_t"], float)
    lp = np.asarray(rows["lane_position"], float)
    if np.isfinite(lp).any():
        enc = road.dictionary_encode()
        code = enc.indices.fill_null(-1).to_numpy(zero_copy_only=False)
        lane = lanes.fill_null(0).to_numpy(zero_copy_only=False).astype(np.int64)
        ok = np.isfinite(lp) & (code >= 0)
        given = (state_ext or {}).get("lane_offset")
        if given is not None and given[0] == "f":
            ok &= ~given[2]  # (present in the extension: null or a value, the map's is not used)
        lo = np.full(n, np.nan)
        idx = np.flatnonzero(ok)
        order = idx[np.argsort(code[idx], kind="stable")]
        bounds = np.searchsorted(code[order], np.arange(len(enc.dictionary) + 1))
        for k, r in enumerate(enc.dictionary.to_pylist()):
            m = order[bounds[k]:bounds[k + 1]]
            if not len(m):
                continue
            try:
                inner, outer = net.lane_borders(r, states["road_s"][m], lane[m])
                lo[m] = lp[m] * np.abs(outer - inner)
            except Exception:  # noqa: BLE001 — a road the map lacks
                pass
        states["lane_offset"] = lo


def _apply_state_extension(states: dict[str, Any], state_ext: dict[str, tuple]) -> None:
    """The extension of this library's own export into ``states``: its columns and the exact
    values (and nulls) where the profile's would differ."""
    for c in sorted(state_ext):
        base = states.get(c)
        rep = state_ext[c]
        if rep[0] == "f":  # floats (the common case): vectorised, same result as below
            _, fv, pr, nl = rep
            if base is None and (pr & ~nl).any():
                states[c] = pa.array(fv, mask=~(pr & ~nl), type=pa.float64())
                continue
            if (isinstance(base, np.ndarray) and base.dtype == np.float64 and base.ndim == 1
                    and len(base) == len(fv)):
                null = np.where(pr, nl, np.isnan(base))
                if not null.all():
                    states[c] = pa.array(np.where(pr, fv, base), mask=null, type=pa.float64())
                    continue
        if base is None and rep[0] == "o":  # (bools, ints, texts: Arrow infers from the objects)
            try:
                states[c] = pa.array(rep[1], mask=rep[1] == _MISSING)
                continue
            except (pa.ArrowException, TypeError, ValueError):  # (mixed values: as a list below)
                pass
        vals = _rep_list(rep)
        if base is None:
            states[c] = pa.array([None if v is _MISSING else v for v in vals])
        else:
            cur = base.to_pylist() if isinstance(base, (pa.Array, pa.ChunkedArray)) else [
                None if (isinstance(b, float) and math.isnan(b)) else b for b in np.asarray(base).tolist()]
            states[c] = pa.array([cur[i] if v is _MISSING else v for i, v in enumerate(vals)])


def _state_arrays(states: dict[str, Any], ext: dict[str, Any] | None) -> dict[str, pa.Array]:
    """The states' columns as Arrow arrays (only those our own export had, where it says)."""
    cols_keep = (ext or {}).get("states_columns")
    if cols_keep:
        for c in list(states):
            if c not in cols_keep:
                del states[c]
    return {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(
        np.asarray(v), from_pandas=True)) for c, v in states.items()}


# ================================================================================================
# participants
# ================================================================================================

def _participants(uids: list[str], objects: dict[str, Any], pid_of: dict[str, int], obj_ext: dict,
                  sizes: dict[str, list], ext: dict[str, Any] | None, frame_types: dict[str, str]
                  ) -> tuple[dict[str, Any], bool]:
    """``(participants columns, whether an object is the recording vehicle)``."""
    part, ego_seen = _profile_participants(uids, objects, pid_of, sizes, frame_types)
    if all(v is None for v in part["class_pmf"]):
        del part["class_pmf"]
    else:
        from aveas_format.schema.pmf import one_hot

        part["class_pmf"] = [v if v is not None else one_hot([c], "class")[0].tolist()
                             for v, c in zip(part["class_pmf"], part["class"])]
        m = np.asarray(part["class_pmf"], np.float32)
        part["class_pmf"] = pa.array(list(m), pa.list_(pa.float32()))
        # the class is the PMF's argmax (a foreign file may disagree; the PMF wins)
        part["class"] = [CLASSES[int(np.argmax(r))] if not obj_ext.get(u) else c
                         for r, c, u in zip(m, part["class"], uids)]
    for c in ("attached_to", "height", "length_std", "width_std", "height_std"):
        if c in part and all(v is None for v in part[c]):
            del part[c]
    p_ext_rows = [obj_ext.get(u) for u in uids]
    if any(e for e in p_ext_rows):
        _apply_participants_extension(part, p_ext_rows)
    pcols = (ext or {}).get("participants_columns")
    if pcols:
        for c in list(part):
            if c not in pcols:
                del part[c]
    participants = {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(v))
                    for c, v in part.items()}
    if not uids:  # a file without objects (e.g. the profile's minimum example)
        participants = {"participant_id": pa.array([], pa.int64()), "class": pa.array([], pa.string()),
                        "length": pa.array([], pa.float64()), "width": pa.array([], pa.float64())}
    return participants, ego_seen


def _profile_participants(uids: list[str], objects: dict[str, Any], pid_of: dict[str, int],
                          sizes: dict[str, list], frame_types: dict[str, str]
                          ) -> tuple[dict[str, list], bool]:
    """The participants' columns from the objects' types (in ``objects``, or inside a frame's
    object_data as TUM Traffic writes them) and static attributes (the size, else the median of
    the object's boxes; a static size with a sentinel value is ignored)."""
    part: dict[str, list] = defaultdict(list)
    ego_seen = False
    for u in uids:
        obj = objects.get(u) or {}
        attrs = _attrs(obj.get("object_data"))
        od = obj.get("object_data") if isinstance(obj.get("object_data"), dict) else {}
        otype = str(obj.get("type") or (od.get("type") if isinstance(od.get("type"), str) else None)
                    or frame_types.get(u) or "other")
        cls = TYPE_TO_CLASS.get(otype) or label_kind(otype)[0]
        is_ego = otype.lower() in ("egocar", "ego", "ego_vehicle") or bool(_first(attrs, "is_recorder", False))
        ego_seen |= is_ego
        size = _static_size(_first(attrs, "dimensions/size"))
        if size is None:
            arr = np.asarray(sizes.get(u) or [[1.0, 1.0, 1.0]], float)
            size = np.median(arr, axis=0).tolist()
        ssd = _first(attrs, "dimensions/size/ustddev")
        pmf = _first(attrs, "classification/uncertainties")
        part["participant_id"].append(pid_of[u])
        part["source_id"].append(str(obj.get("name") or u))
        part["class"].append(cls)
        part["length"].append(float(size[0]))
        part["width"].append(float(size[1]))
        part["height"].append(float(size[2]) if len(size) > 2 and size[2] else None)
        part["length_std"].append(float(ssd[0]) if ssd else None)
        part["width_std"].append(float(ssd[1]) if ssd else None)
        part["height_std"].append(float(ssd[2]) if ssd and len(ssd) > 2 else None)
        part["class_pmf"].append([float(v) for v in pmf] if pmf and len(pmf) == len(CLASSES) else None)
        att = _first(attrs, "attached_to")
        part["attached_to"].append(pid_of.get(str(att)) if att is not None else None)
        part["role"].append("recording_vehicle" if is_ego else "observed")
    return part, ego_seen


def _static_size(size: Any) -> list | None:
    """An object's static ``dimensions/size`` (length, width[, height]), or None where absent or
    a sentinel (a -1000, a 0, not numbers)."""
    if not isinstance(size, (list, tuple)) or len(size) < 2:
        return None
    try:
        arr = np.asarray([[float(v) for v in size[:3]] + [np.nan] * (3 - len(size[:3]))])
    except (TypeError, ValueError):
        return None
    return None if implausible_size(arr)[0] else list(size)


def _apply_participants_extension(part: dict[str, Any], p_ext_rows: list) -> None:
    """The participants' extension items of this library's own export into ``part``."""
    keys = sorted({c for e in p_ext_rows if e for c in e} - {"participant_id"})
    for c in keys:
        vals = [e.get(c, _MISSING) if e else _MISSING for e in p_ext_rows]
        cur = part.get(c)
        if c == "class_pmf":
            mats = [None if v is _MISSING else v for v in vals]
            if cur is not None:
                curl = cur.to_pylist()
                mats = [curl[i] if v is _MISSING else v for i, v in enumerate(vals)]
            part[c] = pa.array(mats, pa.list_(pa.float32()))
            continue
        if cur is None:
            part[c] = [None if v is _MISSING else v for v in vals]
        else:
            part[c] = [cur[i] if v is _MISSING else v for i, v in enumerate(vals)]
