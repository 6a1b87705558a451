"""The OSI import's columnar decoder: the fields the import reads, from the bytes of many
GroundTruth messages at once (:func:`aveas_format.converters._protowire.walk`), without a Python
object per message or per moving object.

It reads exactly what :func:`aveas_format.converters.osi._object` reads from betterosi's
messages, with the same values where a field or a sub-message is absent (a scalar absent from a
present sub-message is 0, as the bindings give it; an enum value outside the enum counts as its
UNKNOWN) — and gives up (:class:`~aveas_format.converters.common.fastpath.FastPathUnsupported`, the import then
decodes the trace with betterosi) on anything whose handling it would have to re-invent: invalid
wire format (betterosi's error, located, is the one reported), a singular field twice or with
another wire type, a moving object without id or base, a first sample of an object without a
positive size or with an unmapped type, a SensorView without ground truth, a timestamp going back
(those are the import's located findings, made by the betterosi path), an MCAP trace with other
message kinds or encodings on its OSI topics.
"""

from __future__ import annotations

import math
import struct
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.converters import _protowire as pw
from aveas_format.converters._protowire import I64, LEN, VARINT
from aveas_format.converters.common.fastpath import FastPathUnsupported

#: bytes of messages decoded at once (bounds the decoding's memory: the chunk and its field tables,
#: 41 B per field occurrence)
CHUNK_BYTES = 8 << 20


def message_type(path: Path, option: str) -> str:
    """GroundTruth or SensorView, as betterosi resolves it (option, file name, first message)."""
    if option != "auto":
        return option
    import betterosi
    from betterosi import io as bio

    try:
        with open(path, "rb") as f, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = bio._resolve_osi_message_type(f, path, None, betterosi, probe=True)
    except OSError as e:  # betterosi's path reports it, located
        raise FastPathUnsupported(f"message type: {e}") from None
    if t not in ("GroundTruth", "SensorView"):
        raise FastPathUnsupported(f"message type {t}")
    return t


def _sub(F: pw.Fields, number: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(span, start, end) of a singular sub-message field."""
    r = F.select(number, LEN)
    return F.span[r], F.pos[r], F.pos[r] + F.length[r]


def _scalar(F: pw.Fields, buf: np.ndarray, number: int, wire: int, default: float | int,
            dtype) -> np.ndarray:
    """A singular scalar field of every span (``default`` where absent)."""
    r = F.select(number, wire)
    out = np.full(F.n_spans, default, dtype)
    if r.size:
        out[F.span[r]] = (pw.doubles(buf, F.pos[r]) if wire == I64 else
                          F.value[r].view(np.int64))
    return out


def _triples(buf: np.ndarray, n: int, subs: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
             absent: list[tuple[float, float, float]]) -> list[np.ndarray]:
    """Fields 1, 2, 3 (doubles: Vector3d, Orientation3d, Dimension3d) of sub-messages of ``n``
    objects, all kinds at once: for kind ``k`` an ``n x 3`` array, ``absent[k]`` where the
    object has no such sub-message, 0.0 for a field absent from a present one. The common layout
    — up to three distinct double fields with one-byte keys, 9 bytes each — is read straight;
    anything else is walked."""
    start = np.concatenate([s[1] for s in subs])
    length = np.concatenate([s[2] for s in subs]) - start
    vals = np.zeros((len(start), 3))
    ok = (length % 9 == 0) & (length <= 27)
    keys = []
    for j in range(3):
        k = np.where(ok & (length > 9 * j), buf[start + 9 * j], 0)
        ok &= (length <= 9 * j) | np.isin(k, (0x09, 0x11, 0x19))
        keys.append(k)
    ok &= ((keys[0] != keys[1]) | (keys[1] == 0)) & ((keys[0] != keys[2]) | (keys[2] == 0)) & \
        ((keys[1] != keys[2]) | (keys[2] == 0))
    for j, k in enumerate(keys):
        r = np.flatnonzero(ok & (k != 0))
        vals[r, (k[r] >> 3).astype(np.int64) - 1] = pw.doubles(buf, start[r] + 9 * j + 1)
    rest = np.flatnonzero(~ok)
    if rest.size:
        V = pw.walk(buf, start[rest], start[rest] + length[rest])
        vals[rest] = np.stack([_scalar(V, buf, f, I64, 0.0, np.float64) for f in (1, 2, 3)], 1)
    out, k0 = [], 0
    for (sp, _, _), miss in zip(subs, absent):
        a = np.tile(np.asarray(miss, np.float64), (n, 1))
        a[sp] = vals[k0:k0 + len(sp)]
        out.append(a)
        k0 += len(sp)
    return out


def _idents(buf: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """``value`` of Identifier messages (int64; beyond it: unsupported)."""
    v = _scalar(pw.walk(buf, start, end), buf, 1, VARINT, 0, np.int64)
    if (v < 0).any():
        raise FastPathUnsupported("identifier beyond int64")
    return v


#: brake light state -> value; indicator state -> (left, right, hazard) (UNKNOWN/OTHER: NaN)
_NAN = math.nan
_BRAKE = np.array([_NAN, _NAN, 0.0, 1.0, 1.0])
_INDICATOR = np.array([(_NAN,) * 3, (_NAN,) * 3, (0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)],
                      np.float64)


def _enum_lookup(table: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Values outside the enum are its UNKNOWN (as the bindings read them)."""
    return table[np.where((v >= 0) & (v < len(table)), v, 0)]


def decode_chunk(buf: np.ndarray, start: np.ndarray, end: np.ndarray, sensor_view: bool,
                 msg0: int) -> dict[str, Any]:
    """The messages ``buf[start[i]:end[i]]`` (``msg0`` = the trace index of the first): per
    message ``t``, the host ids, the first ``proj``; per moving object (message order, then
    field order) the float columns of ``osi._FLOAT_COLS`` (``f``), ``id``, ``msg``, the type
    columns (``otype``, ``has_vc``, ``vtype``), its dimension (``dim``) and ``lanes`` (object
    index, lane id) pairs."""
    if sensor_view:  # SensorView.global_ground_truth
        span, start, end = _sub(pw.walk(buf, start, end), 7)
        if len(span) != len(start) or len(span) != (span.max(initial=-1) + 1):
            raise FastPathUnsupported("a SensorView without global_ground_truth")
    G = pw.walk(buf, start, end)
    m = len(start)
    span, s, e = _sub(G, 2)  # timestamp
    T = pw.walk(buf, s, e)
    sec = np.zeros(m)
    nanos = np.zeros(m)
    sec[span] = _scalar(T, buf, 1, VARINT, 0, np.int64).astype(np.float64)
    nanos[span] = (_scalar(T, buf, 2, VARINT, 0, np.int64) & 0xFFFFFFFF).astype(np.float64)
    t = sec + nanos * 1e-9
    span, s, e = _sub(G, 3)  # host_vehicle_id
    hosts = set(_idents(buf, s, e).tolist())
    proj = None
    r = G.select(14, LEN)
    r = r[G.length[r] > 0]
    if r.size:
        i = r[0]
        try:
            text = buf[G.pos[i]:G.pos[i] + G.length[i]].tobytes().decode("utf-8", "strict")
        except UnicodeDecodeError:  # betterosi's path reports it, located
            raise FastPathUnsupported(f"message {msg0 + int(G.span[i])}: proj_string is not "
                                      "UTF-8 text") from None
        off = (0.0, 0.0, 0.0, 0.0)
        span20, s20, e20 = _sub(G, 20)  # proj_frame_offset of the same message
        k = np.flatnonzero(span20 == G.span[i])
        if k.size:
            P = pw.walk(buf, s20[k], e20[k])
            yaw = float(_scalar(P, buf, 2, I64, 0.0, np.float64)[0])
            ps, pst, pe = _sub(P, 1)  # position (0, 0 where absent)
            xy = _triples(buf, 1, [(ps, pst, pe)], [(0.0, 0.0, 0.0)])[0][0]
            off = (float(xy[0]), float(xy[1]), 0.0, yaw)
        proj = (text, off)
    r = G.select(5, LEN, singular=False)  # moving_object
    msg = G.span[r]
    M = pw.walk(buf, G.pos[r], G.pos[r] + G.length[r])
    n = len(r)
    out: dict[str, Any] = {"t": t, "hosts": hosts, "proj": proj, "msg": msg + msg0}
    id_span, id_s, id_e = _sub(M, 1)
    base_span, base_s, base_e = _sub(M, 2)
    if len(id_span) != n or len(base_span) != n:
        raise FastPathUnsupported("a moving object without id or base")
    oid = np.empty(n, np.int64)
    oid[id_span] = _idents(buf, id_s, id_e)
    out["id"] = oid
    out["otype"] = _scalar(M, buf, 3, VARINT, 0, np.int64)
    vc_span, vc_s, vc_e = _sub(M, 6)
    C = pw.walk(buf, vc_s, vc_e)
    has_vc = np.zeros(n, bool)
    has_vc[vc_span] = True
    vtype = np.zeros(n, np.int64)
    vtype[vc_span] = _scalar(C, buf, 1, VARINT, 0, np.int64)
    out["has_vc"], out["vtype"] = has_vc, vtype
    ls_span, ls_s, ls_e = _sub(C, 2)
    L = pw.walk(buf, ls_s, ls_e)
    lights = np.full((n, 4), _NAN)
    obj = vc_span[ls_span]
    lights[obj, 0] = _enum_lookup(_BRAKE, _scalar(L, buf, 7, VARINT, 0, np.int64))
    lights[obj, 1:] = _enum_lookup(_INDICATOR, _scalar(L, buf, 1, VARINT, 0, np.int64))
    r = M.select(4, LEN, singular=False)  # assigned_lane_id
    out["lanes"] = (M.span[r], _idents(buf, M.pos[r], M.pos[r] + M.length[r]))
    B = pw.walk(buf, base_s, base_e)
    subs = [_sub(B, k) for k in (1, 2, 3, 4, 5, 6)]
    subs = [(base_span[sp], s, e) for sp, s, e in subs]  # base span -> object
    dim, pos, ori, vel, acc, rate = _triples(
        buf, n, subs, [(_NAN,) * 3, (_NAN,) * 3, (0.0,) * 3, (0.0,) * 3, (_NAN,) * 3, (_NAN,) * 3])
    out["dim"] = dim
    f = np.empty((n, 14))
    f[:, 0] = t[msg]
    f[:, 1:4] = pos
    f[:, 4] = ori[:, 2]
    f[:, 5:7] = vel[:, :2]
    f[:, 7:9] = acc[:, :2]
    f[:, 9] = rate[:, 2]
    f[:, 10:14] = lights
    out["f"] = f
    return out


def _decoded(raws: list[bytes], sensor_view: bool, msg0: int) -> dict[str, Any]:
    """:func:`decode_chunk` of messages given as byte strings."""
    lengths = np.fromiter(map(len, raws), np.int64, len(raws))
    ends = np.cumsum(lengths)
    try:
        return decode_chunk(pw.padded(b"".join(raws)), ends - lengths, ends, sensor_view, msg0)
    except pw.WireError as e:
        raise FastPathUnsupported(f"message {msg0 + e.span}: {e.reason}") from None


def _mcap_chunks(path: Path):
    """The GroundTruth / SensorView messages of an MCAP trace, in chunks, as betterosi reads them
    (its OSI topics, in log-time order); other message kinds and encodings, and a file the MCAP
    reader cannot read (betterosi's path reports it, located): unsupported."""
    from betterosi.mcap_reader import osi_type_name
    from mcap.reader import make_reader

    from aveas_format.converters.common.mcap import mcap_errors, why
    from aveas_format.safeio import check_mcap

    check_mcap(path)
    kind, raws, size, msg0 = None, [], 0, 0
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
            topics = None
            if summary is not None:
                topics = [c.topic for c in summary.channels.values()
                          if osi_type_name(summary.schemas.get(c.schema_id)) is not None] or None
            messages = reader.iter_messages(topics=topics)
        except mcap_errors() as e:
            raise FastPathUnsupported(f"MCAP: {why(e)}") from None
        while True:
            try:
                schema, channel, message = next(messages)
            except StopIteration:
                break
            except mcap_errors() as e:
                raise FastPathUnsupported(f"MCAP: {why(e)}") from None
            t = osi_type_name(schema)
            if (t not in ("GroundTruth", "SensorView") or channel.message_encoding != "protobuf"
                    or schema.encoding != "protobuf" or kind not in (None, t)):
                raise FastPathUnsupported(f"MCAP channel {channel.topic}: {t} ({channel.message_encoding})")
            kind = t
            raws.append(message.data)
            size += len(message.data)
            if size >= CHUNK_BYTES:
                yield _decoded(raws, kind == "SensorView", msg0)
                msg0 += len(raws)
                raws, size = [], 0
    if raws:
        yield _decoded(raws, kind == "SensorView", msg0)


def decode_trace(path: Path, option: str):
    """The chunks (:func:`decode_chunk`) of a binary .osi or an MCAP trace, in order."""
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        yield from _mcap_chunks(path)
        return
    if suffix != ".osi":
        raise FastPathUnsupported("not a binary .osi or .mcap trace")
    sensor_view = message_type(path, option) == "SensorView"
    size = path.stat().st_size
    with open(path, "rb") as fh:
        off = msg = 0
        while off < size:  # a chunk: the whole messages of the next CHUNK_BYTES (at least one)
            fh.seek(off)
            block = fh.read(CHUNK_BYTES)
            starts, pos = [], 0
            while pos + 4 <= len(block):
                (n,) = struct.unpack_from("<I", block, pos)
                if pos + 4 + n > len(block):
                    break
                starts.append(pos + 4)
                pos += 4 + n
            if not starts:  # a message longer than a chunk, or a truncated trace
                if size - off < 4 or off + 4 + struct.unpack_from("<I", block)[0] > size:
                    raise FastPathUnsupported(f"message {msg} truncated (the framing check reports it)")
                fh.seek(off)
                block = fh.read(4 + struct.unpack_from("<I", block)[0])
                starts, pos = [4], len(block)
            st = np.array(starts, np.int64)
            ends = np.r_[st[1:] - 4, pos]
            try:
                yield decode_chunk(pw.padded(block[:pos]), st, ends, sensor_view, msg)
            except pw.WireError as e:
                raise FastPathUnsupported(f"message {msg + e.span}: {e.reason}") from None
            off += pos
            msg += len(starts)
