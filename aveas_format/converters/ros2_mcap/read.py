"""Reading the MCAP files of one recording: which topics to read (``_select_topics``) and one
pass over their messages (``read_topics``), each decoded and handed to its per-message reader."""

from __future__ import annotations

import warnings
from pathlib import Path

from aveas_format.converters.common.mcap import mcap_errors, why
from aveas_format.converters.ros2_mcap.decode import DecoderError, Decoders, channels, decode_errors
from aveas_format.converters.ros2_mcap.messages import (
    OBJECT_READERS,
    read_navsatfix,
    read_odometry,
    read_tf,
    header_stamp,
)
from aveas_format.converters.ros2_mcap.options import (
    OBJECT_TYPES,
    PREFERRED_FIX,
    PREFERRED_ODOM,
    T_FIX,
    T_ODOM,
    T_TF,
    Ros2McapOptions,
    canonical_type,
)
from aveas_format.converters.ros2_mcap.rows import ObjectSink
from aveas_format.converters.ros2_mcap.tree import TransformSamples
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.resort import StatesWriter
from aveas_format.safeio import check_mcap


def _pick(types: dict[str, str], wanted: str, given: str | None, preferred: tuple[str, ...],
          path: Path, what: str) -> str | None:
    """The topic of type ``wanted`` to read: ``given`` (checked; "" = none), else the only one,
    else the first of ``preferred`` present, else the first by name."""
    if given == "":
        return None
    if given is not None:
        if given not in types:
            raise FormatError(f"{what} topic {given!r} not in the file; topics: {sorted(types)}",
                              path=path)
        if types[given] != wanted:
            raise FormatError(f"topic {given!r} has type {types[given]}, expected {wanted}", path=path)
        return given
    cands = sorted(t for t, ty in types.items() if ty == wanted)
    if len(cands) == 1:
        return cands[0]
    for p in preferred:
        if p in cands:
            return p
    return cands[0] if cands else None




def _select_topics(paths: list[Path], opts: Ros2McapOptions):
    """Every file's topics (each pre-scanned by ``safeio.check_mcap``) and the ones to read:
    (types, object topics, odometry topic, NavSatFix topic, tf topics)."""
    types: dict[str, str] = {}
    for p in paths:
        if not p.is_file():
            raise RecordingIOError("input not found", path=p)
        check_mcap(p)  # bounded pre-scan: no record or chunk may claim more than the file holds
        types.update(channels(p))
    first = paths[0]
    if opts.object_topics is not None:
        for t in opts.object_topics:
            if t not in types:
                raise FormatError(f"object topic {t!r} not in the file; topics: {sorted(types)}",
                                  path=first)
            if types[t] not in OBJECT_TYPES:
                raise FormatError(f"topic {t!r} has type {types[t]}; supported object types: "
                                  f"{', '.join(OBJECT_TYPES)}", path=first)
        obj_topics = list(opts.object_topics)
    else:
        obj_topics = sorted(t for t, ty in types.items() if ty in OBJECT_TYPES)
    odom = _pick(types, T_ODOM, opts.odometry_topic, PREFERRED_ODOM, first, "odometry")
    fix = _pick(types, T_FIX, opts.navsatfix_topic, PREFERRED_FIX, first, "NavSatFix")
    tf_topics = [t for t in opts.tf_topics if types.get(t) == T_TF]
    if not obj_topics and odom is None and fix is None:
        from aveas_format.converters.common.mcap import viewing_export_note

        note = viewing_export_note(first)
        if note:
            raise FormatError(f"not a ROS 2 recording: {note}", path=first)
        raise FormatError("no object, odometry or NavSatFix topics found; topics: "
                          f"{ {t: ty for t, ty in sorted(types.items())} }", path=first)
    return types, obj_topics, odom, fix, tf_topics


def read_topics(paths: list[Path], opts: Ros2McapOptions, writer: StatesWriter):
    """One pass over the wanted topics of every file: (types, object topics, odometry topic,
    NavSatFix topic, the object rows (an :class:`ObjectSink` that flushed them into ``writer``),
    transform samples, odometry samples, NavSatFix samples)."""
    from mcap.reader import make_reader

    types, obj_topics, odom, fix, tf_topics = _select_topics(paths, opts)
    topic_index = {t: i for i, t in enumerate(obj_topics)}
    wanted = set(obj_topics) | set(tf_topics) | {t for t in (odom, fix) if t}

    sink = ObjectSink(writer, len(obj_topics) > 1)
    edges = TransformSamples()
    ego_odom: dict[str, list] = {"t": [], "pose": [], "pcov": [], "twist": [], "tcov": [],
                                 "frame": [], "child": []}
    ego_fix: dict[str, list] = {"t": [], "lonlat": [], "cov": []}
    counters: dict[str, int] = {}
    zero_stamps = 0
    for path in paths:
        factory = Decoders()
        try:
            f = open(path, "rb")
        except OSError as e:
            raise RecordingIOError(f"cannot read: {e.strerror}", path=path) from None
        with f:
            reader = make_reader(f)
            it = reader.iter_messages(topics=sorted(wanted & set(channels(path))))
            while True:
                try:
                    schema, ch, m = next(it)
                except StopIteration:
                    break
                except mcap_errors() as e:
                    raise FormatError(f"corrupt MCAP after {sum(counters.values())} messages: "
                                      f"{why(e)}", path=path) from None
                topic = ch.topic
                mi = counters.get(topic, 0)
                counters[topic] = mi + 1
                where = f"topic {topic} message {mi}"
                try:
                    decode = factory.decoder(schema, ch.message_encoding, path)
                except DecoderError as e:
                    raise FormatError(f"{where}: cannot decode: {e}", path=path) from None
                try:
                    msg = decode(m.data)
                except decode_errors() as e:
                    raise FormatError(f"{where}: cannot decode: {type(e).__name__}: {e}",
                                      path=path) from None
                ty = canonical_type(schema.name)
                try:
                    if ty in OBJECT_READERS and topic in topic_index:
                        t_ns, ok = header_stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        OBJECT_READERS[ty](msg, sink.rows, t_ns, topic_index[topic], mi, opts)
                        sink.maybe_flush()
                    elif ty == T_TF:
                        read_tf(msg, edges, topic, m.log_time)
                    elif ty == T_ODOM and topic == odom:
                        t_ns, ok = header_stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        read_odometry(msg, ego_odom, t_ns)
                    elif ty == T_FIX and topic == fix:
                        if int(msg.status.status) < 0:  # no fix
                            continue
                        t_ns, ok = header_stamp(msg.header, m.log_time)
                        zero_stamps += not ok
                        read_navsatfix(msg, ego_fix, t_ns)
                except (AttributeError, TypeError, ValueError, IndexError) as e:
                    raise FormatError(f"{where}: malformed {ty}: {e}", path=path) from None
    if zero_stamps:
        warnings.warn(f"{zero_stamps} messages have a zero header.stamp; their log time is used",
                      stacklevel=3)
    sink.flush()
    return types, obj_topics, odom, fix, sink, edges, ego_odom, ego_fix
