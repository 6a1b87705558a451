"""Participants: identity, class, size and references between participants and states.

Unique ids, classes in the taxonomy and valid class PMFs are declared properties of the columns and
are reported by the generic rules ``structure.duplicate_key``, ``structure.category`` and
``structure.pmf``; sizes <= 0 by ``structure.value_range``. The rules here check what the declarations
cannot express.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyarrow as pa

from aveas_format.io.arrow import pmf_matrix
from aveas_format.schema.pmf import pmf_problems
from aveas_format.schema.taxonomy import CLASSES
from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hits, rule
from aveas_format.validate.views import ints, nullable_ints, num

_F = "participants.parquet"


@rule("participants.class_pmf_argmax", "error", "class is not the most probable class of class_pmf",
      "participants.parquet: row {row}: participant {participant_id} has class {value!r} but "
      "class_pmf puts most mass on {expected!r} ({p_expected} > {p_value})",
      enforces="docs/format.md §4: `class` is the most probable class; the argmax of class_pmf equals "
               "`class`")
def class_pmf_argmax(ctx: Context) -> Iterator[Hits]:
    """A participant's ``class`` is not a most probable class of its ``class_pmf`` (ties are
    accepted: the class only needs the maximal probability, within 1e-6)."""
    pv = ctx.participants_view
    t = pv.table
    if t is None or "class_pmf" not in t.column_names or not pv.n:
        return
    if not pa.types.is_struct(t.column("class_pmf").type):
        return
    try:
        m = pmf_matrix(t.column("class_pmf"), "class").astype(np.float64)
    except Exception:  # noqa: BLE001 — a struct without the 13 fields: structure.column_type
        return
    valid = ~np.isnan(m).any(axis=1) & ~pmf_problems(m)  # invalid PMFs: structure.pmf
    idx = _class_index(pv.cls)
    has = valid & (idx >= 0)
    p_cls = np.where(has, m[np.arange(pv.n), np.maximum(idx, 0)], np.nan)
    pmax = np.nanmax(np.where(np.isnan(m), -np.inf, m), axis=1)
    bad = has & (p_cls < pmax - 1e-6)
    if bad.any():
        rows = np.flatnonzero(bad)
        best = np.asarray(CLASSES, dtype=object)[np.argmax(m[rows], axis=1)]
        yield Hits(total=len(rows), arrays={
            "row": rows, "participant_id": pv.pid[rows], "value": pv.cls[rows],
            "expected": best, "p_expected": np.round(pmax[rows], 4), "p_value": np.round(p_cls[rows], 4)},
            const={"file": _F, "table": "participants", "column": "class"})


def _class_index(cls: np.ndarray) -> np.ndarray:
    lut = {c: i for i, c in enumerate(CLASSES)}
    return np.fromiter((lut.get(c, -1) for c in cls), dtype=np.int64, count=len(cls))


@rule("participants.size_implausible", "warning", "Size implausible for the class",
      "participants.parquet: row {row}: participant {participant_id} ({class_}) has {column} "
      "{value} m, outside the plausible {low}-{high} m",
      enforces=quality("sizes"))
def size_implausible(ctx: Context) -> Iterator[Hits]:
    """A participant's length or width lies outside the plausible range of its class (e.g. a car
    2.5-7 m long; ranges configurable under ``[classes.<class>]``: ``length``, ``width``). Sizes
    <= 0 are errors of structure.value_range."""
    pv = ctx.participants_view
    if not pv.n:
        return
    for column, values in (("length", pv.length), ("width", pv.width)):
        if values is None:
            continue
        lo = np.full(pv.n, np.nan)
        hi = np.full(pv.n, np.nan)
        for c, lim in ctx.config.classes.items():
            rng = getattr(lim, column)
            if rng is not None:
                sel = pv.cls == c
                lo[sel], hi[sel] = rng
        bad = (values > 0) & ((values < lo) | (values > hi))
        if bad.any():
            rows = np.flatnonzero(bad)
            yield Hits(total=len(rows), arrays={
                "row": rows, "participant_id": pv.pid[rows], "class_": pv.cls[rows],
                "value": np.round(values[rows], 3), "low": lo[rows], "high": hi[rows]},
                const={"file": _F, "table": "participants", "column": column})


@rule("participants.size_std_missing", "warning", "Measured participant without size uncertainty",
      "participants.parquet: row {row}: participant {participant_id} is measured ({provenance}) "
      "but {column} is {state}",
      enforces=("docs/format.md §2: measured data (provenance natural or staged) SHOULD carry _std for "
                "length and width"))
def size_std_missing(ctx: Context) -> Iterator[Hits]:
    """A measured participant (provenance natural or staged) has no ``length_std`` / ``width_std``
    (column absent or null): docs/format.md §2 says measured data SHOULD carry them."""
    pv = ctx.participants_view
    t = pv.table
    if t is None or not pv.n or not pv.measured.any():
        return
    for column in ("length_std", "width_std"):
        v = num(t, column, "participants")
        if column in t.column_names and v is None:
            continue  # mistyped: structure.column_type
        missing = pv.measured & (np.isnan(v) if v is not None else True)
        if missing.any():
            rows = np.flatnonzero(missing)
            yield Hits(total=len(rows), arrays={"row": rows, "participant_id": pv.pid[rows],
                                                "provenance": pv.provenance[rows]},
                       const={"file": _F, "table": "participants", "column": column,
                              "state": "null" if v is not None else "absent"})


@rule("participants.attached_to_unknown", "error", "attached_to names no other participant",
      "participants.parquet: row {row}: participant {participant_id} is attached_to {value}, "
      "{why}",
      enforces="docs/format.md §4: attached_to is another participant (e.g. a trailer's towing vehicle)")
def attached_to_unknown(ctx: Context) -> Iterator[Hits]:
    """``attached_to`` names a participant id that does not exist, or the participant itself."""
    pv = ctx.participants_view
    t = pv.table
    col = nullable_ints(t, "attached_to", "participants")
    if col is None or not pv.n:
        return
    a, has = col
    unknown = has & (pv.index_of(a) < 0)
    itself = has & (a == pv.pid)
    bad = unknown | itself
    if bad.any():
        rows = np.flatnonzero(bad)
        why = np.where(itself[rows], "itself", "which is not a participant")
        yield Hits(total=len(rows), arrays={"row": rows, "participant_id": pv.pid[rows],
                                            "value": a[rows], "why": why},
                   const={"file": _F, "table": "participants", "column": "attached_to"})


@rule("participants.without_states", "warning", "Participant without states",
      "participants.parquet: row {row}: participant {participant_id} has no row in states.parquet",
      enforces=quality("participants_in_states"))
def without_states(ctx: Context) -> Iterator[Hits]:
    """A participant is declared but never appears in states.parquet (a leftover of filtering, or
    states written for other ids)."""
    pv = ctx.participants_view
    s = ints(ctx.key_table("states", ("participant_id",)) if "states" in ctx.table_names
             else None, "participant_id")
    if s is None or not pv.n or not pv.ok:
        return
    bad = ~np.isin(pv.pid, np.unique(s))
    if bad.any():
        rows = np.flatnonzero(bad)
        yield Hits(total=len(rows), arrays={"row": rows, "participant_id": pv.pid[rows]},
                   const={"file": _F, "table": "participants"})


@rule("participants.unknown_in_states", "error", "States of an unknown participant",
      "{file}: row {row}: participant_id {participant_id} is not in participants.parquet "
      "({n_rows} rows of this participant)",
      enforces="docs/format.md §5: states.participant_id refers to participants.parquet")
def unknown_in_states(ctx: Context) -> Iterator[Hits]:
    """states (or interior) rows carry a participant_id that participants.parquet does not declare;
    one finding per unknown id, at its first row."""
    pv = ctx.participants_view
    if not pv.ok or ctx.table("participants") is None:
        return
    for name in ("states", "interior"):
        keys = ctx.key_table(name, ("participant_id",)) if name in ctx.table_names else None
        pid = ints(keys, "participant_id")
        if pid is None or not len(pid):
            continue
        unknown = pv.index_of(pid) < 0
        if not unknown.any():
            continue
        ids, first, counts = np.unique(pid[unknown], return_index=True, return_counts=True)
        rows = np.flatnonzero(unknown)[first]
        o = np.argsort(rows)
        yield Hits(total=len(ids), arrays={"row": rows[o], "participant_id": ids[o],
                                           "n_rows": counts[o]},
                   const={"file": f"{name}.parquet", "table": name, "column": "participant_id"})


@rule("participants.unknown_reference", "error", "Event or region names an unknown participant",
      "{file}: row {row}: {column} names participant {participant_id}, which is not in "
      "participants.parquet",
      enforces="docs/format.md §6-7: events.participant_ids and unobserved.occluder_id refer to "
               "participants")
def unknown_reference(ctx: Context) -> Iterator[Hits]:
    """An event's ``participant_ids`` or a region's ``occluder_id`` names a participant that does
    not exist."""
    pv = ctx.participants_view
    if not pv.ok or ctx.table("participants") is None:
        return
    u = ctx.table("unobserved")
    occ = nullable_ints(u, "occluder_id", "unobserved")
    if occ is not None:
        ids, has = occ
        bad = has & (pv.index_of(ids) < 0)
        if bad.any():
            rows = np.flatnonzero(bad)
            yield Hits(total=len(rows), arrays={"row": rows, "participant_id": ids[rows]},
                       const={"file": "unobserved.parquet", "table": "unobserved",
                              "column": "occluder_id"})
    e = ctx.table("events")
    if e is not None and "participant_ids" in e.column_names and pa.types.is_list(
            e.column("participant_ids").type):
        lst = e.column("participant_ids").combine_chunks()
        if pa.types.is_integer(lst.type.value_type) and len(lst):
            flat = np.asarray(lst.flatten().to_numpy(zero_copy_only=False), dtype=np.int64)
            offs = np.asarray(lst.offsets.to_numpy(), dtype=np.int64)
            row_of = np.repeat(np.arange(len(lst)), np.diff(offs))
            bad = pv.index_of(flat) < 0
            if bad.any():
                yield Hits(total=int(bad.sum()), arrays={"row": row_of[bad],
                                                         "participant_id": flat[bad]},
                           const={"file": "events.parquet", "table": "events",
                                  "column": "participant_ids"})
