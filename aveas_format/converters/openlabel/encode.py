"""The OpenLABEL frames as JSON bytes built from columns (the hot path of the export).

No dict per state: each part of an object's data (the box, the velocity, the lights, the road
facts, the extension's values...) is one column of JSON fragments of a
:class:`~aveas_format.io.jsontext.Layout`, built for a chunk of rows at once (optional parts are
empty fragments). Only what is irregular by nature (interior signals, ``impact`` attributes,
extension columns of nested types) goes through a Python value per row, and only in the rows that
have it.

:func:`frame_chunks` yields the members of the ``frames`` object in frame order, a chunk of about
:data:`CHUNK_ROWS` rows at a time, so that an export never holds the document (only the
recording's columns and one chunk of text).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.openlabel.profile import LONGITUDINAL, EXT, LIGHTS
from aveas_format.io.jsontext import Layout, dumps, numbers, texts
from aveas_format.io.timemajor import chunk_bounds

#: rows per chunk of the streamed frames (a chunk ends at a frame boundary)
CHUNK_ROWS = 16384


def _vector(lay: Layout, parts: list, idx: np.ndarray) -> list:
    """Segments of a vector's components (arrays over all rows, or numbers) for the rows ``idx``:
    one fragment per row, or the vector in the template where it is the same in every row."""
    m = len(idx)
    return [lay.floats(np.column_stack([np.full(m, c, dtype=np.float64) if np.isscalar(c) else c[idx]
                                        for c in parts]))]


def _named(name: str, val: list, *, vec: bool = False, quoted: bool = False) -> list:
    """Segments of ``{"name":NAME,"val":V}`` (``[V]`` for a vector, ``"V"`` quoted)."""
    head = b'{"name":' + dumps(name) + b',"val":' + (b"[" if vec else b'"' if quoted else b"")
    return [head, *val, b"]}" if vec else b'"}' if quoted else b"}"]


def frame_chunks(frame_of_row: np.ndarray, times: np.ndarray, prepare, *,
                 chunk_rows: int = CHUNK_ROWS, part: tuple[int, int] | None = None) -> Iterator[Any]:
    """The members ``"k":{frame}`` of the ``frames`` object, comma-separated, in chunks of about
    ``chunk_rows`` rows (whole frames): ``frame_of_row`` = each state row's frame (an index into
    ``times``), ``prepare(rows)`` = the per-row inputs of the state rows ``rows`` (in that order;
    :func:`aveas_format.converters.openlabel.write.openlabel_chunks`), asked for one chunk at a
    time. ``part``: only the chunks ``[first, last)`` of :func:`~aveas_format.io.timemajor.chunk_bounds` (their text is the
    same as in the whole sequence: a comma before every chunk but the very first)."""
    order = np.argsort(frame_of_row, kind="stable")  # in a frame: the objects in the states' order
    if len(order) < 2**31:
        order = order.astype(np.int32)  # (half the memory: one index per state)
    fs = frame_of_row[order]
    ts = numbers(times)
    bounds = chunk_bounds(fs, chunk_rows)
    c0, c1 = part if part is not None else (0, len(bounds) - 1)
    for c in range(c0, c1):
        start, stop = bounds[c], bounds[c + 1]
        rows = order[start:stop]
        f = fs[start:stop]
        m = len(f)
        lo = np.flatnonzero(np.r_[True, f[1:] != f[:-1]])  # the first row of each frame
        # before each row its frame's head (a frame's first row) or a comma, after a frame's
        # last row "}}": fragments of the rows themselves (the chunk is written in one go)
        heads = [b'%s"%d":{"frame_properties":{"timestamp":%s},"objects":{'
                 % (b"" if c == 0 and j == 0 else b",", k, ts[k]) for j, k in enumerate(f[lo].tolist())]
        before = np.zeros(m, np.int64)
        before[lo] = np.arange(1, len(lo) + 1)
        after = np.zeros(m, np.int64)
        after[np.r_[lo[1:] - 1, m - 1]] = 1
        yield _objects_packed(prepare(rows), np.arange(m), (np.array([b",", *heads], dtype=object), before),
                              (_AFTER, after))


_AFTER = np.array([b"", b"}}"], dtype=object)


def _objects_packed(r: dict[str, Any], idx: np.ndarray, before: tuple, after: tuple) -> pa.Buffer:
    """``"uid":{"object_data":{...}}`` for the rows ``idx``, one after the other, each between
    a fragment ``before`` and one ``after`` (``(table, each row's index into it)``)."""
    m = len(idx)
    lay = Layout(m)
    pid = r["pid"][idx]
    on = r["on"][idx]
    vec = [(True, _named("velocity", _vector(lay, r["vel"], idx), vec=True)),
           (True, _named("acceleration", _vector(lay, r["acc"], idx), vec=True))]
    if r["box_std"] is not None:
        vec.append((True, _named("bounding_box/ustddev", _vector(lay, r["box_std"], idx), vec=True)))
    if r["vel_std"] is not None:
        vec.append((lay.mask(r["vel_ok"][idx]),
                    _named("velocity/ustddev", _vector(lay, r["vel_std"], idx), vec=True)))
    if r["acc_std"] is not None:
        vec.append((lay.mask(r["acc_ok"][idx]),
                    _named("acceleration/ustddev", _vector(lay, r["acc_std"], idx), vec=True)))
    text, num, boolean = [], [], []
    if on.any():
        p_on = lay.mask(on)
        words = np.array([*texts(r["road_words"]), b""], dtype=object)
        text.append((p_on, _named("used_road_link", [lay.coded(words, r["road_code"][idx])])))
        if r["lane_id"] is not None:
            lid = r["lane_id"][idx]
            ok = on & np.isfinite(lid)
            text.append((lay.mask(ok), _named("open_drive/lane_id",
                                              [lay.ints(np.where(ok, lid, 0).astype(np.int64))], quoted=True)))
        vec.append((p_on, _named("open_drive/local_road_coordinates",
                                 _vector(lay, [r["road_s"], r["road_t"]], idx), vec=True)))
        facts = r["facts"]
        if facts is not None:
            lp = facts["lane_position"][idx]
            num.append((lay.mask(on & np.isfinite(lp)), _named("open_drive/lane_position", [lay.floats(lp)])))
            road_user = lay.mask(on & r["road_class"][idx])
            text.append((road_user, _named("road/classification",
                                           [lay.text(texts(facts["classification"][idx].tolist()))])))
            for side in ("left", "right"):
                for kind, key in (("legal", f"{side}_legal"), ("physical", f"{side}_phys")):
                    num.append((road_user, _named(f"road/number_lanes/{side}/{kind}",
                                                  [lay.ints(facts[key][idx])])))
    for c, name in LIGHTS.items():
        a = r["lights"].get(c)
        if a is not None:
            a = a[idx]
            boolean.append((lay.mask(np.isfinite(a)), _named(name, [lay.booleans(a >= 0.5)])))
    _irregular(r, idx, pid, lay, vec, num, boolean)
    segments = [lay.coded(*before), b'"', lay.ints(pid), b'":{"object_data":{"cuboid":[{"name":"bounding_box","val":[',
                *_vector(lay, r["box"], idx), b"]", *_extension(r, idx, lay), b"}],",
                lay.join(b'"vec":[', vec, b"]"), b",", lay.join(b'"boolean":[', boolean, b"]"), b",",
                lay.join(b'"num":[', num, b"]"), b",", lay.join(b'"text":[', text, b"]"), b"}}",
                lay.coded(*after)]
    return lay.packed(segments)


def _irregular(r: dict[str, Any], idx: np.ndarray, pid: np.ndarray, lay: Layout, vec: list,
               num: list, boolean: list) -> None:
    """Interior signals and ``impact`` attributes: by (participant, time), only in the rows that
    have them (each a ready fragment of comma-separated list items)."""
    interior, impact = r["interior"], r["impact"]
    if not interior and not impact:
        return
    m = len(idx)
    b_int, n_int, v_imp = [b""] * m, [b""] * m, [b""] * m
    t = r["t"][idx].tolist()
    for j, key in enumerate(zip(pid.tolist(), t)):
        irow = interior.get(key) if interior else None
        if irow:
            bl, nl = [], []
            for c in ("automation_longitudinal_p", "automation_lateral_p"):
                # the profile's lateral flag carries the longitudinal name (quirk)
                if irow.get(c) is not None:
                    bl.append({"name": LONGITUDINAL, "val": bool(irow[c] >= 0.5)})
            for c, name in (("steering_angle", "interior/steering_angle"),
                            ("steering_angle_std", "interior/steering_angle/ustddev"),
                            ("brake_pedal", "interior/brake_pedal"),
                            ("accelerator_pedal", "interior/accelerator_pedal"),
                            ("gear", "interior/gear")):
                if irow.get(c) is not None:
                    nl.append({"name": name, "val": irow[c] if c == "gear" else float(irow[c])})
            b_int[j] = b",".join(dumps(x) for x in bl)
            n_int[j] = b",".join(dumps(x) for x in nl)
        imp = impact.get(key) if impact else None
        if imp:
            items = []
            for k in ("gttc", "pret", "thw"):
                if imp.get(f"{k}/values"):
                    items.append({"name": f"impact/{k}/object_ids", "val": imp[f"{k}/object_ids"]})
                    items.append({"name": f"impact/{k}/values", "val": imp[f"{k}/values"]})
            v_imp[j] = b",".join(dumps(x) for x in items)
    for target, frags in ((vec, v_imp), (boolean, b_int), (num, n_int)):
        a = np.array(frags, dtype=object)
        target.append((lay.mask(a != b""), [lay.text(a)]))


def _extension(r: dict[str, Any], idx: np.ndarray, lay: Layout) -> list:
    """Segments of ``,"aveas_format":{...}`` where the row has extension values (the states'
    columns the profile lacks, placeholders of null profile columns, exact values), else none."""
    ext = r["ext"]
    if ext is None:
        return []
    members: list = []
    ix = pa.array(idx)

    def member(c: str, token: int, mask: np.ndarray | None) -> None:
        members.append((lay.mask(mask), [b'"' + c.encode() + b'":', token]))

    for c, col in ext["columns"].items():
        valid, token = lay.arrow(col.take(ix))
        member(c, token, valid)
    for c, isnull in ext["nullable"].items():
        member(c, lay.text(b"null"), isnull[idx])
    for c, vals in ext["exact"].items():
        v = vals[idx]
        member(c, lay.floats(v), ~np.isnan(v))
    if not members:
        return []
    return [lay.join(b',"' + EXT.encode() + b'":{', members, b"}", empty=b"")]


__all__ = ["CHUNK_ROWS", "frame_chunks"]
