"""Reading tabular sources (CSV with any delimiter, Parquet) with located errors: the file, the
CSV line and the column of a value that is not a number, a missing column, bytes that are not
UTF-8; and turning a column of source ids into participant codes."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from aveas_format.errors import FormatError, RecordingIOError


def read_table(path: Path, *, required: Sequence[str] = (), numeric: Sequence[str] = (),
               delimiter: str | None = None) -> pa.Table:
    """Read a CSV (any delimiter, sniffed from the header) or Parquet file.

    Errors name the file and, for CSV, the line: a row with the wrong number of fields, a missing
    required column, a non-numeric value in a numeric column (with its line and column).
    """
    path = Path(path)
    if not path.is_file():
        raise RecordingIOError("input not found", path=path)
    if path.suffix.lower() == ".parquet":
        try:
            table = pq.read_table(path)
        except (pa.ArrowException, OSError) as e:
            raise RecordingIOError(f"not a readable Parquet file: {str(e).splitlines()[0]}",
                                   path=path) from None
        _check_required(table, required, path)
        return _numeric(table, numeric, path, header_lines=0)
    if delimiter is None:
        with open(path, "rb") as f:
            head = f.readline().decode("utf-8", "replace")
        delimiter = max((",", ";", "\t"), key=head.count) if head else ","
    try:
        table = pacsv.read_csv(
            path, parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(
                column_types={c: pa.string() for c in numeric}, strings_can_be_null=True),
        )
    except pa.ArrowInvalid as e:
        msg = str(e).splitlines()[0]
        m = re.search(r"[Rr]ow #(\d+)", str(e))
        line = int(m.group(1)) if m else None
        raise FormatError(f"malformed CSV: {msg}", path=path, line=line) from None
    try:
        table.column_names  # noqa: B018 — decodes the header
    except UnicodeDecodeError:
        raise FormatError("the CSV header is not UTF-8 text", path=path, line=1) from None
    dup = next((c for i, c in enumerate(table.column_names) if c in table.column_names[:i]), None)
    if dup is not None:
        raise FormatError(f"column {dup!r} appears more than once in the header", path=path, line=1)
    reject_non_utf8(table, path, header_lines=1)
    _check_required(table, required, path)
    return _numeric(table, numeric, path, header_lines=1)


def reject_non_utf8(table: pa.Table, path: Path, header_lines: int = 1) -> None:
    """A CSV column that pyarrow typed as binary holds bytes that are not UTF-8 text: raise a
    :class:`FormatError` naming the column and the line of the first such value (instead of an
    ``ArrowInvalid`` from a later cast to string)."""
    for c, col in zip(table.column_names, table.columns):
        if not (pa.types.is_binary(col.type) or pa.types.is_large_binary(col.type)):
            continue
        for i, v in enumerate(col.to_pylist()):
            if v is None:
                continue
            try:
                v.decode("utf-8")
            except UnicodeDecodeError:
                raise FormatError(f"column {c!r}: value is not UTF-8 text", path=path,
                                  line=i + 1 + header_lines) from None


def _check_required(table: pa.Table, required: Sequence[str], path: Path) -> None:
    missing = [c for c in required if c not in table.column_names]
    if missing:
        raise FormatError(f"required column(s) {missing} missing; found {table.column_names}",
                          path=path)


def _numeric(table: pa.Table, numeric: Sequence[str], path: Path, header_lines: int) -> pa.Table:
    for c in numeric:
        if c not in table.column_names:
            continue
        col = table.column(c)
        if pa.types.is_floating(col.type) or pa.types.is_integer(col.type) or pa.types.is_null(col.type):
            col = col.cast(pa.float64())
        else:
            s = pc.utf8_trim_whitespace(col.cast(pa.string()))
            num = _try_float(s)
            if num is None:
                vals = s.to_pylist()
                bad = next(i for i, v in enumerate(vals) if v not in (None, "") and not is_float(v))
                raise FormatError(f"column {c!r}: {vals[bad]!r} is not a number", path=path,
                                  line=bad + 1 + header_lines if header_lines else None,
                                  row=None if header_lines else bad)
            col = num
        table = table.set_column(table.column_names.index(c), c, col)
    return table


def _try_float(s: pa.ChunkedArray) -> pa.ChunkedArray | None:
    try:
        empty = pc.equal(s, "")
        return pc.if_else(empty, pa.scalar(None, pa.string()), s).cast(pa.float64())
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None


def is_float(v: str) -> bool:
    """Does ``float(v)`` accept the string ``v`` (for locating the first value that is not a
    number)?"""
    try:
        float(v)
        return True
    except ValueError:
        return False


def factorize(values: Sequence[Any] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(codes, uniques) in order of first appearance: source ids -> participant ids 0..n-1."""
    arr = pa.array(np.asarray(values, dtype=object) if not isinstance(values, pa.Array) else values)
    enc = pc.dictionary_encode(arr.cast(pa.string()))
    return enc.indices.to_numpy().astype(np.int64), np.asarray(enc.dictionary.to_pylist(), dtype=object)


def header_names(path: Path, head: bytes) -> set[str]:
    """The column names of a table file, for sniffing: a Parquet file's schema (read from its
    footer), else the first line of ``head`` (a file's first bytes) split at its most frequent
    delimiter (``,``, ``;`` or tab). Empty where there is none or it cannot be read."""
    if Path(path).suffix.lower() == ".parquet":
        try:
            return set(pq.read_schema(path).names)
        except (pa.ArrowException, OSError):
            return set()
    line = head.split(b"\n", 1)[0].decode("utf-8", "replace").strip().lstrip("\ufeff")
    if not line:
        return set()
    delimiter = max((",", ";", "\t"), key=line.count)
    return {c.strip().strip('"') for c in line.split(delimiter)}
