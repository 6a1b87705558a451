"""ASAM OSI traces (GroundTruth / SensorView) -> recording.

Input: an OSI trace, either a binary ``.osi`` file (messages each prefixed with their length as a
4-byte little-endian integer; the message type from the trace file name convention
``<time>_<gt|sv>_...osi``, the ``message_type`` option, or probed from the first message) or an
MCAP file (``.mcap``) with ``osi3.GroundTruth``/``osi3.SensorView`` channels and the
``net.asam.osi.trace`` metadata record. SensorViews contribute their ``global_ground_truth``.
Decoding uses the PyPI package ``betterosi`` (pure-Python OSI 3.7/3.8 bindings).

What is read, per GroundTruth message (``timestamp`` -> time, relative to the first message;
MCAP ``zero_time`` metadata + that offset gives ``start_time`` unless the option sets it):

- every ``moving_object``: ``id`` -> source id; ``base.position`` x, y (z) = the bounding box centre
  in the OSI global frame, which is the footprint centre the format uses; ``base.orientation.yaw``
  (rad, counter-clockwise) -> heading; ``base.velocity``/``base.acceleration`` x, y -> vx, vy, ax,
  ay; ``base.dimension`` length/width/height (the first message of an object with a positive one
  counts);
  ``base.orientation_rate.yaw`` -> yaw_rate.
- class: ``type`` PEDESTRIAN -> pedestrian, ANIMAL -> animal, VEHICLE by
  ``vehicle_classification.type``: (small/compact/luxury) car -> car, delivery van -> van, heavy
  truck / semitractor -> truck, (semi)trailer -> trailer, motorbike -> motorcycle, bicycle, bus,
  tram/train -> railvehicle, wheelchair / stand-up scooter / micromobility device ->
  mobility_device, anything else -> other.
- ``vehicle_classification.light_state``: brake light on, indicators left/right/warning ->
  ``light_brake_p``, ``light_indicator_left_p``/``right_p``, ``light_hazard_p`` (0/1).
- ``assigned_lane_id`` (OSI lane ids, not OpenDRIVE lanes) -> the participant's ``osi_lanes``
  attribute; road coordinates are computed through the map.
- ``host_vehicle_id`` -> that participant gets role ``host_role`` (default ``system_under_test``).

Findings about the trace that the import survives are located (message index, object id) with
:func:`aveas_format.errors.report_source`, one per object and kind with a count (warnings of
``convert``, the ``source.osi.*`` rules of ``validate TRACE``): a moving object without id or
base (the sample is skipped), without a positive ``base.dimension`` (a later message's is used;
without any the object is not imported), an UNKNOWN or unmapped type (class ``other``), a
timestamp earlier than the previous message's (the states are sorted).

Frame: the OSI global frame is taken to be the map's local frame (a simulator driving on the same
OpenDRIVE map). Where the GroundTruth carries a ``proj_string`` that differs from the map's
geoReference, positions go from the OSI frame (through ``proj_frame_offset``) to the projected CRS
and then into the map's frame. Provenance ``simulated``, role ``simulated_agent``, every ``_std`` 0;
method ``traffic_simulation`` (option ``method`` for driving-simulator traces).

Where the map has no ``<geoReference>``, the trace's ``proj_string`` (with its
``proj_frame_offset``, a translation) is the recording's CRS, or ``--crs`` gives it. The map is
``--map``, else the file the first GroundTruth's ``map_reference`` names, next to the trace. The
OSI export writes ``proj_string``, ``map_reference`` and the map next to the trace, and in an MCAP
trace a metadata record ``aveas`` with the recording's partner, rights, start time and title, so
that its re-import needs nothing else.

Large traces: ``convert`` (of one trace) and ``validate TRACE`` import in bounded memory: the
samples are held in a :class:`~aveas_format.io.resort.StatesWriter` (spilled to a hidden temporary
directory next to the output beyond 128 MB) and made into states a bucket of objects at a time
(:func:`~aveas_format.converters.common.assemble.write_by_buckets`), written to
``states.parquet``: the same recording as the import in memory (the location's mean summed bucket
by bucket: equal to 1e-12 degrees). The Python function ``convert`` returns a recording in memory;
``convert_to`` writes it in bounded memory.

Tested on: omega-prime's esmini-written traces ``alks_cut-in.osi`` and ``acc-test.osi`` on
``straight_500m.xodr`` (``../shared/data/real/omega-prime``; also with the map's geoReference
removed), and this toolkit's own OSI exports of every real OpenSCENARIO file.
"""

from __future__ import annotations

import json
import math
import struct
from array import array
import warnings
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import bounded_states, to_recording, write_by_buckets
from aveas_format.converters.common.boxes import Boxes, Rows, Sensor
from aveas_format.converters.common.fastpath import FastPathUnsupported, read_by
from aveas_format.converters.common.geometry import projected_to_local, rotate
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError, report_source
from aveas_format.io.arrow import column_numpy
from aveas_format.io.resort import StatesWriter
from aveas_format.mapref.build import load_map_bytes
from aveas_format.safeio import check_mcap

VEHICLE_CLASS = {
    "SMALL_CAR": "car", "COMPACT_CAR": "car", "CAR": "car", "MEDIUM_CAR": "car", "LUXURY_CAR": "car",
    "DELIVERY_VAN": "van", "HEAVY_TRUCK": "truck", "SEMITRACTOR": "truck", "SEMITRAILER": "trailer",
    "TRAILER": "trailer", "MOTORBIKE": "motorcycle", "BICYCLE": "bicycle", "BUS": "bus",
    "TRAM": "railvehicle", "TRAIN": "railvehicle", "WHEELCHAIR": "mobility_device",
    "STANDUP_SCOOTER": "mobility_device", "MICROMOBILITY_DEVICE": "mobility_device",
}


class OsiOptions(ImportOptions):
    message_type: Literal["auto", "GroundTruth", "SensorView"] = "auto"
    """Message type of a .osi trace (auto: from the file name, else probed)."""
    host_role: Literal["system_under_test", "recording_vehicle", "simulated_agent"] = \
        "system_under_test"
    """Role of the GroundTruth's host vehicle."""
    method: Literal["traffic_simulation", "driving_simulator"] = "traffic_simulation"
    """acquisition.method of the recording."""


def _enum_name(v: Any) -> str:
    name = getattr(v, "name", None)
    if name is None:
        name = str(v).rsplit(".", 1)[-1]
    return str(name).upper().removeprefix("TYPE_")


def check_osi_framing(path: Path) -> int:
    """Number of length-prefixed messages of a binary .osi trace; a truncated message is an error
    naming its index and byte offset."""
    size = path.stat().st_size
    count = 0
    with open(path, "rb") as f:
        offset = 0
        while offset < size:
            head = f.read(4)
            if len(head) < 4:
                raise FormatError(f"truncated length prefix of message {count} at byte {offset}",
                                  path=path)
            (n,) = struct.unpack("<I", head)
            if offset + 4 + n > size:
                raise FormatError(f"message {count} at byte {offset} declares {n} bytes but the file "
                                  f"ends {size - offset - 4} bytes later (truncated trace?)", path=path)
            f.seek(n, 1)
            offset += 4 + n
            count += 1
    return count


def _messages(path: Path, options: OsiOptions):
    import betterosi

    suffix = path.suffix.lower()
    if suffix == ".osi":
        if check_osi_framing(path) == 0:
            raise FormatError("empty OSI trace", path=path)
        kw: dict[str, Any] = {}
        if options.message_type != "auto":
            kw["osi_message_type"] = options.message_type
        return betterosi.read(str(path), return_ground_truth=True, **kw)
    if suffix == ".mcap":
        check_mcap(path)  # bounded pre-scan before betterosi's mcap reader opens the file
        return betterosi.read(str(path), return_ground_truth=True)
    raise RecordingIOError("not an OSI trace (.osi or .mcap)", path=path)


#: the MCAP metadata record in which this toolkit's OSI export carries the recording.json values a
#: person states (:mod:`aveas_format.converters.common.carried`) and the map's file name
CARRIED_RECORD = "aveas"


def _trace_metadata(path: Path) -> dict[str, dict[str, str]]:
    """The metadata records of an MCAP trace by name (``net.asam.osi.trace``: ``zero_time``...;
    :data:`CARRIED_RECORD`); none for a .osi trace. An unreadable metadata section is reported
    as a finding."""
    if path.suffix.lower() != ".mcap":
        return {}
    import betterosi

    from aveas_format.converters.common.mcap import mcap_errors, why

    try:
        records = betterosi.read_file_metadata(str(path))
    except mcap_errors() as e:
        report_source("source.other", f"the MCAP metadata cannot be read "
                      f"({why(e)}): no zero_time, no start time from the trace", file=str(path))
        return {}
    return {str(md.get("name")): dict(md.get("data") or md.get("metadata") or {}) for md in records}


def _map_of_trace(path: Path, map_source, meta: dict[str, dict[str, str]], options: OsiOptions):
    """The map: ``--map``, else the one the trace names next to it (the first GroundTruth's
    ``map_reference``, or the export's metadata record); none is an error saying so."""
    if map_source is not None:
        return map_source
    name = (meta.get(CARRIED_RECORD) or {}).get("map")
    if not name:
        try:
            first = next(iter(_messages(path, options)), None)
        except Exception:  # noqa: BLE001 — the decoders report a damaged trace, located
            first = None
        name = str(getattr(first, "map_reference", "") or "") if first is not None else ""
    if not name or not name.lower().endswith(".xodr"):  # (esmini writes its proj string there)
        raise FormatError("no map: pass --map MAP.xodr (the trace names no map file: its "
                          + (f"map_reference {name!r} is no .xodr file name)" if name else
                             "GroundTruth has no map_reference)"), path=path)
    cand = path.parent / Path(name).name
    if not cand.is_file():
        raise FormatError(f"no map: pass --map MAP.xodr (the trace's map_reference {name!r} is "
                          f"not next to it, at {cand})", path=path)
    return cand


def convert_osi_to(inputs: list[Path], output: Path, *, map_source, options: OsiOptions,
                   overwrite: bool = False):
    """The trace's recording written to ``output`` in bounded memory: the samples held in a
    :class:`~aveas_format.io.resort.StatesWriter` (spilled next to the output beyond its memory),
    the states made and written a bucket of objects at a time (``convert`` of one trace, ``validate
    TRACE``): the same recording as :func:`convert_osi`."""
    with bounded_states(output, overwrite, key="oid") as w:
        trace = _trace(inputs, map_source, options, w)
        return write_by_buckets(w, partial(_boxes_of, trace=trace), trace.sensor,
                                trace.source_ids, output=output, overwrite=overwrite, converter="osi",
                                inputs=inputs, options=options, map_bytes=trace.map_bytes,
                                participants=trace.participants, net=trace.net)


@converter("osi", description="ASAM OSI trace (.osi length-prefixed binary or MCAP): GroundTruth "
           "moving objects", patterns=("*.osi", "*.mcap"), method="traffic_simulation",
           options=OsiOptions, requires=("betterosi",), extra="osi", sniff=(b"osi3.", b"net.asam.osi"),
           needs_map=False, writes=convert_osi_to)
def convert_osi(inputs: list[Path], *, map_source, options: OsiOptions):
    """The map is ``--map`` or the one the trace references (``map_reference``) next to it."""
    with StatesWriter(memory=None, key="oid") as w:
        trace = _trace(inputs, map_source, options, w)
        boxes = _boxes_of(next(w.buckets()), trace)
    return to_recording(boxes, trace.sensor, converter="osi", inputs=inputs, options=options,
                        map_bytes=trace.map_bytes, participants=trace.participants)


def _trace(inputs: list[Path], map_source, options: OsiOptions, writer: StatesWriter) -> SimpleNamespace:
    """The samples of the traces into ``writer`` (a row per sample: the object id ``oid``, the
    message ``msg`` and :data:`_FLOAT_COLS`) and what the import decides over all of them: the
    objects imported (``uniq``, ``source_ids``; those without a size reported and left out:
    ``sizeless``), the time origin ``t0``, the participants, the map, the projection and the
    sensor."""
    from aveas_format.converters.common.carried import sensor_values
    from aveas_format.opendrive import load_map

    if inputs[0].suffix.lower() == ".mcap":
        from aveas_format.converters.common.mcap import viewing_export_note

        note = viewing_export_note(inputs[0])
        if note:
            raise FormatError(f"not an OSI trace: {note}", path=inputs[0])
    meta = _trace_metadata(inputs[0])
    map_source = _map_of_trace(inputs[0], map_source, meta, options)

    def into(decode):
        def run():
            writer.reset()  # (a fast path that refuses a trace half-way leaves rows behind)
            return decode(inputs, options, _Sink(writer))
        return run

    what = ", ".join(p.name for p in inputs)
    static, host_ids, proj, found, tmin = read_by(what, ("the columnar decoder", into(_decode_columns)),
                                                 ("betterosi", into(_decode_objects)))
    sizeless = [oid for oid, d in static.items() if d["length"] is None]
    for oid in sizeless:
        found.add("source.osi.missing_dimension", oid, static[oid]["no_size_msg"],
                  f"moving object {oid} has no positive base.dimension (length, width) in any of "
                  f"its messages: not imported", count=static[oid]["no_size_n"])
        del static[oid]  # (objects without a size cannot be participants: their samples go)
    found.report(inputs[0] if len(inputs) == 1 else None)
    uniq = np.asarray(sorted(static), np.int64)
    if not len(uniq):
        raise FormatError("no GroundTruth moving objects in the trace", path=inputs[0])
    map_bytes = load_map_bytes(map_source)
    net = load_map(map_bytes)
    m = len(uniq)
    info = [static[int(u)] for u in uniq]
    participants = {
        "class": [d["class"] for d in info],
        "length": [d["length"] for d in info], "width": [d["width"] for d in info],
        "height": [d["height"] for d in info],
        "length_std": np.zeros(m), "width_std": np.zeros(m), "height_std": np.zeros(m),
        "role": [options.host_role if int(u) in host_ids else "simulated_agent" for u in uniq],
        "provenance": ["simulated"] * m,
        "attributes": [json.dumps({"osi_type": d["osi_type"], "osi_lanes": sorted(d["lanes"])})
                       for d in info],
    }
    t0 = min(tmin[int(u)] for u in uniq)
    zt = (meta.get("net.asam.osi.trace") or {}).get("zero_time")
    carried = sensor_values(meta.get(CARRIED_RECORD) or {})
    if zt and not options.start_time:
        carried["start_time"] = _shift_iso(zt, t0)
    sensor = Sensor(method=options.method, provenance="simulated",
                    platform="ASAM OSI trace", sensors=[{"id": "osi", "kind": "simulator"}],
                    crs=_map_frame_crs(proj, net.header, options),
                    **{"partner": "ASAM OSI simulation", **carried})
    return SimpleNamespace(uniq=uniq, source_ids=[str(int(u)) for u in uniq],
                           sizeless=np.asarray(sizeless, np.int64), t0=t0, participants=participants,
                           map_bytes=map_bytes, net=net, proj=proj, sensor=sensor, inputs=inputs)


class _Sink:
    """The decoders' samples into a :class:`~aveas_format.io.resort.StatesWriter`: a block of
    :data:`_FLOAT_COLS` rows with their object ids and message indices at a time; the earliest time
    of each object on the way (``tmin``)."""

    def __init__(self, writer: StatesWriter) -> None:
        self.writer, self.tmin = writer, {}

    def __call__(self, f: np.ndarray, ids: np.ndarray, msgs: np.ndarray) -> None:
        if not len(f):
            return
        u, inv = np.unique(ids, return_inverse=True)
        first = np.full(len(u), np.inf)
        np.minimum.at(first, inv.reshape(-1), f[:, 0])
        for o, t in zip(u.tolist(), first.tolist()):
            self.tmin[o] = min(self.tmin.get(o, np.inf), t)
        self.writer.add({"oid": np.asarray(ids, np.int64), "msg": np.asarray(msgs, np.int64),
                         **{k: np.ascontiguousarray(f[:, j]) for j, k in enumerate(_FLOAT_COLS)}})


def _boxes_of(bucket: pa.Table, trace: SimpleNamespace) -> Boxes:
    """The boxes of a bucket of whole objects (:func:`_trace`'s samples), in the map's frame."""
    bucket = bucket.combine_chunks()
    ids = bucket.column("oid").to_numpy()
    keep = ~np.isin(ids, trace.sizeless)
    if not keep.all():
        bucket, ids = bucket.filter(pa.array(keep)), ids[keep]
    t, x, y, msgs = (column_numpy(bucket, k) for k in ("t", "x", "y", "msg"))
    # a duplicate names the object id and the frame (0-based message index, the states'
    # source_frame) of its second sample
    boxes = Boxes(np.searchsorted(trace.uniq, ids), t - trace.t0, x, y, source_ids=trace.source_ids,
                  rows=Rows(trace.inputs if len(trace.inputs) == 1 else [], place=msgs, unit="frame")).sort()
    for k in _FLOAT_COLS[3:]:  # the other columns in the boxes' order
        v = column_numpy(bucket, k)[boxes.order]
        boxes[_STATE_OF.get(k, k)] = v.astype(np.float32) if k in _LIGHTS else v
    n = len(boxes)
    for c in ("x", "y", "heading", "vx", "vy"):
        boxes[f"{c}_std"] = np.zeros(n)
    boxes["source_frame"] = msgs[boxes.order]
    _to_map_frame(boxes, trace.proj, trace.net.header)
    return boxes


def _map_frame_crs(proj, header, options: OsiOptions) -> str | None:
    """The recording's CRS where the map has no geoReference: the trace's ``proj_string`` with its
    offset (unless ``--crs`` gives one)."""
    if proj is None or header.geo_reference or options.crs:
        return None
    return _offset_crs(proj[0], proj[1])


def _to_map_frame(boxes: Boxes, proj, header) -> None:
    """The boxes moved from the OSI global frame into the map's (in place). The OSI frame is the
    map's; where the trace's ``proj_string`` differs from the map's geoReference, positions go
    through the projected CRS into the map's frame (directions turned by the grid convergence and
    the frame offset's yaw). Without a geoReference nothing moves (:func:`_map_frame_crs`)."""
    from aveas_format.crs import LocalFrame, crs_equal

    if proj is None or not header.geo_reference or crs_equal(proj[0], header.geo_reference):
        return
    px, py = LocalFrame(proj[0], proj[1], warn=False).to_projected(boxes["x"], boxes["y"])
    boxes["x"], boxes["y"], rot = projected_to_local(px, py, proj[0], header.geo_reference,
                                                     header.offset)
    rot = rot + proj[1][3]
    boxes["heading"] = boxes["heading"] + rot
    boxes["vx"], boxes["vy"] = rotate(boxes["vx"], boxes["vy"], rot)
    boxes["ax"], boxes["ay"] = rotate(boxes["ax"], boxes["ay"], rot)


def _decode_objects(inputs: list[Path], options: OsiOptions, sink: _Sink):
    """The samples of the traces decoded by betterosi, one message object at a time, into
    ``sink``: ``(per-object statics, host ids, the first proj_string and its offset, the findings,
    the earliest time of each object)``."""
    # the floats (_FLOAT_COLS) of each sample (a tuple each, turned into a float64 block every
    # _BLOCK samples: ~110 B per sample, not a Python float per value), its object id and message
    # index apart (typed arrays)
    from aveas_format.converters.common.mcap import mcap_errors

    cols: dict[str, Any] = {"f": [], "id": array("q"), "msg": array("q")}

    def flush() -> None:
        sink(np.asarray(cols["f"], np.float64).reshape(-1, len(_FLOAT_COLS)),
             np.frombuffer(cols["id"], np.int64).copy(), np.frombuffer(cols["msg"], np.int64).copy())
        cols.update(f=[], id=array("q"), msg=array("q"))

    static: dict[int, dict[str, Any]] = {}
    host_ids: set[int] = set()
    proj: tuple[str, tuple[float, float, float, float]] | None = None
    n_msg = 0
    last_t = -math.inf
    found = _Findings()
    for path in inputs:
        # what the bindings raise on bytes that are no message (ValueError, when a field is
        # read), and for an MCAP trace what its reader raises on a damaged file
        errors = (ValueError,) + (mcap_errors() if path.suffix.lower() == ".mcap" else ())
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                for gt in _messages(path, options):
                    t = _get(gt, "timestamp", "seconds", default=0.0) + \
                        _get(gt, "timestamp", "nanos", default=0.0) * 1e-9
                    if getattr(gt, "host_vehicle_id", None) is not None:
                        host_ids.add(int(gt.host_vehicle_id.value))
                    if proj is None and getattr(gt, "proj_string", ""):
                        off = getattr(gt, "proj_frame_offset", None)
                        o = (0.0, 0.0, 0.0, 0.0) if off is None else (
                            _get(off, "position", "x", default=0.0),
                            _get(off, "position", "y", default=0.0), 0.0,
                            _get(off, "yaw", default=0.0))
                        proj = (str(gt.proj_string), o)
                    if t < last_t:
                        found.add("source.osi.time_not_increasing", None, n_msg,
                                  f"timestamp {t:.9g} s is earlier than the previous "
                                  f"message's ({last_t:.9g} s); the states are sorted")
                    last_t = max(last_t, t)
                    for mo in gt.moving_object:
                        _object(mo, t, n_msg, cols, static, found)
                    n_msg += 1
                    if len(cols["f"]) >= _BLOCK:
                        flush()
        except errors as e:
            if isinstance(e, (FormatError, RecordingIOError)):  # located already
                raise
            raise FormatError(f"cannot decode OSI message {n_msg}: {type(e).__name__}: {e}",
                              path=path) from None
    flush()
    return static, host_ids, proj, found, sink.tmin


def _decode_columns(inputs: list[Path], options: OsiOptions, sink: _Sink):
    """What :func:`_decode_objects` does, by the columnar decoder
    (:mod:`aveas_format.converters.osi_columns`); :class:`~aveas_format.converters.common.fastpath.
    FastPathUnsupported` where it does not take the trace (then betterosi decodes it)."""
    import betterosi as b

    from aveas_format.converters.osi_columns import decode_trace

    otypes = {int(m): m.name for m in b.MovingObject.Type}
    vtypes = {int(m): m.name for m in b.MovingObject.VehicleClassification.Type}
    static: dict[int, dict[str, Any]] = {}
    host_ids: set[int] = set()
    proj = None
    n_msg = 0
    last_t = -math.inf
    for path in inputs:
        if path.suffix.lower() == ".osi" and path.stat().st_size == 0:
            raise FormatError("empty OSI trace", path=path)
        n_file = 0
        for ch in decode_trace(path, options.message_type):
            t = ch["t"]
            if len(t):
                if (t < np.maximum.accumulate(np.r_[last_t, t])[:-1]).any():
                    raise FastPathUnsupported("a timestamp going back (a finding)")
                last_t = max(last_t, float(t.max()))
            host_ids |= ch["hosts"]
            if proj is None:
                proj = ch["proj"]
            oid = ch["id"]
            u, first = np.unique(oid, return_index=True)
            new = np.fromiter((o not in static for o in u.tolist()), bool, len(u))
            i = first[new]  # the first sample of each object not seen before
            for o, ot, has_vc, vt, (length, width, height) in zip(
                    u[new].tolist(), ch["otype"][i].tolist(), ch["has_vc"][i].tolist(),
                    ch["vtype"][i].tolist(), ch["dim"][i].tolist()):
                otype = otypes.get(ot, "UNKNOWN")
                vtype = vtypes.get(vt, "UNKNOWN") if has_vc and otype == "VEHICLE" else None
                cls, unknown = _classify(otype, vtype, has_vc)
                if unknown or not (length > 0 and width > 0):
                    raise FastPathUnsupported("an unknown type or a missing size (a finding)")
                static[o] = {"class": cls, "length": length, "width": width,
                             "height": height if height > 0 else None, "osi_type": otype,
                             "lanes": set(), "no_size_msg": 0, "no_size_n": 0}
            lane_obj, lane_id = ch["lanes"]
            if len(lane_obj):
                pairs = np.unique(np.stack([oid[lane_obj], lane_id], axis=1), axis=0)
                for o, lane in pairs.tolist():
                    static[o]["lanes"].add(lane)
            sink(ch["f"], oid, ch["msg"] + n_msg)
            n_file += len(t)
        n_msg += n_file
    return static, host_ids, proj, _Findings(), sink.tmin


def _offset_crs(proj: str, offset: tuple[float, float, float, float]) -> str:
    """The CRS of the OSI frame: the trace's ``proj_string`` with its ``proj_frame_offset``
    (a translation; a rotated frame is refused) folded into the false easting/northing."""
    if not offset[0] and not offset[1] and not offset[3]:
        return proj
    if offset[3]:
        raise FormatError("the trace's proj_frame_offset rotates the frame (yaw "
                          f"{offset[3]!r}) and the map has no <geoReference>: pass --crs")
    from aveas_format.converters.levelx import shifted_crs

    return shifted_crs(proj, offset[0], offset[1])


def _shift_iso(iso: str, seconds: float) -> str:
    from datetime import datetime, timedelta, timezone

    try:
        dt = datetime.fromisoformat(iso.replace("Z", "+00:00")).astimezone(timezone.utc)
    except ValueError:
        return "1970-01-01T00:00:00Z"
    dt = dt + timedelta(seconds=seconds)
    return dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


#: samples kept as Python tuples before they become one float64 block (bounds the import's memory)
_BLOCK = 65536

#: the float columns of the samples (one tuple each), in order
_FLOAT_COLS = ("t", "x", "y", "z", "yaw", "vx", "vy", "ax", "ay", "yaw_rate", "brake", "ind_l",
               "ind_r", "hazard")
#: the states column of each of them (where the name differs) and the light probabilities
_STATE_OF = {"yaw": "heading", "brake": "light_brake_p", "ind_l": "light_indicator_left_p",
             "ind_r": "light_indicator_right_p", "hazard": "light_hazard_p"}
_LIGHTS = ("brake", "ind_l", "ind_r", "hazard")


def _get(obj: Any, *path: str, default: float = math.nan) -> float:
    """A numeric field of nested OSI messages; ``default`` where a message on the way is unset."""
    for name in path:
        obj = getattr(obj, name, None)
        if obj is None:
            return default
    return float(obj)


class _Findings:
    """What the import finds about the trace, one finding per (code, object) with the first
    message index and a count (:func:`aveas_format.errors.report_source` at the end)."""

    def __init__(self) -> None:
        self.first: dict[tuple[str, int | None], list[Any]] = {}

    def add(self, code: str, oid: int | None, msg: int, message: str, count: int = 1) -> None:
        entry = self.first.get((code, oid))
        if entry is None:
            self.first[(code, oid)] = [msg, message, count]
        else:
            entry[2] += count

    def report(self, path: Path | None) -> None:
        for (code, oid), (msg, message, count) in self.first.items():
            report_source(code, message + (f" ({count} times)" if count > 1 else ""),
                          count=count, stacklevel=3, file=str(path) if path else None,
                          message_index=msg, object_id=oid)


#: light states already seen -> their values (an enum's name is looked up once, not per object)
_BRAKE: dict[Any, float] = {}
_INDICATOR: dict[Any, tuple[float, float, float]] = {}


def _brake_value(state: Any) -> float:
    name = _enum_name(state)
    return math.nan if name in ("UNKNOWN", "OTHER") else 0.0 if name == "OFF" else 1.0


def _indicator_values(state: Any) -> tuple[float, float, float]:
    """(left, right, hazard) of an indicator state; NaN where unknown."""
    name = _enum_name(state)
    if name in ("UNKNOWN", "OTHER"):
        return (math.nan,) * 3
    return float(name == "LEFT"), float(name == "RIGHT"), float(name == "WARNING")


def _classify(otype: str, vtype: str | None, has_vc: bool) -> tuple[str, bool]:
    """The class of a moving object of OSI type ``otype`` (vehicle type ``vtype``), and whether
    the types are unknown or unmapped (a finding: class other)."""
    if otype == "PEDESTRIAN":
        cls = "pedestrian"
    elif otype == "ANIMAL":
        cls = "animal"
    elif otype == "VEHICLE":
        cls = VEHICLE_CLASS.get(vtype, "other") if has_vc else "car"
    else:
        cls = "other"
    return cls, otype not in ("PEDESTRIAN", "ANIMAL", "VEHICLE", "OTHER") or (
        vtype is not None and vtype not in VEHICLE_CLASS and vtype != "OTHER")


def _object(mo, t: float, msg: int, cols: dict[str, Any], static: dict[int, dict[str, Any]],
            found: _Findings) -> None:
    oid = int(mo.id.value) if getattr(mo, "id", None) is not None else None
    if oid is None or getattr(mo, "base", None) is None:
        found.add("source.osi.missing_base", oid, msg,
                  f"a moving object without {'id' if oid is None else 'base'} was skipped")
        return
    b = mo.base
    p, o, v, a, r = b.position, b.orientation, b.velocity, b.acceleration, b.orientation_rate
    nan = math.nan
    brake = ind_l = ind_r = hazard = nan
    vc = mo.vehicle_classification
    ls = vc.light_state if vc is not None else None
    if ls is not None:
        bs, ins = ls.brake_light_state, ls.indicator_state
        brake = _BRAKE[bs] if bs in _BRAKE else _BRAKE.setdefault(bs, _brake_value(bs))
        ind_l, ind_r, hazard = (_INDICATOR[ins] if ins in _INDICATOR else
                                _INDICATOR.setdefault(ins, _indicator_values(ins)))
    cols["f"].append((
        t, *((p.x, p.y, p.z) if p is not None else (nan, nan, nan)),
        o.yaw if o is not None else 0.0,
        *((v.x, v.y) if v is not None else (0.0, 0.0)),
        *((a.x, a.y) if a is not None else (nan, nan)),
        r.yaw if r is not None else nan, brake, ind_l, ind_r, hazard))
    cols["id"].append(oid)
    cols["msg"].append(msg)
    d = static.get(oid)
    if d is None:
        otype = _enum_name(mo.type)
        vtype = _enum_name(vc.type) if vc is not None and otype == "VEHICLE" else None
        cls, unknown = _classify(otype, vtype, vc is not None)
        if unknown:
            found.add("source.osi.unknown_type", oid, msg,
                      f"moving object {oid}: type {otype}"
                      + (f", vehicle type {vtype}" if vtype is not None else "")
                      + " has no class of the format: class other")
        static[oid] = d = {"class": cls, "length": None, "width": None, "height": None,
                           "osi_type": otype, "lanes": set(), "no_size_msg": msg, "no_size_n": 0}
    if d["length"] is None:
        length, width, height = (_get(b, "dimension", k) for k in ("length", "width", "height"))
        if length > 0 and width > 0:
            if d["no_size_n"]:
                found.add("source.osi.missing_dimension", oid, d["no_size_msg"],
                          f"moving object {oid} has no positive base.dimension in message "
                          f"{d['no_size_msg']} and {d['no_size_n'] - 1} later ones; the size of "
                          f"message {msg} is used", count=d["no_size_n"])
            d.update(length=length, width=width, height=height if height > 0 else None)
        else:
            d["no_size_n"] += 1
    lanes = mo.assigned_lane_id
    if lanes:
        d["lanes"].update(int(li.value) for li in lanes)
