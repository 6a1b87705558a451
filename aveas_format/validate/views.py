"""Numpy views of the tables that the semantic rules share (built once per validation).

Rules past the structure family work on numpy arrays, not on Arrow tables: a declared column read as
float64 (nulls -> NaN), participants joined onto state rows, and states in (participant_id, time)
order with per-participant segment boundaries. A column that is missing or stored with the wrong type
reads as ``None`` here (the structure rules report it), so semantic rules simply skip what they
cannot check.

:class:`StatesView` keeps ``row``: the position of each sorted sample in the file, so findings point
at file rows even when the file is not sorted (which structure.sort_order reports).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.io.arrow import arrow_type, column_numpy, types_compatible
from aveas_format.schema.tables import TABLES
from aveas_format.schema.taxonomy import VEHICLE_CLASSES

_MEASURED = ("natural", "staged")


def _compatible(table: pa.Table, spec_name: str, name: str) -> bool:
    if name not in table.column_names:
        return False
    c = TABLES[spec_name].get(name)
    return c is None or types_compatible(table.column(name).type, arrow_type(c))


def num(table: pa.Table | None, name: str, spec: str | None = None) -> np.ndarray | None:
    """A numeric column as float64 (nulls -> NaN); None if absent or not numeric."""
    if table is None or name not in table.column_names:
        return None
    if spec is not None and not _compatible(table, spec, name):
        return None
    t = table.column(name).type
    if not (pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_boolean(t)):
        return None
    return column_numpy(table, name)


def ints(table: pa.Table | None, name: str) -> np.ndarray | None:
    """An integer key column as int64 (None if absent, not integer, or holding nulls); see
    :func:`nullable_ints` for a column that may hold nulls."""
    if table is None or name not in table.column_names:
        return None
    a = table.column(name)
    if not pa.types.is_integer(a.type) or a.null_count:
        return None
    return np.asarray(a.to_numpy(zero_copy_only=False), dtype=np.int64)


def nullable_ints(table: pa.Table | None, name: str,
                  spec: str | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """An integer column that may hold nulls (``attached_to``, ``occluder_id``...) exactly, as
    (int64 values with 0 at nulls, valid mask); None if absent or not integer. Ids never go through
    float64, which holds integers exactly only up to 2**53 (the format allows any int64 id)."""
    if table is None or name not in table.column_names:
        return None
    if spec is not None and not _compatible(table, spec, name):
        return None
    a = table.column(name)
    if not pa.types.is_integer(a.type):
        return None
    valid = np.asarray(a.is_valid().to_numpy(zero_copy_only=False), bool)
    values = pc.fill_null(a, 0).to_numpy(zero_copy_only=False) if a.null_count else \
        a.to_numpy(zero_copy_only=False)
    return np.asarray(values, dtype=np.int64), valid


def strings(table: pa.Table | None, name: str) -> tuple[np.ndarray, np.ndarray] | None:
    """A (dictionary) string column as (codes int32 with -1 for null, values object array)."""
    if table is None or name not in table.column_names:
        return None
    a = table.column(name)
    if pa.types.is_dictionary(a.type):
        a = a.cast(pa.dictionary(pa.int32(), a.type.value_type))
        a = a.unify_dictionaries() if hasattr(a, "unify_dictionaries") else a
        chunks = a.chunks
        if not chunks:
            return np.zeros(0, np.int32), np.array([], dtype=object)
        if len(chunks) > 1:
            a = pa.chunked_array(chunks).combine_chunks()
        else:
            a = chunks[0]
        if not pa.types.is_string(a.type.value_type) and not pa.types.is_large_string(
                a.type.value_type):
            return None
        codes = pc.fill_null(a.indices, -1).to_numpy(zero_copy_only=False).astype(np.int32)
        values = np.array(a.dictionary.to_pylist(), dtype=object)
        return codes, values
    if not (pa.types.is_string(a.type) or pa.types.is_large_string(a.type)):
        return None
    enc = pc.dictionary_encode(a).combine_chunks() if isinstance(a, pa.ChunkedArray) else \
        pc.dictionary_encode(a)
    codes = pc.fill_null(enc.indices, -1).to_numpy(zero_copy_only=False).astype(np.int32)
    return codes, np.array(enc.dictionary.to_pylist(), dtype=object)


def decode(codes: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Object array of strings (None for null) from codes/values."""
    ext = np.append(values, None).astype(object)
    return ext[np.where(codes < 0, len(values), codes)]


class ParticipantsView:
    """participants.parquet as numpy arrays (sorted by participant_id for lookups)."""

    def __init__(self, table: pa.Table | None, recording_provenance: str | None) -> None:
        self.table = table
        pid = ints(table, "participant_id")
        self.ok = pid is not None
        self.pid = pid if pid is not None else np.zeros(0, np.int64)
        self.n = len(self.pid)
        self.order = np.argsort(self.pid, kind="stable")
        self.sorted_pid = self.pid[self.order]
        cls = strings(table, "class")
        self.cls = decode(*cls) if cls is not None else np.full(self.n, None, dtype=object)
        prov = strings(table, "provenance")
        if prov is not None:
            self.provenance = decode(*prov)
        else:
            default = recording_provenance if recording_provenance != "mixed" else None
            self.provenance = np.full(self.n, default, dtype=object)
        self.measured = np.isin(self.provenance, _MEASURED)
        self.length = num(table, "length", "participants")
        self.width = num(table, "width", "participants")

    def index_of(self, ids: np.ndarray) -> np.ndarray:
        """Row in participants of each id (-1 where unknown)."""
        ids = np.asarray(ids, dtype=np.int64)
        if self.n == 0:
            return np.full(len(ids), -1, np.int64)
        pos = np.clip(np.searchsorted(self.sorted_pid, ids), 0, self.n - 1)
        found = self.sorted_pid[pos] == ids
        return np.where(found, self.order[pos], -1)


class StatesView:
    """states.parquet in (participant_id, time) order, with participant attributes joined."""

    def __init__(self, table: pa.Table, parts: ParticipantsView, spec: str = "states") -> None:
        self.table = table
        self.spec = spec
        pid = ints(table, "participant_id")
        t = num(table, "time", spec)
        self.ok = pid is not None and t is not None and not np.isnan(t).any()
        if not self.ok:
            pid = np.zeros(0, np.int64)
            t = np.zeros(0)
        self.n = len(pid)
        unsorted = self.n > 1 and bool(((pid[1:] < pid[:-1]) |
                                        ((pid[1:] == pid[:-1]) & (t[1:] < t[:-1]))).any())
        self.order = np.lexsort((t, pid)) if unsorted else None
        self.pid = pid[self.order] if unsorted else pid
        self.t = t[self.order] if unsorted else t
        self.parts = parts
        #: same[i]: samples i and i+1 belong to the same participant
        self.same = self.pid[1:] == self.pid[:-1]
        self.starts = np.r_[0, np.flatnonzero(~self.same) + 1] if self.n else np.zeros(0, np.int64)
        self.ends = np.r_[self.starts[1:], self.n] if self.n else np.zeros(0, np.int64)
        #: segment number of each sample
        self.seg = np.repeat(np.arange(len(self.starts)), self.ends - self.starts)
        self.pidx = parts.index_of(self.pid)

    @cached_property
    def row(self) -> np.ndarray:
        """File row of each sorted sample."""
        return self.order if self.order is not None else np.arange(self.n)

    def col(self, name: str) -> np.ndarray | None:
        """A numeric column in sorted order (None if absent or mistyped)."""
        v = num(self.table, name, self.spec)
        if v is None or not self.ok:
            return None
        return v[self.order] if self.order is not None else v

    def strings(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        s = strings(self.table, name) if self.ok else None
        if s is None:
            return None
        codes, values = s
        return (codes[self.order] if self.order is not None else codes), values

    def present(self, name: str) -> bool:
        return name in self.table.column_names

    def _part(self, arr: np.ndarray, fill) -> np.ndarray:
        ext = np.append(arr, fill)
        return ext[np.where(self.pidx >= 0, self.pidx, len(arr))]

    @cached_property
    def cls(self) -> np.ndarray:
        """Class of each sample's participant (None where unknown)."""
        return self._part(self.parts.cls.astype(object), None)

    @cached_property
    def measured(self) -> np.ndarray:
        return self._part(self.parts.measured, False).astype(bool)

    @cached_property
    def vehicle(self) -> np.ndarray:
        return self._part(np.isin(self.parts.cls.astype(object), list(VEHICLE_CLASSES)), False).astype(bool)

    def per_sample(self, values_by_class: dict[str, float | None]) -> np.ndarray:
        """A per-class number for every sample (NaN where the class has none; per participant,
        then to its samples)."""
        per_part = [values_by_class.get(c) if isinstance(c, str) else None for c in self.parts.cls.tolist()]
        return self._part(np.asarray([np.nan if v is None else v for v in per_part], float), np.nan)

    def ahead(self, window: float) -> np.ndarray:
        """Index of the first sample of the same participant at least ``window`` s later (-1 if
        none): the end point of a finite difference over ``window``."""
        if self.n == 0:
            return np.zeros(0, np.int64)
        span = float(self.t.max() - self.t.min()) + 2 * window + 1.0
        key = self.seg * span + (self.t - self.t.min())
        j = np.searchsorted(key, key + window, side="left")
        ok = j < self.n
        jj = np.minimum(j, self.n - 1)
        ok &= self.seg[jj] == self.seg
        return np.where(ok, jj, -1)
