"""Structure rules: files, recording.json, Parquet files, declared columns, types, ranges, keys.

Most of these are generic: they are driven by the column declarations of ``aveas_format.schema``
(STYLE.md 9), so a column declared with a range or categories is checked without a rule of its own.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import jsonschema
import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.io.arrow import arrow_type, types_compatible
from aveas_format.io.container import sha256_of
from aveas_format.schema.metadata import recording_json_schema
from aveas_format.schema.pmf import pmf_problems
from aveas_format.schema.tables import TABLES
from aveas_format.schema.taxonomy import CATEGORY_SETS
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, rule

_REQUIRED_FILES = ("recording.json", "map.xodr", "participants.parquet", "states.parquet")


@rule("structure.missing_file", "error", "Required file missing",
      "{file}: file missing from the recording",
      enforces="docs/format.md §1: recording.json, map.xodr, participants.parquet and states.parquet MUST "
               "exist; every table listed in recording.json:tables must exist")
def missing_file(ctx: Context) -> Iterator[Hit]:
    """A file the format requires, or that recording.json lists, is not in the recording."""
    seen = set()
    for p in ctx.problems_of("missing_file"):
        seen.add(p.fields["file"])
        yield Hit(file=p.fields["file"], table=p.fields.get("table"))
    present = set(ctx.container.names()) if ctx.container else None
    if present is not None:
        for f in _REQUIRED_FILES:
            if f not in present and f not in seen:
                yield Hit(file=f)


@rule("structure.broken_json", "error", "recording.json is not valid JSON",
      "{file}:{line}: not a valid JSON object: {error}",
      enforces="docs/format.md §3: recording.json MUST hold the metadata as JSON")
def broken_json(ctx: Context) -> Iterator[Hit]:
    """recording.json cannot be parsed as a JSON object; nothing in it can be checked."""
    for p in ctx.problems_of("broken_json"):
        yield Hit(**p.fields)


@rule("structure.format_version", "error", "Unsupported format_version",
      "{file}: {error}", enforces="docs/format.md §11: format_version follows semantic versioning")
def format_version(ctx: Context) -> Iterator[Hit]:
    """format_version is missing, malformed, newer than this library, or has no migration path."""
    d = ctx.meta_dict
    if d is not None and "format_version" not in d:
        yield Hit(file="recording.json", error="format_version missing", column="format_version")
        return
    for p in ctx.problems_of("format_version"):
        yield Hit(file=p.fields["file"], error=p.fields["error"], column="format_version")


@rule("structure.metadata_schema", "error", "recording.json violates its schema",
      "{file}: {column}: {error}",
      enforces="docs/format.md §3: the fields of recording.json, their types and required fields")
def metadata_schema(ctx: Context) -> Iterator[Hit]:
    """recording.json fails the JSON Schema of the format (``aveas-format schema``), or a check the
    schema cannot express (PMF sums, calendar dates of timestamps)."""
    d = ctx.meta_dict
    if d is None or ctx.problems_of("format_version"):
        return
    validator = jsonschema.Draft202012Validator(_json_schema())
    errors = sorted(validator.iter_errors(d), key=lambda e: list(e.absolute_path))
    for e in errors:
        path = ".".join(str(p) for p in e.absolute_path) or "(top level)"
        yield Hit(file="recording.json", column=path, error=e.message)
    if not errors:
        _ = ctx.meta
        for p in ctx.problems_of("metadata"):
            yield Hit(**p.fields)


_SCHEMA: dict | None = None


def _json_schema() -> dict:
    global _SCHEMA
    if _SCHEMA is None:
        _SCHEMA = recording_json_schema()
    return _SCHEMA


@rule("structure.unlisted_table", "error", "Table not listed in recording.json",
      "{file}: table {table} is not listed in recording.json:tables",
      enforces="docs/format.md §1: recording.json lists every table with its row count and SHA-256")
def unlisted_table(ctx: Context) -> Iterator[Hit]:
    """A table file is present but recording.json:tables does not list it, so it cannot be checked
    against a checksum. (In-memory recordings get their entries when written.)"""
    d = ctx.meta_dict
    if ctx.recording is not None or d is None or not isinstance(d.get("tables"), dict):
        return
    for name in ctx.table_names:
        if name not in d["tables"]:
            yield Hit(file=TABLES[name].file, table=name)


@rule("structure.unknown_table", "error", "Unknown table in recording.json",
      "recording.json: tables lists {table!r}, which the format does not define",
      enforces="docs/format.md §1: the tables of a recording")
def unknown_table(ctx: Context) -> Iterator[Hit]:
    """recording.json:tables names a table the format does not define."""
    d = ctx.meta_dict
    if d is None or not isinstance(d.get("tables"), dict):
        return
    for name in d["tables"]:
        if name not in TABLES:
            yield Hit(file="recording.json", table=name, column=f"tables.{name}")


@rule("structure.checksum", "error", "Checksum mismatch",
      "{file}: SHA-256 {actual} differs from recording.json ({expected}): changed or truncated "
      "after writing",
      enforces="docs/format.md §1: a mismatch of recording.json's SHA-256 is an error")
def checksum(ctx: Context) -> Iterator[Hit]:
    """A table's or the map's SHA-256 differs from the one recording.json declares."""
    if ctx.container is None:
        return
    d = ctx.meta_dict or {}
    listed = d.get("tables") if isinstance(d.get("tables"), dict) else {}
    for name, entry in listed.items():
        info = ctx.file_info(name) if name in TABLES else {}
        expected = entry.get("sha256") if isinstance(entry, dict) else None
        if info and expected and info["sha256"] != expected:
            yield Hit(file=TABLES[name].file, table=name, actual=info["sha256"][:12] + "…",
                      expected=str(expected)[:12] + "…")
    m = d.get("map") if isinstance(d.get("map"), dict) else {}
    if ctx.map_bytes is not None and m.get("sha256"):
        actual = sha256_of(ctx.map_bytes)
        if actual != m["sha256"]:
            yield Hit(file=m.get("file", "map.xodr"), actual=actual[:12] + "…",
                      expected=str(m["sha256"])[:12] + "…")


@rule("structure.row_count", "error", "Row count mismatch",
      "{file}: {actual} rows, recording.json says {expected}",
      enforces="docs/format.md §1: recording.json lists every table with its row count")
def row_count(ctx: Context) -> Iterator[Hit]:
    """A table has a different number of rows than recording.json declares."""
    d = ctx.meta_dict or {}
    listed = d.get("tables") if isinstance(d.get("tables"), dict) else {}
    for name, entry in listed.items():
        n = ctx.num_rows(name) if name in TABLES else None
        expected = entry.get("rows") if isinstance(entry, dict) else None
        if n is not None and isinstance(expected, int) and n != expected:
            yield Hit(file=TABLES[name].file, table=name, actual=n, expected=expected)


@rule("structure.unreadable_table", "error", "Unreadable Parquet file",
      "{file}: not a readable Parquet file: {error}",
      enforces="docs/format.md §1: tables are Parquet files")
def unreadable_table(ctx: Context) -> Iterator[Hit]:
    """A table file is truncated, corrupt or not Parquet at all."""
    for p in ctx.problems_of("unreadable_table"):
        yield Hit(**p.fields)


@rule("structure.parquet_key", "error", "Missing or invalid 'aveas' Parquet metadata",
      "{file}: Parquet key-value metadata 'aveas' {error}",
      enforces="docs/format.md §1: every Parquet file carries key-value metadata under the key 'aveas'")
def parquet_key(ctx: Context) -> Iterator[Hit]:
    """The ``aveas`` key-value metadata of a table is missing, not JSON, lacks format_version/table,
    or names another table."""
    for name in ctx.table_names:
        if ctx.schema(name) is None:
            continue
        if ctx.recording is not None:
            return  # in-memory tables get their key when written
        raw = ctx.file_info(name).get("kv")
        f = TABLES[name].file
        if raw is None:
            yield Hit(file=f, table=name, error="is missing")
            continue
        try:
            info = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError):
            yield Hit(file=f, table=name, error="is not valid JSON")
            continue
        if not isinstance(info, dict) or "format_version" not in info or "table" not in info:
            yield Hit(file=f, table=name, error="lacks format_version or table")
        elif info["table"] != name:
            yield Hit(file=f, table=name, error=f"names table {info['table']!r}")


@rule("structure.missing_column", "error", "Required column missing",
      "{file}: required column {column!r} missing",
      enforces="docs/format.md §4-10: columns marked MUST")
def missing_column(ctx: Context) -> Iterator[Hit]:
    """A column the format marks MUST is absent from its table."""
    for name in ctx.table_names:
        t = ctx.schema(name)
        if t is None:
            continue
        for c in TABLES[name].required:
            if c.name not in t.names:
                yield Hit(file=TABLES[name].file, table=name, column=c.name)


@rule("structure.column_type", "error", "Column has the wrong type",
      "{file}: column {column!r} has type {actual}, the format declares {expected}",
      enforces="docs/format.md §4-10: the declared type of each column")
def column_type(ctx: Context) -> Iterator[Hit]:
    """A declared column is stored with an incompatible Arrow type (e.g. a string ``x``)."""
    for name in ctx.table_names:
        t = ctx.schema(name)
        if t is None:
            continue
        spec = TABLES[name]
        for f in t:
            c = spec.get(f.name)
            if c is not None and not types_compatible(f.type, arrow_type(c)):
                yield Hit(file=spec.file, table=name, column=f.name, actual=str(f.type),
                          expected=c.type)


@rule("structure.unknown_column", "info", "Column not defined by the format",
      "{file}: column {column!r} is not defined by the format (kept, but not checked)")
def unknown_column(ctx: Context) -> Iterator[Hit]:
    """A table has a column the format does not declare; readers keep it, nothing checks it."""
    for name in ctx.table_names:
        t = ctx.schema(name)
        if t is None:
            continue
        for col in t.names:
            if col not in TABLES[name]:
                yield Hit(file=TABLES[name].file, table=name, column=col)


def _typed_columns(ctx: Context):
    """(table name, spec, column spec, array) for each declared column stored with its type, of the
    tables whose rows this context checks."""
    for name in ctx.row_tables:
        t = ctx.table(name)
        if t is None:
            continue
        spec = TABLES[name]
        for c in spec.columns:
            if c.name in t.column_names and types_compatible(t.column(c.name).type, arrow_type(c)):
                yield name, spec, c, t.column(c.name)


def _keys(t: pa.Table, rows: np.ndarray) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for k in ("participant_id", "time"):
        if k in t.column_names:
            # to_pylist: exact int64 ids (a column with nulls would go through float64)
            out[k] = np.array(t.column(k).take(pa.array(rows[:1000])).to_pylist(), dtype=object)
    return out


@rule("structure.null_values", "error", "Nulls in a non-nullable column",
      "{file}: row {row}: {column} is null",
      enforces="docs/format.md §4-10: key and required values (ids, time, x, y, heading, ...) are never null", scope="rows")
def null_values(ctx: Context) -> Iterator[Hits]:
    """A column that must always hold a value (ids, time, position, heading, velocity, lon/lat,
    class, sizes...) has nulls."""
    for name, spec, c, arr in _typed_columns(ctx):
        if c.nullable:
            continue
        mask = np.asarray(arr.is_null().to_numpy(zero_copy_only=False), bool)
        if c.is_float:  # NaN is how numpy writers spell null
            mask |= np.isnan(pc.fill_null(arr, 0.0).to_numpy(zero_copy_only=False))
        rows = np.flatnonzero(mask)
        if not len(rows):
            continue
        yield Hits(total=len(rows), arrays={"row": rows, **_keys(ctx.table(name), rows)},
                   const={"file": spec.file, "table": name, "column": c.name})


def _exact_numbers(arr: pa.ChunkedArray) -> np.ndarray:
    """A numeric column as numpy without losing precision: integers in their own type (nulls as
    0, to be masked by the caller; float64 holds integers exactly only up to 2**53, and an id of
    2**60 is valid), floats as float64 (nulls as NaN)."""
    if pa.types.is_integer(arr.type):
        return np.asarray(pc.fill_null(arr, 0).to_numpy(zero_copy_only=False))
    return pc.fill_null(arr.cast(pa.float64()), np.nan).to_numpy(zero_copy_only=False)


@rule("structure.value_range", "error", "Value outside the declared range",
      "{file}: row {row}: {column} = {value} outside {range}",
      enforces="docs/format.md §2-10: declared ranges (sizes > 0, std >= 0, probabilities and correlations "
               "in [0, 1] / [-1, 1], heading in (-pi, pi], lon/lat bounds)", scope="rows")
def value_range(ctx: Context) -> Iterator[Hits]:
    """A numeric value lies outside the range its column declares, or is infinite. Null (NaN) is
    not checked here (see structure.null_values)."""
    for name, spec, c, arr in _typed_columns(ctx):
        if c.minimum is None and c.maximum is None and not c.is_float:
            continue
        if not (pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type)):
            continue
        v = _exact_numbers(arr)
        bad = np.isinf(v) if v.dtype.kind == "f" else np.zeros(len(v), bool)
        if c.minimum is not None:
            bad |= (v <= c.minimum) if c.exclusive_minimum else (v < c.minimum)
        if c.maximum is not None:
            bad |= v > c.maximum
        if v.dtype.kind != "f" and arr.null_count:
            bad &= np.asarray(arr.is_valid().to_numpy(zero_copy_only=False), bool)
        if not bad.any():
            continue
        rows = np.flatnonzero(bad)
        yield Hits(total=len(rows),
                   arrays={"row": rows, "value": v[rows], **_keys(ctx.table(name), rows)},
                   const={"file": spec.file, "table": name, "column": c.name,
                          "range": c.range_text() or "finite values"})


@rule("structure.category", "error", "Value not in the allowed categories",
      "{file}: row {row}: {column} = {value!r} is not one of the allowed values",
      enforces="docs/format.md §4-7: class is one of the 13 classes; role, provenance, kind, origin are "
               "enumerations", scope="rows")
def category(ctx: Context) -> Iterator[Hits]:
    """A categorical column (class, role, provenance, kind, relation...) holds a value outside its
    enumeration."""
    for name, spec, c, arr in _typed_columns(ctx):
        if not c.categories:
            continue
        s = arr.cast(pa.string()) if pa.types.is_dictionary(arr.type) else arr
        bad = pc.and_(pc.invert(pc.is_in(s, value_set=pa.array(c.categories))), pc.is_valid(s))
        mask = np.asarray(bad.to_numpy(zero_copy_only=False), bool)
        if mask.any():
            rows = np.flatnonzero(mask)
            vals = s.take(pa.array(rows[:1000])).to_pylist()
            yield Hits(total=len(rows), arrays={"row": rows, "value": vals,
                                                **_keys(ctx.table(name), rows)},
                       const={"file": spec.file, "table": name, "column": c.name})


@rule("structure.pmf", "error", "PMF not normalised",
      "{file}: row {row}: {column} is not a PMF (fields >= 0 summing to 1 ± 1e-3; sum = {sum})",
      enforces="docs/format.md §2: PMF fields are >= 0 and sum to 1 (tolerance 1e-3)", scope="rows")
def pmf(ctx: Context) -> Iterator[Hits]:
    """A PMF struct column (class_pmf, weather, ...) has a row with negative or non-finite fields or
    a sum that differs from 1 by more than 1e-3."""
    for name, spec, c, arr in _typed_columns(ctx):
        if not c.pmf_set:
            continue
        cats = CATEGORY_SETS[c.pmf_set]
        chunk = arr.combine_chunks() if isinstance(arr, pa.ChunkedArray) else arr
        m = np.column_stack([pc.fill_null(pc.struct_field(chunk, k).cast(pa.float64()), np.nan)
                             .to_numpy(zero_copy_only=False) for k in cats]) if len(chunk) else \
            np.zeros((0, len(cats)))
        if chunk.null_count:
            m[np.asarray(chunk.is_null().to_numpy(zero_copy_only=False), bool)] = np.nan
        bad = pmf_problems(m)
        if bad.any():
            rows = np.flatnonzero(bad)
            yield Hits(total=len(rows), arrays={"row": rows, "sum": np.round(np.nansum(m[rows], 1), 6),
                                                **_keys(ctx.table(name), rows)},
                       const={"file": spec.file, "table": name, "column": c.name})


def _key_arrays(t: pa.Table, keys: tuple[str, ...]) -> list[np.ndarray] | None:
    out = []
    for k in keys:
        if k not in t.column_names:
            return None
        a = t.column(k)
        if pa.types.is_dictionary(a.type):
            a = a.cast(pa.string())
        out.append(a.to_numpy(zero_copy_only=False))
    return out


@rule("structure.sort_order", "error", "Rows not in the declared order",
      "{file}: row {row} ({participant_id}, {time}) comes before the row after it in "
      "(participant_id, time) order",
      enforces="docs/format.md §5: states.parquet is sorted by participant_id, time")
def sort_order(ctx: Context) -> Iterator[Hits]:
    """A table with a declared order (states, interior: participant_id then time) is not sorted."""
    for name in ("states", "interior"):
        t = ctx.key_table(name, ("participant_id", "time")) if name in ctx.table_names else None
        if t is None or t.num_rows < 2:
            continue
        keys = _key_arrays(t, ("participant_id", "time"))
        if keys is None:
            continue
        pid, tm = keys
        if pid.dtype == object or tm.dtype == object:
            continue
        bad = (pid[1:] < pid[:-1]) | ((pid[1:] == pid[:-1]) & (tm[1:] < tm[:-1]))
        if bad.any():
            rows = np.flatnonzero(bad)
            yield Hits(total=len(rows), arrays={"row": rows, "participant_id": pid[rows],
                                                "time": tm[rows]},
                       const={"file": TABLES[name].file, "table": name})


@rule("structure.duplicate_key", "error", "Duplicate key",
      "{file}: row {row}: key ({key}) = {value} repeats an earlier row",
      enforces="docs/format.md §4-10: participant_id unique; (participant_id, time) unique; region_id, "
               "event_id, conflict_id unique")
def duplicate_key(ctx: Context) -> Iterator[Hits]:
    """Two rows share the key of their table (participant_id in participants; (participant_id,
    time) in states; region_id, event_id, ...)."""
    for name in ctx.table_names:
        spec = TABLES[name]
        t = ctx.key_table(name) if spec.key else None
        if t is None or t.num_rows < 2 or not spec.key:
            continue
        keys = _key_arrays(t, spec.key)
        if keys is None or any(k.dtype == object and len(spec.key) > 2 for k in keys):
            continue
        try:
            order = np.lexsort(tuple(reversed(keys)))
        except TypeError:
            continue
        same = np.ones(len(order) - 1, dtype=bool)
        for k in keys:
            ks = k[order]
            same &= ks[1:] == ks[:-1]
        if same.any():
            rows = np.sort(order[1:][same])
            vals = [", ".join(str(k[r]) for k in keys) for r in rows[:1000]]
            yield Hits(total=len(rows), arrays={"row": rows, "value": vals},
                       const={"file": spec.file, "table": name, "key": ", ".join(spec.key)})
