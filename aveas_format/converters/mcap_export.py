"""Recording -> MCAP for Foxglove (visual inspection of the scene moving over its lanes).

``aveas-format export --to mcap REC -o rec.mcap`` writes an MCAP file with Protobuf messages of the
Foxglove schemas (PyPI ``foxglove-schemas-protobuf``, ``mcap``), log times = ``start_time`` +
``time``:

- ``/scene`` (``foxglove.SceneUpdate``), one message per distinct ``time``: per participant an
  entity ``participant/<id>`` in frame ``map`` (the recording's local frame) with a cube at the
  footprint centre (z lifted by half the height), yaw = ``heading``, size length x width x height,
  coloured by class, and a text label ``<id> <class>``; the entities' lifetime is 1.5 sample
  periods, so a participant disappears when its trajectory ends.
- ``/map`` (``foxglove.SceneUpdate``), one message at the start: the lane borders of the OpenDRIVE
  map as line strips (entity ``map/lanes``, drivable lanes white, others grey), lifetime forever.
- ``/unobserved`` (``foxglove.SceneUpdate``): the unobserved regions as closed red outlines for
  their validity intervals.
- ``/locations`` (``foxglove.LocationFix``): each participant's WGS 84 position per sample
  (``frame_id`` = participant id), for the Map panel; ``/origin``: the recording's location.

Open the file in Foxglove, add a 3D panel (display frame ``map``) and a Map panel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.converters.registry import ConverterOptions, converter

#: class -> RGBA (0..1)
CLASS_COLOURS: dict[str, tuple[float, float, float, float]] = {
    "car": (0.20, 0.55, 0.95, 0.85), "van": (0.10, 0.75, 0.85, 0.85),
    "truck": (0.95, 0.55, 0.10, 0.85), "bus": (0.95, 0.80, 0.10, 0.85),
    "trailer": (0.80, 0.45, 0.20, 0.85), "motorcycle": (0.75, 0.25, 0.85, 0.85),
    "bicycle": (0.30, 0.85, 0.30, 0.85), "pedestrian": (0.95, 0.25, 0.35, 0.9),
    "mobility_device": (0.55, 0.90, 0.45, 0.85), "pushable_pullable": (0.65, 0.65, 0.30, 0.85),
    "railvehicle": (0.55, 0.35, 0.25, 0.85), "animal": (0.60, 0.40, 0.10, 0.85),
    "other": (0.70, 0.70, 0.70, 0.85),
}


#: states encoded at once (bounds the memory of the encoding: ~3 kB per state)
BATCH_STATES = 25_000


class McapExportOptions(ConverterOptions):
    lane_step_m: float = 2.0
    """Sampling step of the lane borders (m)."""
    every: int = 1
    """Write every n-th time step of ``/scene`` (1 = all)."""
    locations: bool = True
    """Write ``/locations`` (one LocationFix per participant and sample)."""
    compression: str = "zstd"
    """Chunk compression: zstd, lz4 or none."""


def _file_descriptor_set(message_class) -> bytes:
    """The FileDescriptorSet (the MCAP protobuf schema) of a message class and its imports."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    fds = FileDescriptorSet()
    seen: set[str] = set()
    stack = [message_class.DESCRIPTOR.file]
    while stack:
        fd = stack.pop()
        if fd.name in seen:
            continue
        seen.add(fd.name)
        stack.extend(fd.dependencies)
        fd.CopyToProto(fds.file.add())
    return fds.SerializeToString()


def _ts(msg_field, ns: int) -> None:
    msg_field.seconds = ns // 1_000_000_000
    msg_field.nanos = ns % 1_000_000_000


@converter("mcap", direction="export", options=McapExportOptions,
           description="MCAP with Foxglove SceneUpdate boxes, lane lines and LocationFix",
           requires=("mcap", "foxglove_schemas_protobuf", "google.protobuf"), extra="mcap")
def export_mcap(rec, output: Path, *, options: McapExportOptions) -> list[Path]:
    from aveas_format.safeio import write_chunks_atomic

    return [write_chunks_atomic(Path(output), _mcap_chunks(rec, options))]


class _Drain:
    """The output stream of the MCAP writer, handed on in pieces (:meth:`drain`) so that the file
    is written while it is built (``mcap`` asks the stream only to ``write`` and ``tell``)."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.pos = 0

    def write(self, data) -> int:
        self.parts.append(bytes(data))
        self.pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def drain(self) -> bytes:
        out = b"".join(self.parts)
        self.parts = []
        return out


def _mcap_chunks(rec, options: McapExportOptions):
    """The MCAP file's bytes, a batch of states at a time (what :func:`export_mcap` writes)."""
    import shapely

    # the [mcap] extra: checked by the registry (requires=) before this runs
    from foxglove_schemas_protobuf.Color_pb2 import Color
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from mcap.writer import CompressionType, Writer

    from aveas_format._version import __version__
    from aveas_format.schema.metadata import timestamp_ns

    t0 = timestamp_ns(rec.meta.start_time)
    buf = _Drain()
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE}[options.compression]
    w = Writer(buf, compression=comp)
    w.start(profile="", library=f"aveas-format {__version__}")
    scene_schema = w.register_schema("foxglove.SceneUpdate", "protobuf", _file_descriptor_set(SceneUpdate))
    fix_schema = w.register_schema("foxglove.LocationFix", "protobuf", _file_descriptor_set(LocationFix))
    ch_scene = w.register_channel("/scene", "protobuf", scene_schema)
    ch_map = w.register_channel("/map", "protobuf", scene_schema)
    ch_loc = w.register_channel("/locations", "protobuf", fix_schema) if options.locations else None
    ch_origin = w.register_channel("/origin", "protobuf", fix_schema)
    w.add_metadata("aveas", {"recording_id": rec.meta.recording_id, "crs": rec.meta.crs,
                             "start_time": rec.meta.start_time, "frame": "map"})

    # ---- map lanes ----------------------------------------------------------------------------
    up = SceneUpdate()
    ent = up.entities.add()
    _ts(ent.timestamp, t0)
    ent.frame_id = "map"
    ent.id = "map/lanes"
    polys, drivable = [], set()
    if rec.map_source is not None:
        from shapely.errors import GEOSException

        try:
            polys = rec.map.lane_polygons(step=options.lane_step_m)
            drivable = {(r, sec, lid) for r, sec, lid, _ in rec.map.lane_polygons(
                step=options.lane_step_m * 10, drivable_only=True)}
        except (ValueError, GEOSException) as e:  # a map the engine cannot read (MapError) or
            # sample: the boxes without lanes, said (anything else propagates)
            import warnings

            warnings.warn(f"mcap export: the map's lanes are left out: {e}", stacklevel=2)
    for road, sec, lid, poly in polys:
        line = ent.lines.add()
        line.type = LinePrimitive.LINE_LOOP
        line.thickness = 0.12
        line.pose.orientation.w = 1.0
        c = (0.95, 0.95, 0.95, 0.9) if (road, sec, lid) in drivable else (0.5, 0.5, 0.5, 0.7)
        line.color.CopyFrom(Color(r=c[0], g=c[1], b=c[2], a=c[3]))
        for x, y in np.asarray(shapely.get_coordinates(poly.exterior))[:-1]:
            pt = line.points.add()
            pt.x, pt.y = float(x), float(y)
    w.add_message(ch_map, t0, up.SerializeToString(), t0)

    # ---- unobserved regions -------------------------------------------------------------------
    if rec.unobserved is not None and rec.unobserved.num_rows:
        ch_un = w.register_channel("/unobserved", "protobuf", scene_schema)
        for r in rec.unobserved.to_pylist():
            g = shapely.from_wkb(r["geometry"])
            u = SceneUpdate()
            e = u.entities.add()
            ns = t0 + int(round(r["time_start"] * 1e9))
            _ts(e.timestamp, ns)
            e.frame_id = "map"
            e.id = f"unobserved/{r['region_id']}"
            dur = int(round((r["time_end"] - r["time_start"]) * 1e9))
            _ts(e.lifetime, max(dur, 1))
            for part in getattr(g, "geoms", [g]):
                line = e.lines.add()
                line.type = LinePrimitive.LINE_LOOP
                line.thickness = 0.2
                line.pose.orientation.w = 1.0
                line.color.CopyFrom(Color(r=1.0, g=0.2, b=0.2, a=0.8))
                for x, y in np.asarray(shapely.get_coordinates(part.exterior))[:-1]:
                    pt = line.points.add()
                    pt.x, pt.y = float(x), float(y)
            w.add_message(ch_un, ns, u.SerializeToString(), ns)

    # ---- boxes ----------------------------------------------------------------------------------
    p = rec.participants
    s = rec.states
    info = {}
    hcol = p.column("height").to_pylist() if "height" in p.column_names else [None] * p.num_rows
    for q, cls, ln, wd, hh in zip(p.column("participant_id").to_pylist(),
                                  p.column("class").cast("string").to_pylist(),
                                  p.column("length").to_pylist(), p.column("width").to_pylist(), hcol):
        info[q] = (cls, ln, wd, hh if hh else 1.5)
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x, y, h = (s.column(c).to_numpy() for c in ("x", "y", "heading"))
    z = (np.nan_to_num(s.column("z").to_numpy(zero_copy_only=False).astype(float))
         if "z" in s.column_names else np.zeros(len(t)))
    times, inv = np.unique(t, return_inverse=True)
    period = float(np.median(np.diff(times))) if len(times) > 1 else 1.0 / rec.meta.nominal_rate_hz
    life = int(round(1.5 * period * max(options.every, 1) * 1e9))
    steps = np.arange(0, len(times), max(options.every, 1))
    order = np.argsort(inv, kind="stable")
    order = order[np.isin(inv[order], steps)] if options.every > 1 else order
    bounds = np.r_[np.searchsorted(inv[order], steps), len(order)]
    step_ns = t0 + np.round(times[steps] * 1e9).astype(np.int64)
    ids = list(info)
    rows = np.searchsorted(np.asarray(ids), pid[order]) if ids == sorted(ids) else \
        np.asarray([ids.index(int(q)) for q in pid[order]])
    k0 = 0
    while k0 < len(steps):  # batches of about BATCH_STATES states: bounded memory
        k1 = int(np.searchsorted(bounds, bounds[k0] + BATCH_STATES, side="right"))
        k1 = min(max(k1 - 1, k0 + 1), len(steps))
        a, z1 = bounds[k0], bounds[k1]
        o = order[a:z1]
        scenes = _scene_updates(info, rows[a:z1], np.repeat(step_ns[k0:k1], np.diff(bounds[k0:k1 + 1])),
                                life, x[o], y[o], z[o], h[o], bounds[k0:k1 + 1] - a)
        add_messages(w, ch_scene, step_ns[k0:k1], scenes)
        yield buf.drain()
        k0 = k1

    # ---- geo --------------------------------------------------------------------------------------
    loc = rec.meta.location
    fix = LocationFix(latitude=loc.lat, longitude=loc.lon, altitude=loc.alt or 0.0, frame_id="origin")
    _ts(fix.timestamp, t0)
    w.add_message(ch_origin, t0, fix.SerializeToString(), t0)
    if ch_loc is not None:
        lon, lat = s.column("lon").to_numpy(), s.column("lat").to_numpy()
        o = np.argsort(t, kind="stable")
        ns = t0 + np.round(t[o] * 1e9).astype(np.int64)
        ids_arr = np.asarray(ids)
        prow = np.searchsorted(ids_arr, pid[o]) if ids == sorted(ids) else \
            np.asarray([ids.index(int(q)) for q in pid[o]])
        for a in range(0, len(o), BATCH_STATES):
            sl = slice(a, a + BATCH_STATES)
            add_messages(w, ch_loc, ns[sl], _location_fixes(info, prow[sl], ns[sl], lat[o[sl]], lon[o[sl]]))
            yield buf.drain()
    w.finish()
    yield buf.drain()


# ---- many messages into the MCAP writer at once ---------------------------------------------------

def add_messages(w, channel: int, times: np.ndarray, data) -> None:
    """Messages of one channel (log time = publish time = ``times``, ns; ``data``: a
    :class:`~aveas_format.converters._protowire.Ragged` of their bytes), the file exactly as
    ``w.add_message`` one by one writes it: the records are built with numpy and appended to the
    writer's chunk one chunk at a time, the chunk finished where ``add_message`` finishes it (its
    size passes ``chunk_size``). ``mcap``'s writer spends ~5 us of Python per message otherwise,
    most of the export's time. Uses the writer's private state (mcap 1.x); where it differs, the
    messages go through ``add_message``."""
    cb = getattr(w, "_Writer__chunk_builder", None)
    stats = getattr(w, "_Writer__statistics", None)
    limit = getattr(w, "_Writer__chunk_size", None)
    finish = getattr(w, "_Writer__maybe_finalize_chunk", None)
    if (cb is None or stats is None or limit is None or finish is None or
            not hasattr(cb, "record_writer") or not hasattr(cb, "message_indices")):
        for t, d in zip(np.asarray(times).tolist(), data.tolist()):
            w.add_message(channel, t, d, t)
        return
    from aveas_format.converters import _protowire as pw

    n = data.n
    if n == 0:
        return
    times = np.asarray(times, np.int64)
    head = np.zeros(n, dtype=[("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"),
                              ("log", "<u8"), ("pub", "<u8")])  # a Message record's header
    head["op"], head["len"], head["ch"] = 0x05, 22 + data.lengths, channel
    head["log"] = head["pub"] = times
    rec = pw.concat(pw.Ragged.fixed(head.view(np.uint8).reshape(n, -1)), data)
    off = rec.offsets()
    i = 0
    while i < n:
        start = cb.count
        # the first message after which the chunk is larger than the limit ends this chunk
        j = min(int(np.searchsorted(off, off[i] + limit - start, side="right")), n)
        t = times[i:j]
        lo, hi = int(t.min()), int(t.max())
        stats.message_start_time = lo if stats.message_count == 0 else min(lo, stats.message_start_time)
        stats.message_end_time = max(hi, stats.message_end_time)
        stats.channel_message_counts[channel] += j - i
        stats.message_count += j - i
        cb.message_start_time = lo if cb.num_messages == 0 else min(lo, cb.message_start_time)
        cb.message_end_time = max(hi, cb.message_end_time)
        index = cb.message_indices.get(channel)
        if not isinstance(index, _MessageIndex):
            index = cb.message_indices[channel] = _MessageIndex(channel, index.records if index else [])
        index.add(t, start + off[i:j] - off[i])
        cb.num_messages += j - i
        cb.record_writer.write(rec.data[off[i]:off[j]].tobytes())
        finish()
        i = j


class _MessageIndex:
    """A chunk's message index of one channel (mcap's ``MessageIndex`` record), its entries
    kept as arrays and written at once."""

    def __init__(self, channel_id: int, records: list) -> None:
        self.channel_id = channel_id
        self.parts = [np.asarray(records, np.uint64).reshape(-1, 2)]

    @property
    def records(self) -> list:
        return [tuple(r) for r in np.concatenate(self.parts).tolist()]

    def add(self, times: np.ndarray, offsets: np.ndarray) -> None:
        self.parts.append(np.column_stack([times, offsets]).astype(np.uint64))

    def write(self, stream) -> None:
        from mcap.opcode import Opcode

        body = np.concatenate(self.parts).astype("<u8").tobytes()
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(body))
        stream.write(body)
        stream.finish_record()


# ---- the per-state messages, encoded from columns (converters/_protowire.py) --------------------

def _numbers(message_class) -> dict[str, int]:
    """Field name -> field number of a protobuf message class (from its descriptor)."""
    return {f.name: f.number for f in message_class.DESCRIPTOR.fields}


def _time(field: int, ns: np.ndarray):
    """A google.protobuf.Timestamp / Duration field (seconds 1, nanos 2) of nanoseconds."""
    from aveas_format.converters import _protowire as pw

    sec, nanos = np.divmod(np.asarray(ns, np.int64), 1_000_000_000)
    return pw.f_message(field, pw.concat(pw.f_varint(1, sec, True), pw.f_varint(2, nanos, True)))


def _vec(field: int, *xyz: np.ndarray, names: str = "xyz"):
    """A foxglove Vector3 / Quaternion / Color field (doubles 1, 2, ... in ``names`` order)."""
    from aveas_format.converters import _protowire as pw

    return pw.f_message(field, pw.concat(*(pw.f_double(k + 1, v, True) for k, v in enumerate(xyz))))


def _colour(field: int, classes: list[str]):
    c = np.array([CLASS_COLOURS.get(k, CLASS_COLOURS["other"]) for k in classes], float)
    return _vec(field, *c.T)


def _scene_updates(info: dict, rows: np.ndarray, ns: np.ndarray, life: int, x, y, z, h,
                   bounds: np.ndarray):
    """The ``foxglove.SceneUpdate`` of each time step: per state an entity with a cube and a
    label (what :func:`export_mcap`'s docstring says), the states of step ``k`` being
    ``bounds[k]:bounds[k+1]``; ``rows`` = each state's participant (index into ``info``)."""
    from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
    from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive

    from aveas_format.converters import _protowire as pw

    E, C, T = _numbers(SceneEntity), _numbers(CubePrimitive), _numbers(TextPrimitive)
    P, K = _numbers(Pose), _numbers(KeyValuePair)
    ids = list(info)
    cls = [info[q][0] for q in ids]
    size = np.array([info[q][1:4] for q in ids], float)
    n, m = len(rows), len(ids)
    # per participant, then per state (take)
    ent_id = pw.take(pw.f_strings(E["id"], [f"participant/{q}" for q in ids]), rows)
    meta = pw.take(pw.f_message(E["metadata"], pw.concat(pw.f_strings(K["key"], ["class"] * m),
                                                         pw.f_strings(K["value"], cls))), rows)
    cube_size = pw.take(_vec(C["size"], *size.T), rows)
    cube_colour = pw.take(_colour(C["color"], cls), rows)
    label = pw.take(pw.f_strings(T["text"], [f"{q} {k}" for q, k in zip(ids, cls)]), rows)
    hh = size[rows, 2]
    zero = np.zeros(n)
    cube = pw.concat(
        pw.f_message(C["pose"], pw.concat(
            _vec(P["position"], x, y, z + hh / 2),
            _vec(P["orientation"], zero, zero, np.sin(h / 2), np.cos(h / 2)))),
        cube_size, cube_colour)
    text = pw.concat(
        pw.f_message(T["pose"], pw.concat(_vec(P["position"], x, y, z + hh + 0.5),
                                          _vec(P["orientation"], zero, zero, zero, zero + 1))),
        pw.f_varint(T["billboard"], np.ones(n, np.int64)),
        pw.f_double(T["font_size"], np.full(n, 14.0)),
        pw.f_varint(T["scale_invariant"], np.ones(n, np.int64)),
        _vec(T["color"], zero + 1, zero + 1, zero + 1, zero + 1), label)
    entity = pw.concat(  # in field-number order, as protobuf writes them
        _time(E["timestamp"], ns), pw.f_strings(E["frame_id"], ["map"] * n), ent_id,
        _time(E["lifetime"], np.full(n, life)), meta, pw.f_message(E["cubes"], cube),
        pw.f_message(E["texts"], text))
    return pw.group(pw.f_message(_numbers(SceneUpdate)["entities"], entity), bounds)


def _location_fixes(info: dict, rows: np.ndarray, ns: np.ndarray, lat, lon):
    """One ``foxglove.LocationFix`` per state: latitude, longitude, the participant id as
    ``frame_id``, the class colour, the timestamp."""
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix

    from aveas_format.converters import _protowire as pw

    F = _numbers(LocationFix)
    ids = list(info)
    colour = pw.take(_colour(F["color"], [info[q][0] for q in ids]), rows)
    frame = pw.take(pw.f_strings(F["frame_id"], [str(int(q)) for q in ids]), rows)
    return pw.concat(pw.f_double(F["latitude"], lat, True), pw.f_double(F["longitude"], lon, True),
                     _time(F["timestamp"], ns), frame, colour)


__all__ = ["CLASS_COLOURS", "export_mcap"]
