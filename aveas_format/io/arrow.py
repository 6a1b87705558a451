"""Arrow schemas derived from the column declarations of ``aveas_format.schema``.

- :func:`arrow_type` maps a logical type (``float64``, ``dict<string>``, ``pmf<class>``...) to Arrow.
- :func:`arrow_schema` gives the full Arrow schema of a table (or of a subset of its columns).
- :func:`conform` casts a user's table to the declared types (ints -> int64, strings -> dictionary,
  lists of floats -> PMF structs...), keeps undeclared columns after the declared ones, and names the
  column when a cast is impossible.
- :func:`pmf_matrix` / :func:`pmf_array` convert PMF struct columns to and from (n, k) numpy arrays.
- :func:`column_numpy` reads a numeric column as numpy (nulls as NaN, an absent column as asked).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.errors import FormatError
from aveas_format.schema.columns import Column, TableSpec
from aveas_format.schema.taxonomy import CATEGORY_SETS

_SCALARS: dict[str, pa.DataType] = {
    "int64": pa.int64(),
    "int32": pa.int32(),
    "int16": pa.int16(),
    "int8": pa.int8(),
    "float64": pa.float64(),
    "float32": pa.float32(),
    "bool": pa.bool_(),
    "string": pa.string(),
    "binary": pa.binary(),
    "dict<string>": pa.dictionary(pa.int32(), pa.string()),
    "list<int64>": pa.list_(pa.int64()),
    "list<string>": pa.list_(pa.string()),
}


def pmf_type(set_name: str) -> pa.StructType:
    """The Arrow struct type of a PMF over a category set: one float32 field per category."""
    return pa.struct([pa.field(c, pa.float32()) for c in CATEGORY_SETS[set_name]])


def arrow_type(column: Column) -> pa.DataType:
    if column.pmf_set:
        return pmf_type(column.pmf_set)
    return _SCALARS[column.type]


def arrow_field(column: Column) -> pa.Field:
    meta = {"unit": column.unit} if column.unit else None
    return pa.field(column.name, arrow_type(column), nullable=column.nullable, metadata=meta)


def arrow_schema(spec: TableSpec, columns: Iterable[str] | None = None) -> pa.Schema:
    """The Arrow schema of a table: every declared column, or the named ones in declared order."""
    names = set(columns) if columns is not None else None
    return pa.schema([arrow_field(c) for c in spec.columns if names is None or c.name in names])


def types_compatible(actual: pa.DataType, expected: pa.DataType) -> bool:
    """Is ``actual`` the declared type (dictionary index width and large variants are tolerated)?"""
    if actual.equals(expected):
        return True
    if pa.types.is_dictionary(expected):
        if pa.types.is_dictionary(actual):
            return pa.types.is_integer(actual.index_type) and (
                pa.types.is_string(actual.value_type) or pa.types.is_large_string(actual.value_type)
            )
        return False
    if pa.types.is_string(expected):
        return pa.types.is_large_string(actual)
    if pa.types.is_binary(expected):
        return pa.types.is_large_binary(actual)
    if pa.types.is_list(expected) and (pa.types.is_list(actual) or pa.types.is_large_list(actual)):
        return types_compatible(actual.value_type, expected.value_type)
    return False


def _cast_column(arr: pa.ChunkedArray, column: Column, expected: pa.DataType) -> pa.ChunkedArray:
    if types_compatible(arr.type, expected):
        if pa.types.is_dictionary(expected) and not arr.type.equals(expected):
            return arr.cast(expected)
        return arr
    if column.pmf_set:
        return pa.chunked_array([_to_pmf_struct(chunk, column) for chunk in arr.chunks], expected)
    if pa.types.is_dictionary(arr.type):
        arr = arr.cast(arr.type.value_type)
    if pa.types.is_floating(arr.type) and pa.types.is_integer(expected):
        # only exact integers may become integers
        vals = arr.to_numpy(zero_copy_only=False)
        finite = vals[~np.isnan(vals)]
        if not np.all(finite == np.round(finite)):
            raise pa.ArrowInvalid("non-integer values")
    if pa.types.is_dictionary(expected) and not (
        pa.types.is_string(arr.type) or pa.types.is_large_string(arr.type) or pa.types.is_null(arr.type)
    ):
        raise pa.ArrowInvalid(f"expected strings, got {arr.type}")
    return arr.cast(expected, safe=True)


def _to_pmf_struct(chunk: pa.Array, column: Column) -> pa.Array:
    cats = column.pmf_categories or ()
    t = chunk.type
    if pa.types.is_struct(t):
        names = [t.field(i).name for i in range(t.num_fields)]
        if set(names) != set(cats):
            missing = sorted(set(cats) - set(names))
            extra = sorted(set(names) - set(cats))
            raise pa.ArrowInvalid(f"PMF fields differ from the category set (missing {missing}, "
                                  f"unknown {extra})")
        fields = [pc.struct_field(chunk, names.index(c)).cast(pa.float32()) for c in cats]
        return pa.StructArray.from_arrays(fields, names=list(cats), mask=chunk.is_null())
    if pa.types.is_list(t) or pa.types.is_fixed_size_list(t) or pa.types.is_large_list(t):
        lengths = pc.list_value_length(chunk).to_numpy(zero_copy_only=False)
        ok = np.isnan(lengths.astype(float)) | (lengths == len(cats))
        if not ok.all():
            raise pa.ArrowInvalid(f"PMF lists must have {len(cats)} entries ({', '.join(cats)})")
        flat = pc.list_flatten(chunk).cast(pa.float32()).to_numpy(zero_copy_only=False)
        valid = ~np.asarray(chunk.is_null().to_numpy(zero_copy_only=False), bool)
        m = np.full((len(chunk), len(cats)), np.nan, np.float32)
        m[valid] = flat.reshape(-1, len(cats))
        return pmf_array(m, column.pmf_set or "", mask=~valid)
    raise pa.ArrowInvalid(f"cannot make a PMF struct from {t}")


def conform(table: pa.Table, spec: TableSpec, *, where: str | None = None) -> pa.Table:
    """Cast the declared columns of ``table`` to their declared types; keep others at the end.

    Raises FormatError naming the table and column when a value cannot be represented (e.g. a
    fractional participant_id, text in a float column, a PMF with the wrong fields).
    """
    arrays, fields = [], []
    declared = [c for c in spec.columns if c.name in table.column_names]
    for c in declared:
        expected = arrow_type(c)
        try:
            arr = _cast_column(table.column(c.name), c, expected)
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError) as e:
            raise FormatError(
                f"column {c.name!r} of table {spec.name} has type {table.column(c.name).type}, "
                f"declared {c.type}: {str(e).splitlines()[0]}", path=where,
            ) from None
        arrays.append(arr)
        fields.append(pa.field(c.name, arr.type, nullable=True,
                               metadata={"unit": c.unit} if c.unit else None))
    for name in table.column_names:
        if name not in spec:
            arrays.append(table.column(name))
            fields.append(table.schema.field(name))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata=table.schema.metadata))


# --- PMF columns <-> numpy ---------------------------------------------------------------------

def pmf_matrix(arr: pa.ChunkedArray | pa.Array, set_name: str) -> np.ndarray:
    """(n, k) float32 matrix of a PMF struct column; null rows are all-NaN."""
    cats = CATEGORY_SETS[set_name]
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks() if arr.num_chunks != 1 else arr.chunk(0)
    out = np.empty((len(arr), len(cats)), dtype=np.float32)
    for i, c in enumerate(cats):
        out[:, i] = pc.struct_field(arr, c).to_numpy(zero_copy_only=False).astype(np.float32)
    if arr.null_count:
        out[np.asarray(arr.is_null().to_numpy(zero_copy_only=False), bool)] = np.nan
    return out


def pmf_array(matrix: np.ndarray, set_name: str, mask: np.ndarray | None = None) -> pa.StructArray:
    """A PMF struct array from an (n, k) matrix (optional null mask)."""
    cats = CATEGORY_SETS[set_name]
    m = np.asarray(matrix, dtype=np.float32)
    if m.ndim != 2 or m.shape[1] != len(cats):
        raise ValueError(f"PMF matrix must have shape (n, {len(cats)}), got {m.shape}")
    fields = [pa.array(m[:, i], pa.float32()) for i in range(len(cats))]
    return pa.StructArray.from_arrays(
        fields, names=list(cats), mask=None if mask is None else pa.array(np.asarray(mask, bool))
    )


def column_numpy(table: pa.Table | None, name: str, dtype: type = np.float64, *,
                 null: float = np.nan, nonfinite: float | None = None,
                 missing: float | Literal["raise"] | None = "raise") -> np.ndarray | None:
    """A numeric column as a numpy array (float64 by default) with nulls as NaN: the one helper
    that the converters, derivations, validator and figures read numeric columns with.

    Zero-copy (a read-only view) for a floating column without nulls in one chunk; otherwise a
    copy (integers and booleans converted by numpy, nulls filled by Arrow).

    - ``null``: the value of a null entry (NaN unless given);
    - ``nonfinite``: if given, nulls, NaN and ±inf all read as this value (a default for what is
      undefined, e.g. 0 for an unknown standard deviation);
    - ``missing``: what an absent column (or ``table`` None) gives: ``"raise"`` (KeyError, as
      :meth:`pyarrow.Table.column`), None, or a number (an array of it, one per row).
    """
    if table is None or name not in table.column_names:
        if missing is None:
            return None
        if isinstance(missing, str):
            if table is None:
                raise KeyError(f"no table to read column {name!r} from")
            table.column(name)  # raises the KeyError naming the column
        return np.full(table.num_rows, missing, dtype=dtype)
    arr = table.column(name)
    if arr.null_count == 0 and arr.num_chunks == 1 and pa.types.is_floating(arr.type):
        out = arr.chunk(0).to_numpy().astype(dtype, copy=False)
    elif arr.null_count == 0:
        out = arr.to_numpy().astype(dtype, copy=False)
    else:
        out = pc.fill_null(arr.cast(pa.float64()), null).to_numpy().astype(dtype, copy=False)
    return out if nonfinite is None else np.where(np.isfinite(out), out, nonfinite)
