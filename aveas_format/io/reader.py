"""Reading recordings: metadata, version detection and migration, checksums, partial reads.

``open(path)`` reads a whole recording; ``columns=``, ``participants=``, ``time_range=`` and
``tables=`` read only part of it. Partial reads use the Parquet footer statistics of each row group
(``participant_id`` and ``time`` min/max) to skip row groups that cannot match, then filter the rest
exactly; since states are sorted by (participant_id, time) and written in bounded row groups, a
participant subset touches only its own row groups.

Checksums: a table read whole is hashed (SHA-256 of the file's bytes, which are memory-mapped once)
and compared with recording.json; a partial read checks row counts against the footer instead of
hashing the whole file (``verify=True`` forces the hash).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from pydantic import ValidationError

from aveas_format.errors import (
    ChecksumError,
    FormatError,
    FormatVersionError,
    RecordingIOError,
)
from aveas_format.io.arrow import conform, types_compatible, arrow_type
from aveas_format.io.container import Container, sha256_of
from aveas_format.safeio import load_json
from aveas_format.schema.metadata import RecordingMeta
from aveas_format.schema.tables import TABLES, TableSpec
from aveas_format.schema.versions import TABLE_MIGRATIONS, VersionError, migrate_meta

AVEAS_KEY = b"aveas"
PARTICIPANT_TABLES = ("participants", "states", "interior")
INTERVAL_TABLES = ("unobserved", "events", "environment")


@dataclass
class ReadPlan:
    """What a read touched: per table, the row groups read out of the total (for tests and --debug)."""

    row_groups: dict[str, tuple[int, int]] = field(default_factory=dict)
    hashed: list[str] = field(default_factory=list)


def format_validation_error(e: ValidationError, limit: int = 5) -> str:
    """One line per pydantic error: ``acquisition.method: Input should be 'aerial', ...``."""
    parts = []
    for err in e.errors()[:limit]:
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        parts.append(f"{loc}: {err['msg']}")
    more = f" (+{e.error_count() - limit} more)" if e.error_count() > limit else ""
    return "; ".join(parts) + more


def read_meta(container: Container) -> tuple[RecordingMeta, str | None]:
    """recording.json, migrated to the current version; returns (meta, migrated_from)."""
    where = container.location("recording.json")
    data = load_json(container.read_bytes("recording.json"), path=where)
    if not isinstance(data, dict):
        raise FormatError("recording.json must hold a JSON object", path=where)
    if "format_version" not in data:
        raise FormatVersionError("format_version missing", path=where)
    original = data["format_version"]
    try:
        data, steps = migrate_meta(data)
    except VersionError as e:
        raise FormatVersionError(str(e), path=where) from None
    try:
        meta = RecordingMeta.model_validate(data)
    except ValidationError as e:
        raise FormatError(f"invalid metadata: {format_validation_error(e)}", path=where) from None
    return meta, (original if steps else None)


def _aveas_key(pf: pq.ParquetFile, name: str, where: str) -> dict[str, Any]:
    md = pf.schema_arrow.metadata or {}
    if AVEAS_KEY not in md:
        raise FormatError("Parquet key-value metadata 'aveas' missing", path=where)
    try:
        info = json.loads(md[AVEAS_KEY])
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise FormatError("Parquet key-value metadata 'aveas' is not valid JSON", path=where) from None
    if not isinstance(info, dict) or "format_version" not in info or "table" not in info:
        raise FormatError("Parquet key-value metadata 'aveas' must hold format_version and table",
                          path=where)
    if info["table"] != name:
        raise FormatError(f"Parquet key-value metadata 'aveas' names table {info['table']!r}, "
                          f"expected {name!r}", path=where)
    return info


def _check_types(schema: pa.Schema, spec: TableSpec, where: str) -> None:
    for c in spec.required:
        if c.name not in schema.names:
            raise FormatError(f"required column {c.name!r} missing", path=where)
    for f in schema:
        c = spec.get(f.name)
        if c is not None and not types_compatible(f.type, arrow_type(c)):
            raise FormatError(f"column {f.name!r} has type {f.type}, the format declares {c.type}",
                              path=where)


def _stats_range(rg: pq.RowGroupMetaData, idx: int) -> tuple[Any, Any] | None:
    st = rg.column(idx).statistics
    if st is None or not st.has_min_max:
        return None
    return st.min, st.max


def _select_row_groups(pf: pq.ParquetFile, participants: np.ndarray | None,
                       time_range: tuple[float, float] | None, time_col: str | None) -> list[int]:
    md = pf.metadata
    names = pf.schema_arrow.names
    pid_idx = names.index("participant_id") if "participant_id" in names else None
    t_idx = names.index(time_col) if time_col and time_col in names else None
    keep = []
    for i in range(md.num_row_groups):
        rg = md.row_group(i)
        if participants is not None and pid_idx is not None:
            r = _stats_range(rg, pid_idx)
            if r is not None:
                lo, hi = r
                j = np.searchsorted(participants, lo)
                if j >= len(participants) or participants[j] > hi:
                    continue
        if time_range is not None and t_idx is not None:
            r = _stats_range(rg, t_idx)
            if r is not None and (r[1] < time_range[0] or r[0] > time_range[1]):
                continue
        keep.append(i)
    return keep


def read_table(container: Container, name: str, meta: RecordingMeta, *,
               columns: Sequence[str] | None = None, participants: np.ndarray | None = None,
               time_range: tuple[float, float] | None = None, verify: bool | None = None,
               plan: ReadPlan | None = None, migrations: Iterable[tuple[str, str]] = ()) -> pa.Table:
    """Read one table with optional column / participant / time selection."""
    spec = TABLES[name]
    file = spec.file
    where = container.location(file)
    buf = container.buffer(file)
    entry = meta.tables.get(name)
    partial = columns is not None or participants is not None or time_range is not None
    do_hash = verify if verify is not None else not partial
    if do_hash and entry is not None:
        if sha256_of(buf) != entry.sha256:
            raise ChecksumError("SHA-256 differs from recording.json (the file was changed or "
                                "truncated after writing)", path=where)
        if plan is not None:
            plan.hashed.append(name)
    steps = list(migrations)
    # (migrated tables are checked after the migration)
    pf = _checked_file(pa.BufferReader(buf), meta, name, where, check_types=not steps)

    names = pf.schema_arrow.names
    read_cols: list[str] | None = None
    if columns is not None:
        unknown = [c for c in columns if c not in names]
        if unknown:
            raise FormatError(f"columns {unknown} are not in {name}", path=where)
        must = [k for k in spec.key if k in names and k not in columns]
        read_cols = [c for c in names if c in set(columns) | set(must)]
    pid_filter = participants if name in PARTICIPANT_TABLES else None
    time_col = "time" if "time" in names else ("time_start" if "time_start" in names else None)
    groups = _select_row_groups(pf, pid_filter, time_range, "time" if time_col == "time" else None)
    if plan is not None:
        plan.row_groups[name] = (len(groups), pf.metadata.num_row_groups)
    table = _decoded(lambda: pf.read(columns=read_cols) if len(groups) == pf.metadata.num_row_groups
                     else pf.read_row_groups(groups, columns=read_cols), where)
    table = _filter(table, pid_filter, time_range)
    for step in steps:
        fn = TABLE_MIGRATIONS.get(step, {}).get(name)
        if fn is not None:
            table = fn(table)
    if steps:
        _check_types(table.schema, spec, where)
    return conform(table, spec, where=where)


def _decoded(read, where: str) -> pa.Table:
    """``read()`` (a Parquet read), a corrupt file a RecordingIOError naming ``where``."""
    try:
        return read()
    except (pa.ArrowException, OSError) as e:
        raise RecordingIOError(f"cannot decode Parquet data (corrupt file): {str(e).splitlines()[0]}",
                               path=where) from None


def _checked_file(source: Any, meta: RecordingMeta, name: str, where: str, *,
                  check_types: bool = True) -> pq.ParquetFile:
    """A table's Parquet file after the checks that decode nothing (fail fast): readable, the rows
    recording.json states, the ``aveas`` key, the declared column types."""
    try:
        pf = pq.ParquetFile(source)
    except (pa.ArrowException, OSError) as e:
        raise RecordingIOError(f"not a readable Parquet file (truncated or corrupt): "
                               f"{str(e).splitlines()[0]}", path=where) from None
    entry = meta.tables.get(name)
    if entry is not None and pf.metadata.num_rows != entry.rows:
        raise ChecksumError(f"{pf.metadata.num_rows} rows, recording.json says {entry.rows}",
                            path=where)
    _aveas_key(pf, name, where)
    if check_types:
        _check_types(pf.schema_arrow, TABLES[name], where)
    return pf


class TableParts:
    """One table of a recording on disk read part by part, never whole (bounded memory): the
    checks of :func:`read_table` that decode nothing when made, :meth:`read` a row group or some
    columns as :func:`read_table` would give them (cast to the declared types), :meth:`verify`
    the file's SHA-256 against recording.json, hashed in blocks (for a background thread while
    the parts are read). Not for a recording that needs a migration (``Recording.migrated_from``):
    read it whole."""

    def __init__(self, path: str | Path, meta: RecordingMeta, name: str) -> None:
        self.name, self.meta = name, meta
        self.container = Container(path)
        self.where = self.container.location(TABLES[name].file)
        self.pf = _checked_file(self.container.input_file(TABLES[name].file), meta, name, self.where)
        self.num_rows = self.pf.metadata.num_rows
        self.num_row_groups = self.pf.metadata.num_row_groups
        self.column_names = self.pf.schema_arrow.names

    def read(self, row_group: int | None = None, columns: Sequence[str] | None = None) -> pa.Table:
        """Row group ``row_group`` (None: every row) of ``columns`` (None: all), conformed."""
        t = _decoded(lambda: self.pf.read(columns=columns) if row_group is None
                     else self.pf.read_row_group(row_group, columns=columns), self.where)
        return conform(t, TABLES[self.name], where=self.where)

    def verify(self) -> None:
        """A ChecksumError when the file's SHA-256 is not the one recording.json states."""
        entry = self.meta.tables.get(self.name)
        if entry is not None and self.container.sha256(TABLES[self.name].file) != entry.sha256:
            raise ChecksumError("SHA-256 differs from recording.json (the file was changed or "
                                "truncated after writing)", path=self.where)

    def close(self) -> None:
        self.container.close()


def _filter(table: pa.Table, participants: np.ndarray | None,
            time_range: tuple[float, float] | None) -> pa.Table:
    mask = None
    if participants is not None and "participant_id" in table.column_names:
        mask = pc.is_in(table.column("participant_id"), value_set=pa.array(participants, pa.int64()))
    if time_range is not None:
        t0, t1 = time_range
        if "time" in table.column_names:
            m = pc.and_(pc.greater_equal(table.column("time"), t0), pc.less_equal(table.column("time"), t1))
        elif "time_start" in table.column_names and "time_end" in table.column_names:
            m = pc.and_(pc.less_equal(table.column("time_start"), t1),
                        pc.greater_equal(table.column("time_end"), t0))
        else:
            m = None
        if m is not None:
            mask = m if mask is None else pc.and_(mask, m)
    return table if mask is None else table.filter(mask)


def table_names_present(container: Container, meta: RecordingMeta) -> list[str]:
    """Tables of the recording: those listed in recording.json plus known files present (a table
    ``NAME`` is stored in ``NAME.parquet``), in the order of ``TABLES``."""
    files = [f.removesuffix(".parquet") for f in container.names() if f.endswith(".parquet")]
    return TABLES.order([*meta.tables, *files])


def open_recording(path: str | Path, *, tables: Iterable[str] | None = None,
                   columns: Sequence[str] | dict[str, Sequence[str]] | None = None,
                   participants: Iterable[int] | None = None,
                   time_range: tuple[float, float] | None = None,
                   verify: bool | None = None, plan: ReadPlan | None = None,
                   states: bool = True):  # -> Recording
    """Open a recording (directory or ZIP form).

    tables: names of the tables to read (default: all present). columns: a list (for states) or a
    dict ``{table: [columns]}``; key columns are always read. participants: ids to keep (participants,
    states, interior). time_range: (t0, t1) seconds, inclusive; interval tables keep the rows that
    overlap it. verify: hash tables (default: when a table is read whole). plan: filled with what was
    read. states False: every table but the states (``Recording.states`` None), for a consumer
    that reads them part by part from ``Recording.path`` (:class:`TableParts`; an exporter that
    streams them: ``Converter.streams_states``).
    """
    from aveas_format.io.recording import Recording

    container = Container(path)
    try:
        meta, migrated_from = read_meta(container)
        steps = []
        if migrated_from is not None:
            from aveas_format.schema.versions import migration_path
            steps = migration_path(migrated_from)
        present = table_names_present(container, meta)
        for required in ("participants", "states"):
            if required not in present:
                raise RecordingIOError(f"required table {required} missing",
                                       path=container.location(TABLES[required].file))
        for name in meta.tables:
            if name not in TABLES:
                raise FormatError(f"recording.json lists unknown table {name!r}",
                                  path=container.location("recording.json"))
            if not container.exists(TABLES[name].file):
                raise RecordingIOError("file listed in recording.json:tables is missing",
                                       path=container.location(TABLES[name].file))
        wanted = present if tables is None else [t for t in present if t in set(tables)]
        if not states:
            wanted = [t for t in wanted if t != "states"]
        if tables is not None:
            unknown = sorted({t for t in tables if t not in TABLES})
            if unknown:
                raise FormatError(f"unknown tables {unknown}; known: {sorted(TABLES)}")
        col_map: dict[str, Sequence[str]] = (
            {"states": columns} if isinstance(columns, (list, tuple)) else dict(columns or {})
        )
        pids = None
        if participants is not None:
            pids = np.unique(np.asarray(list(participants), dtype=np.int64))
        if plan is None:
            plan = ReadPlan()
        loaded = {
            name: read_table(container, name, meta, columns=col_map.get(name), participants=pids,
                             time_range=time_range, verify=verify, plan=plan, migrations=steps)
            for name in wanted
        }
        map_bytes = _read_map(container, meta, verify)
    finally:
        container.close()
    rec = Recording(meta=meta, tables=loaded, map_source=map_bytes, path=Path(path),
                    migrated_from=migrated_from)
    rec.read_plan = plan
    return rec


def _read_map(container: Container, meta: RecordingMeta, verify: bool | None) -> bytes | None:
    name = meta.map.file
    if not container.exists(name):
        raise RecordingIOError("map file missing from the recording", path=container.location(name))
    data = container.read_bytes(name)
    if verify is not False and sha256_of(data) != meta.map.sha256:
        raise ChecksumError("SHA-256 of the map differs from recording.json map.sha256",
                            path=container.location(name))
    return data
