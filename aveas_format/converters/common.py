"""Pieces every converter uses: reading tabular sources with located errors, moving reference
points, angle conventions, and finishing a recording with its ``source`` block."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aveas_format._version import __version__
from aveas_format.errors import FormatError, RecordingIOError
from aveas_format.io.builder import build_recording, load_map_bytes

__all__ = [
    "build_recording", "column", "factorize", "file_sha256", "load_map_bytes", "move_along_heading",
    "navigation_deg_to_heading", "read_table", "source_block", "wrap_recording",
]


def file_sha256(path: Path, chunk: int = 1 << 22) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def source_block(converter: str, inputs: Iterable[Path], options: Any, version: str = "1"
                 ) -> dict[str, Any]:
    """The recording.json ``source`` object: converter, versions, input names + SHA-256, options."""
    opts = options.model_dump(mode="json") if hasattr(options, "model_dump") else dict(options or {})
    return {
        "converter": converter,
        "converter_version": f"{version} (aveas-format {__version__})",
        "inputs": [{"file": Path(p).name, "sha256": file_sha256(Path(p))} for p in inputs],
        "options": opts,
    }


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
        except (pa.ArrowInvalid, OSError) as e:
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
        import re

        m = re.search(r"[Rr]ow #(\d+)", str(e))
        line = int(m.group(1)) if m else None
        raise FormatError(f"malformed CSV: {msg}", path=path, line=line) from None
    _check_required(table, required, path)
    return _numeric(table, numeric, path, header_lines=1)


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
        if pa.types.is_floating(col.type) or pa.types.is_integer(col.type):
            col = col.cast(pa.float64())
        else:
            s = pc.utf8_trim_whitespace(col.cast(pa.string()))
            num = _try_float(s)
            if num is None:
                vals = s.to_pylist()
                bad = next(i for i, v in enumerate(vals) if v not in (None, "") and not _is_float(v))
                raise FormatError(f"column {c!r}: {vals[bad]!r} is not a number", path=path,
                                  line=bad + 1 + header_lines if header_lines else None,
                                  row=None if header_lines else bad)
            col = num
        table = table.set_column(table.column_names.index(c), c, col)
    return table


def _try_float(s: pa.ChunkedArray) -> pa.ChunkedArray | None:
    try:
        empty = pc.equal(s, "")
        return pc.if_else(empty, pa.scalar(None, pa.float64()), s).cast(pa.float64())
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None


def _is_float(v: str) -> bool:
    try:
        float(v)
        return True
    except ValueError:
        return False


def column(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as float64 numpy (nulls -> NaN)."""
    return pc.fill_null(table.column(name).cast(pa.float64()), np.nan).to_numpy()


# --- reference points and angles -----------------------------------------------------------------

def move_along_heading(x: np.ndarray, y: np.ndarray, heading: np.ndarray, d: np.ndarray | float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Move points by ``d`` metres along their heading (negative = backwards).

    SUMO's front bumper -> footprint centre is ``d = -length / 2``.
    """
    return x + d * np.cos(heading), y + d * np.sin(heading)


def navigation_deg_to_heading(angle_deg: np.ndarray) -> np.ndarray:
    """Navigational degrees (0 = north, clockwise) -> heading (rad, counter-clockwise from +x,
    wrapped to (-pi, pi])."""
    from aveas_format.io.builder import wrap_angle

    return wrap_angle(np.pi / 2 - np.radians(angle_deg))


def factorize(values: Sequence[Any] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(codes, uniques) in order of first appearance: source ids -> participant ids 0..n-1."""
    arr = pa.array(np.asarray(values, dtype=object) if not isinstance(values, pa.Array) else values)
    enc = pc.dictionary_encode(arr.cast(pa.string()))
    return enc.indices.to_numpy().astype(np.int64), np.asarray(enc.dictionary.to_pylist(), dtype=object)


def wrap_recording(converter: str, inputs: Sequence[Path], options: Any, *, map_bytes: bytes,
                   participants: dict[str, Any], states: dict[str, Any], version: str = "1",
                   partner: str = "unknown", start_time: str = "1970-01-01T00:00:00Z",
                   **kw: Any):
    """Finish a conversion: build the recording (lon/lat and road coordinates through the map,
    defaults filled) with the ``source`` block naming the converter, inputs and options.

    ``partner``/``start_time`` are the converter's defaults (e.g. from the source's metadata); the
    common import options (:class:`~aveas_format.converters.registry.ImportOptions`) override them.
    """
    o = options
    partner = getattr(o, "partner", None) or partner
    meta: dict[str, Any] = {
        "start_time": getattr(o, "start_time", None) or start_time,
        "rights": {"right_of_use": getattr(o, "right_of_use", "research_only"),
                   "license": getattr(o, "license", "unspecified"),
                   "owner": getattr(o, "owner", None) or partner},
    }
    for key in ("recording_id", "title"):
        if getattr(o, key, None):
            meta[key] = getattr(o, key)
    meta.update(kw)
    return build_recording(map_source=map_bytes, participants=participants, states=states,
                           partner=partner, source=source_block(converter, inputs, options, version),
                           **meta)
