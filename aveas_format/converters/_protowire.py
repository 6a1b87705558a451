"""Protocol Buffers wire format from columns: many messages of one layout encoded at once.

The OSI and Foxglove exports write one small message per state (an ``osi3.MovingObject``, a
``foxglove.SceneEntity``). Building a message object per state in the Python bindings and
serialising it costs more than everything else of the export (``benchmarks/bench_interop.py``
measures that floor). Here the bytes are built from the columns with numpy instead, by the
encoding rules of https://protobuf.dev/programming-guides/encoding/: a field is its key (field
number << 3 | wire type, a varint) and its value — a varint (integers, enums, bools), 8 or 4
little-endian bytes (double, float), or a varint length and the bytes (strings, sub-messages).

A column of ``n`` byte strings is a :class:`Ragged` (flat bytes + per-row lengths); fields are
:class:`Ragged` columns concatenated row by row (:func:`concat`); a repeated sub-message of
consecutive rows is :func:`group`. Every field is written (proto2 ``optional`` fields set, as the
bindings write what they are given); where a value is absent for some rows, :func:`keep` drops it
from those rows. Decoders read the result as they read the bindings' output (the OSI and MCAP
tests decode it with the bindings).
"""

from __future__ import annotations

import numpy as np

from aveas_format.converters.common.fastpath import FastPathUnsupported

VARINT, I64, LEN, I32 = 0, 1, 2, 5


class Ragged:
    """``n`` byte strings: ``data`` (uint8, all rows' bytes in order) and ``lengths`` (int64)."""

    def __init__(self, data: np.ndarray, lengths: np.ndarray) -> None:
        self.data = data
        self.lengths = lengths

    @property
    def n(self) -> int:
        return len(self.lengths)

    def offsets(self) -> np.ndarray:
        return np.r_[0, np.cumsum(self.lengths)]

    def tolist(self) -> list[bytes]:
        raw = self.data.tobytes()
        off = self.offsets().tolist()
        return [raw[a:b] for a, b in zip(off[:-1], off[1:])]

    @classmethod
    def fixed(cls, matrix: np.ndarray) -> Ragged:
        """Rows of equal width (an ``n x w`` uint8 matrix)."""
        m = np.ascontiguousarray(matrix, np.uint8)
        return cls(m.reshape(-1), np.full(m.shape[0], m.shape[1], np.int64))

    @classmethod
    def const(cls, value: bytes, n: int) -> Ragged:
        """The same bytes in every row."""
        return cls.fixed(np.tile(np.frombuffer(value, np.uint8), (n, 1)))


def key(field: int, wire: int) -> bytes:
    return varint_bytes(field << 3 | wire)


def varint_bytes(v: int) -> bytes:
    out = bytearray()
    v &= (1 << 64) - 1  # negative int64: two's complement, 10 bytes
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def varints(values: np.ndarray) -> Ragged:
    """Each value (integers; negative ones as 64-bit two's complement) as a varint."""
    v = np.asarray(values).astype(np.int64).view(np.uint64)
    n = len(v)
    top = int(v.max()) if n else 0
    if top < 0x80:  # one byte each (keys, enums, short lengths): the common case
        return Ragged.fixed(v.astype(np.uint8).reshape(-1, 1))
    width = (top.bit_length() + 6) // 7
    nbytes = np.ones(n, np.int64)
    for k in range(1, width):
        nbytes += (v >> np.uint64(7 * k)) > 0
    cols = np.arange(width)
    mat = ((v[:, None] >> (np.uint64(7) * cols.astype(np.uint64))) & np.uint64(0x7F)).astype(np.uint8)
    mat |= np.where(cols[None, :] < (nbytes[:, None] - 1), 0x80, 0).astype(np.uint8)
    return Ragged(mat[cols[None, :] < nbytes[:, None]], nbytes)


def _with_key(field: int, wire: int, body: Ragged) -> Ragged:
    return concat(Ragged.const(key(field, wire), body.n), body)


def f_varint(field: int, values: np.ndarray, proto3: bool = False) -> Ragged:
    """An integer / enum / bool field in every row (``proto3``: absent where 0, as proto3
    writers leave a scalar at its default out)."""
    r = _with_key(field, VARINT, varints(values))
    return keep(r, np.asarray(values) != 0) if proto3 else r


def f_double(field: int, values: np.ndarray, proto3: bool = False) -> Ragged:
    """A double field in every row (``proto3``: absent where 0.0)."""
    v = np.ascontiguousarray(np.asarray(values, "<f8"))
    k = np.frombuffer(key(field, I64), np.uint8)
    r = Ragged.fixed(np.hstack([np.tile(k, (len(v), 1)), v.view(np.uint8).reshape(-1, 8)]))
    return keep(r, v.view(np.uint64) != 0) if proto3 else r  # -0.0 is written, as protobuf does


def f_float(field: int, values: np.ndarray) -> Ragged:
    v = np.ascontiguousarray(np.asarray(values, "<f4"))
    k = np.frombuffer(key(field, I32), np.uint8)
    return Ragged.fixed(np.hstack([np.tile(k, (len(v), 1)), v.view(np.uint8).reshape(-1, 4)]))


def f_message(field: int, body: Ragged) -> Ragged:
    """A sub-message (or string / bytes) field: key, length, the bytes."""
    return concat(Ragged.const(key(field, LEN), body.n), varints(body.lengths), body)


def f_strings(field: int, values: list[str]) -> Ragged:
    raw = [s.encode() for s in values]
    body = Ragged(np.frombuffer(b"".join(raw), np.uint8).copy(),
                  np.fromiter(map(len, raw), np.int64, len(raw)))
    return f_message(field, body)


#: a cached ``arange``, sliced as a view (int64: numpy indexes with intp, a narrower index would be
#: converted on every gather)
_IOTA = np.arange(0, dtype=np.int64)
#: the longest range kept (64 MB: a batch's gathers fit); longer ones are made per call
_IOTA_MAX = 1 << 23


def _ragged_index(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The byte positions ``starts[i] + 0 .. starts[i] + lengths[i] - 1`` of every row, in order
    (the gather / scatter index of a ragged copy): one repeat and one in-place add of a cached
    ``arange`` (a view: no new range per call)."""
    global _IOTA
    total = int(lengths.sum())
    idx = np.repeat(starts - np.r_[0, np.cumsum(lengths)][:-1], lengths)
    if total > _IOTA_MAX:
        return idx + np.arange(total)
    if len(_IOTA) < total:
        _IOTA = np.arange(min(max(total, 2 * len(_IOTA)), _IOTA_MAX), dtype=np.int64)
    idx += _IOTA[:total]
    return idx


def take(r: Ragged, rows: np.ndarray) -> Ragged:
    """The given rows (any order, repeats allowed), e.g. a participant's bytes for each state."""
    rows = np.asarray(rows, np.int64)
    off = r.offsets()
    start, lengths = off[rows], r.lengths[rows]
    return Ragged(r.data[_ragged_index(start, lengths)], lengths)


def keep(r: Ragged, mask: np.ndarray) -> Ragged:
    """The rows where ``mask`` is true keep their bytes; the others become empty (the field is
    absent there)."""
    mask = np.asarray(mask, bool)
    per_byte = np.repeat(mask, r.lengths)
    return Ragged(r.data[per_byte], np.where(mask, r.lengths, 0))


class _Concat(Ragged):
    """Rows made of parts (row ``i`` = row ``i`` of every part, in order), their bytes copied
    once, when first asked for: nested messages (a concat inside a length-prefixed field inside a
    concat...) are laid out from their leaves straight into the final buffer instead of being
    copied again at every level."""

    def __init__(self, parts: tuple[Ragged, ...], lengths: np.ndarray) -> None:
        self.parts = parts
        self.lengths = lengths
        self._data: np.ndarray | None = None

    @property
    def data(self) -> np.ndarray:
        if self._data is None:
            out = np.empty(int(self.lengths.sum()), np.uint8)
            self._fill(out, np.r_[0, np.cumsum(self.lengths)][:-1])
            self._data = out
            self.parts = ()
        return self._data

    def _fill(self, out: np.ndarray, starts: np.ndarray) -> None:
        before = starts
        for p in self.parts:
            if isinstance(p, _Concat) and p._data is None:
                p._fill(out, before)
            elif len(p.data):
                w = int(p.lengths[0])
                if (p.lengths == w).all():  # rows of one width: a 2-D index, no repeat
                    out[(before[:, None] + _iota(w)).reshape(-1)] = p.data
                else:
                    out[_ragged_index(before, p.lengths)] = p.data
            before = before + p.lengths


def _iota(k: int) -> np.ndarray:
    return _IOTA[:k] if k <= len(_IOTA) else np.arange(k)


def concat(*parts: Ragged) -> Ragged:
    """Row ``i`` of the result is row ``i`` of every part, in order (the bytes laid out when first
    used: :class:`_Concat`)."""
    parts = tuple(p for p in parts if p is not None)
    n = parts[0].n
    if n == 0:
        return Ragged(np.zeros(0, np.uint8), np.zeros(0, np.int64))
    if all(not isinstance(p, _Concat) and (p.lengths == p.lengths[0]).all() for p in parts):
        return Ragged.fixed(np.hstack([p.data.reshape(n, -1) for p in parts]))  # one hstack
    return _Concat(parts, np.sum([p.lengths for p in parts], axis=0))


def group(r: Ragged, bounds: np.ndarray) -> Ragged:
    """Consecutive rows joined: row ``k`` of the result is rows ``bounds[k]:bounds[k+1]``
    (``bounds`` has one more entry than the result; rows outside are dropped)."""
    off = r.offsets()
    b = np.asarray(bounds, np.int64)
    start, end = off[b[:-1]], off[b[1:]]
    if b[0] == 0 and b[-1] == r.n:
        return Ragged(r.data, end - start)
    return Ragged(r.data[_ragged_index(start, end - start)], end - start)


def length_prefixed(r: Ragged) -> bytes:
    """The rows as one byte string, each prefixed with its length as a 4-byte little-endian
    integer (the framing of a binary .osi trace)."""
    head = Ragged.fixed(r.lengths.astype("<u4").view(np.uint8).reshape(-1, 4))
    return concat(head, r).data.tobytes()


# ---- decoding: the fields of many messages at once ---------------------------------------------

class WireError(ValueError):
    """Bytes that are not valid protobuf wire format: ``span`` is the index of the message (of the
    spans walked) and ``offset`` the byte where it goes wrong."""

    def __init__(self, span: int, offset: int, reason: str) -> None:
        super().__init__(f"message {span}, byte {offset}: {reason}")
        self.span, self.offset, self.reason = span, offset, reason


#: zero bytes after the data (a varint read past the end stops there; the ends are checked)
PAD = 16


def padded(raw: bytes) -> np.ndarray:
    """``raw`` as uint8 with :data:`PAD` zero bytes after it (what :func:`walk` reads)."""
    buf = np.zeros(len(raw) + PAD, np.uint8)
    buf[:len(raw)] = np.frombuffer(raw, np.uint8)
    return buf


def read_varints(buf: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The varint at each position: (value as uint64, its length in bytes); a varint longer than
    10 bytes is a :class:`WireError` (``span`` = its index in ``pos``)."""
    b = buf[pos]
    val = (b & 0x7F).astype(np.uint64)
    nbytes = np.ones(len(pos), np.int64)
    idx = np.flatnonzero(b & 0x80)
    k = 1
    while idx.size:
        if k == 10:
            raise WireError(int(idx[0]), int(pos[idx[0]]), "varint longer than 10 bytes")
        bk = buf[np.minimum(pos[idx] + k, len(buf) - 1)]
        val[idx] |= (bk & 0x7F).astype(np.uint64) << np.uint64(7 * k)
        nbytes[idx] += 1
        idx = idx[(bk & 0x80) != 0]
        k += 1
    return val, nbytes


class Fields:
    """The fields of the messages walked, one row per field occurrence, span by span in the order
    of the bytes: ``span`` (the message's index), ``number``, ``wire`` (type), ``pos`` (first byte
    of the value: of the payload for a length-delimited field), ``length`` (bytes of the value),
    ``value`` (a varint's value, uint64)."""

    def __init__(self, span, number, wire, pos, length, value, n_spans: int) -> None:
        self.span, self.number, self.wire = span, number, wire
        self.pos, self.length, self.value = pos, length, value
        self.n_spans = n_spans

    def select(self, number: int, wire: int, *, singular: bool = True) -> np.ndarray:
        """Rows of field ``number``; another wire type for it, or (``singular``) a span with it
        twice, is :class:`FastPathUnsupported` (a decoder that merges or converts would be needed)."""
        rows = np.flatnonzero(self.number == number)
        if rows.size and (self.wire[rows] != wire).any():
            raise FastPathUnsupported(f"field {number} with wire type "
                              f"{int(self.wire[rows][self.wire[rows] != wire][0])}")
        if singular and rows.size and np.bincount(self.span[rows]).max() > 1:
            raise FastPathUnsupported(f"singular field {number} repeated in a message")
        return rows


def walk(buf: np.ndarray, start: np.ndarray, end: np.ndarray) -> Fields:
    """The fields of the messages ``buf[start[i]:end[i]]`` (``buf`` from :func:`padded`), all at
    once: step ``k`` reads the ``k``-th field of every message that has one (numpy over the
    messages, one step per field of the longest message)."""
    start = np.asarray(start, np.int64)
    end = np.asarray(end, np.int64)
    pos = start.copy()
    act = np.flatnonzero(pos < end)
    out: list[tuple[np.ndarray, ...]] = []
    while act.size:
        p = pos[act]
        key, kn = read_varints(buf, p)
        wire = (key & np.uint64(7)).astype(np.int8)
        number = (key >> np.uint64(3)).astype(np.int64)
        q = p + kn
        length = np.zeros(len(act), np.int64)
        value = np.zeros(len(act), np.uint64)
        for w, size in ((I64, 8), (I32, 4)):
            length[wire == w] = size
        v = np.flatnonzero(wire == VARINT)
        if v.size:
            value[v], length[v] = read_varints(buf, q[v])
        d = np.flatnonzero(wire == LEN)
        if d.size:
            ln, n2 = read_varints(buf, q[d])
            if (ln > np.uint64(1 << 40)).any():
                i = d[np.argmax(ln > np.uint64(1 << 40))]
                raise WireError(int(act[i]), int(p[i]), "length-delimited field longer than 1 TB")
            q[d] += n2
            length[d] = ln.astype(np.int64)
        bad = ~np.isin(wire, (VARINT, I64, LEN, I32)) | (number == 0)
        nxt = q + length
        bad |= nxt > end[act]
        if bad.any():
            i = int(np.argmax(bad))
            why = ("field number 0" if number[i] == 0 else
                   f"wire type {int(wire[i])} (groups are not read)" if wire[i] not in (0, 1, 2, 5)
                   else f"field {int(number[i])} ends {int(nxt[i] - end[act[i]])} bytes after "
                        f"its message")
            raise WireError(int(act[i]), int(p[i]), why)
        out.append((act, number, wire, q, length, value))
        pos[act] = nxt
        act = act[nxt < end[act]]
    if not out:
        e = np.zeros(0, np.int64)
        return Fields(e, e, e.astype(np.int8), e, e, e.astype(np.uint64), len(start))
    cols = [np.concatenate(c) for c in zip(*out)]
    order = np.argsort(cols[0], kind="stable")  # span by span, each in the order of its bytes
    return Fields(*(c[order] for c in cols), n_spans=len(start))


def doubles(buf: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """The little-endian doubles at the given positions (any alignment): one gather from the
    buffer seen as a double at every byte (an unaligned view with a stride of one byte; 5x
    faster than gathering eight bytes per value)."""
    at_every_byte = np.ndarray(shape=(len(buf) - 7,), dtype="<f8", buffer=buf, strides=(1,))
    return at_every_byte[pos]
