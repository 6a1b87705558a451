"""The boxes' rows of a large OpenLABEL import spilled to disk as they are read (bounded memory).

:class:`RowSpill` takes the place of the in-memory column store of
:class:`~aveas_format.converters.openlabel.frames._FrameRows` when an import writes its recording
itself (:mod:`.parts`): each block's columns and extension members go to Arrow IPC files (lz4) in
a hidden temporary directory next to the output — written by the worker process that read the
block (:func:`write_rows`, :meth:`RowSpill.adopt`: the columns are not pickled and sent back;
at 2 M boxes the main process's CPU in the frames 5.6 -> 3.8 s, the import 12.0 -> 10.9 s), or
here for the blocks read before the spill began; per box only its object and frame occurrence
stay in memory (int32 each). A block whose values Arrow cannot give back exactly (texts mixed with numbers, an integer
among floats, nested values) ends the spill: what was spilled is read back into memory
(:meth:`RowSpill.load_into`; blocks the workers spill after that: :func:`read_rows`) and the
import goes on as without it.

The extension members (``ext``: per column ``("f", values, present, null)`` or ``("o", objects)``,
:func:`~aveas_format.converters.openlabel.columns.ext_rep`) are spilled as columns of their own:
``__ef:``/``__ep:``/``__en:`` for floats, ``__eo:``/``__em:`` (the value; missing) for objects.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa

from aveas_format.converters.openlabel.columns import _MISSING

#: object columns are spilled only where Arrow gives back the same Python values
_EXACT_TYPES = (pa.null(), pa.string(), pa.int64(), pa.bool_())
#: the spills' Arrow IPC options (one home: the export's and the import's spills): lz4, or none;
#: written and read in the calling thread — the spills are written and read by processes that
#: keep every core busy already, where Arrow's thread pool only adds wake-ups (at 9.2 M boxes a
#: quarter of the import's pass went into waking threads)
LZ4 = pa.ipc.IpcWriteOptions(compression="lz4", use_threads=False)
PLAIN = pa.ipc.IpcWriteOptions(use_threads=False)
READ = pa.ipc.IpcReadOptions(use_threads=False)
#: up to this many bytes of rows, a pass's bucket files (the import's boxes and states, the
#: export's states) are written uncompressed: read back soon from the page cache (2 M boxes: the
#: import's pass 1.3 -> 0.8 s; 2 M states: the export's 1.75 -> 1.5 s, reading every bucket back
#: 0.21 -> 0.01 s of CPU); above, lz4 (9.2 M boxes: the kernel's writeback of 3.3 GB uncompressed
#: cost as much time as it saved)
PLAIN_BUCKETS_BYTES = 1 << 30


def bucket_options(nbytes: float) -> pa.ipc.IpcWriteOptions:
    """The IPC options of a pass's bucket files for ``nbytes`` of rows in all
    (:data:`PLAIN_BUCKETS_BYTES`)."""
    return PLAIN if nbytes <= PLAIN_BUCKETS_BYTES else LZ4
#: the spills' files are written through a buffer of this many bytes: one write() per buffer
#: instead of one per column's buffer of each batch (a 300-row slice of a block's ~45 columns
#: written lz4: 11.5 -> 3.6 ms of CPU with LZ4's one thread) ...
SINK_BUFFER = 1 << 20
#: ... and of this many where a file per bucket is open at once (:func:`write_by_bucket`: up to
#: 256 buffers; 3.8 ms for that slice)
BUCKET_SINK_BUFFER = 256 << 10
_KEYS = ("uidx", "occ")
#: the field metadata of a column that was an object column (given back as one)
_OBJECTS = {b"aveas_objects": b"1"}


class IpcWriter:
    """An Arrow IPC stream (``file``: an IPC file) at ``path`` written through a buffer of
    ``buffer`` bytes; :meth:`close` closes the file under it too."""

    def __init__(self, path: Path | str, schema: pa.Schema, options: pa.ipc.IpcWriteOptions = LZ4,
                 file: bool = False, buffer: int = SINK_BUFFER) -> None:
        self._sink = pa.output_stream(str(path), compression=None, buffer_size=buffer)
        try:
            self._writer = (pa.ipc.new_file if file else pa.ipc.new_stream)(self._sink, schema, options=options)
        except BaseException:
            self._sink.close()
            raise

    def write_batch(self, batch: pa.RecordBatch) -> None:
        self._writer.write_batch(batch)

    def write_table(self, table: pa.Table) -> None:
        self._writer.write_table(table)

    def close(self) -> None:
        if self._sink.closed:
            return
        try:
            self._writer.close()
        finally:
            self._sink.close()

    def __enter__(self) -> IpcWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _objects_arrow(a: np.ndarray) -> pa.Array | None:
    """An object column as Arrow (None: not exactly)."""
    if len(a) and a[0] is None and (a == None).all():  # noqa: E711 - elementwise (Arrow's inference of
        return pa.nulls(len(a))  # all None: ~1 ms per block, this ~0.05 ms)
    first = next((v for v in a if v is not None), None)
    if type(first) is str:  # texts (road ids): typed, 7x faster than inferred; anything but a text
        try:  # or None raises (a JSON parser gives no bytes, which Arrow would take)
            return pa.array(a, type=pa.string(), from_pandas=False)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            pass
    try:
        arr = pa.array(a, from_pandas=False)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, ValueError, OverflowError):
        return None
    return arr if arr.type in _EXACT_TYPES else None


def _objects_numpy(arr: pa.Array | pa.ChunkedArray) -> np.ndarray:
    """An object column back as the Python values it held (None for a null), by type: texts as
    Arrow gives them to numpy, numbers and booleans through their numpy array (3-40x faster than
    a Python list of every value; the same values and types:
    tests/converters/test_openlabel_parts.py)."""
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks() if arr.num_chunks != 1 else arr.chunk(0)
    t = arr.type
    if pa.types.is_null(t) or arr.null_count == len(arr):
        return np.full(len(arr), None, object)
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return arr.to_numpy(zero_copy_only=False)
    if pa.types.is_integer(t) or pa.types.is_boolean(t):
        if not arr.null_count:
            return arr.to_numpy(zero_copy_only=False).astype(object)
        filled = arr.fill_null(False if pa.types.is_boolean(t) else 0)
        out = filled.to_numpy(zero_copy_only=False).astype(object)
        out[arr.is_null().to_numpy(zero_copy_only=False)] = None
        return out
    out = np.empty(len(arr), object)
    out[:] = arr.to_pylist()
    return out


def to_batch(ch: dict[str, np.ndarray], ext: dict[str, tuple]) -> pa.RecordBatch | None:
    """A block's columns and extension members as one record batch (None: not exactly)."""
    fields, arrays = [], []
    for c, a in ch.items():
        if c in _KEYS:
            continue
        arr = _objects_arrow(a) if a.dtype == object else pa.array(a)
        if arr is None:
            return None
        fields.append(pa.field(c, arr.type, metadata=_OBJECTS if a.dtype == object else None))
        arrays.append(arr)
    for c, rep in ext.items():
        if rep[0] == "f":
            arrays += [pa.array(rep[1], pa.float64()), pa.array(rep[2]), pa.array(rep[3])]
            fields += [pa.field(f"__e{k}:{c}", a.type) for k, a in zip("fpn", arrays[-3:])]
            continue
        vals = rep[1]
        missing = np.asarray(vals == _MISSING, bool)  # (elementwise; the marker equals only itself)
        given = vals.copy()
        given[missing] = None
        arr = _objects_arrow(given)
        if arr is None:
            return None
        arrays += [arr, pa.array(missing)]
        fields += [pa.field(f"__eo:{c}", arr.type), pa.field(f"__em:{c}", pa.bool_())]
    return pa.RecordBatch.from_arrays(arrays, schema=pa.schema(fields))


def _floats(col: pa.Array | pa.ChunkedArray) -> np.ndarray:
    return col.to_numpy(zero_copy_only=False) if col.null_count == 0 else \
        col.fill_null(np.nan).to_numpy(zero_copy_only=False)


def _bools(col: pa.Array | pa.ChunkedArray) -> np.ndarray:
    if pa.types.is_null(col.type):
        return np.zeros(len(col), bool)
    return col.fill_null(False).to_numpy(zero_copy_only=False)


def from_table(t: pa.Table | pa.RecordBatch) -> tuple[dict[str, np.ndarray], dict[str, tuple]]:
    """:func:`to_batch` undone: ``(columns, extension members)`` (other ``__`` columns skipped;
    a member's columns all null where a block had not got it: missing there)."""
    ch: dict[str, np.ndarray] = {}
    ext: dict[str, tuple] = {}
    n = t.num_rows
    for fld in t.schema:
        c = fld.name
        col = t.column(c)
        if c.startswith("__ef:"):
            m = c[5:]
            ext[m] = ("f", _floats(col), _bools(t.column(f"__ep:{m}")), _bools(t.column(f"__en:{m}")))
        elif c.startswith("__eo:"):
            m = c[5:]
            vals = _objects_numpy(col)
            missing = t.column(f"__em:{m}")
            vals[_bools(missing) | (missing.is_null().to_numpy(zero_copy_only=False)
                                    if missing.null_count else np.zeros(n, bool))] = _MISSING
            ext[m] = ("o", vals)
        elif c.startswith("__"):
            continue
        elif fld.metadata == _OBJECTS or pa.types.is_null(col.type):
            ch[c] = _objects_numpy(col)  # (an object column: the same Python values)
        elif pa.types.is_floating(col.type):
            ch[c] = _floats(col)
        elif col.null_count:  # (no block had it: none)
            ch[c] = _objects_numpy(col)
        else:  # (numbers and booleans of numpy columns, the keys the pass adds)
            ch[c] = col.to_numpy(zero_copy_only=False)
    return ch, ext


def write_rows(path: Path, ch: dict[str, np.ndarray], ext: dict[str, tuple]) -> tuple[str, int, int] | None:
    """A block's columns and extension members (:func:`to_batch`) as an Arrow IPC file of their
    own at ``path`` (lz4) — by a worker process that read the block, for :meth:`RowSpill.adopt`:
    ``(path, rows, bytes in memory)``; None where they cannot be spilled exactly (nothing
    written)."""
    batch = to_batch(ch, ext)
    if batch is None:
        return None
    with IpcWriter(path, batch.schema, LZ4, file=True) as w:
        w.write_batch(batch)
    return str(path), batch.num_rows, batch.nbytes


def read_rows(path: str) -> tuple[dict[str, np.ndarray], dict[str, tuple]]:
    """A file of :func:`write_rows` back as ``(columns, extension members)``, the file removed."""
    with pa.OSFile(path) as f:
        t = pa.ipc.open_file(f, options=READ).read_all()
    os.unlink(path)
    return from_table(t)


def write_by_bucket(writers: dict, table: pa.Table, buckets: np.ndarray, path_of, options=LZ4) -> None:
    """The rows of ``table`` appended to their buckets' Arrow IPC streams (``buckets``: each
    row's bucket, sorted; ``writers``: the streams open so far by bucket, a new one at
    ``path_of(bucket)``) — the spills' transpose, one home for the export's and the import's."""
    cuts = np.r_[0, np.flatnonzero(buckets[1:] != buckets[:-1]) + 1, len(buckets)]
    for lo, hi in zip(cuts[:-1].tolist(), cuts[1:].tolist()):
        k = int(buckets[lo])
        w = writers.get(k)
        if w is None:
            w = writers[k] = IpcWriter(path_of(k), table.schema, options, buffer=BUCKET_SINK_BUFFER)
        w.write_table(table.slice(lo, hi - lo))


class RowSpill:
    """The blocks' rows in Arrow IPC files in a temporary directory in ``parent`` (a file per run
    of blocks with one schema written here, a file per block written by the worker process that
    read it: :meth:`adopt`), their object and frame occurrence indices in memory."""

    def __init__(self, parent: Path) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix=".openlabel-rows.", dir=parent))
        self._owner = os.getpid()
        self.files: list[Path] = []
        #: per spilled batch: (file, its batch in the file, first row, rows)
        self.index: list[tuple[int, int, int, int]] = []
        self._writer: IpcWriter | None = None
        self.uidx: list[np.ndarray] = []
        self.occ: list[np.ndarray] = []
        self.n = 0
        self.row_bytes = 0.0

    def append(self, ch: dict[str, np.ndarray], ext: dict[str, tuple]) -> bool:
        """One block (``ch`` with its ``uidx`` and ``occ``); False where it cannot be spilled
        exactly (nothing written)."""
        batch = to_batch(ch, ext)
        if batch is None:
            return False
        if self._writer is None or batch.schema != self._writer_schema:
            self._close_writer()
            path = self.dir / f"r{len(self.files)}.arrow"
            self._writer = IpcWriter(path, batch.schema, LZ4, file=True)
            self._writer_schema = batch.schema
            self.files.append(path)
            self._in_file = 0
        self._writer.write_batch(batch)
        self.index.append((len(self.files) - 1, self._in_file, self.n, batch.num_rows))
        self._in_file += 1
        self.uidx.append(np.asarray(ch["uidx"], np.int32))
        self.occ.append(np.asarray(ch["occ"], np.int32))
        self.n += batch.num_rows
        if not self.row_bytes and batch.num_rows:
            self.row_bytes = batch.nbytes / batch.num_rows
        return True

    def adopt(self, block: tuple[str, int, int], uidx: np.ndarray, occ: np.ndarray) -> None:
        """One block spilled by the process that read it (:func:`write_rows`' ``(path, rows,
        bytes)``, the file in :attr:`dir`), with its rows' object and frame occurrence indices."""
        path, rows, nbytes = block
        self.files.append(Path(path))
        self.index.append((len(self.files) - 1, 0, self.n, rows))
        self.uidx.append(np.asarray(uidx, np.int32))
        self.occ.append(np.asarray(occ, np.int32))
        self.n += rows
        if not self.row_bytes and rows:
            self.row_bytes = nbytes / rows

    def _close_writer(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def batches(self, lo: int = 0, hi: int | None = None) -> Iterator[pa.RecordBatch]:
        """The spilled batches ``lo`` to ``hi`` (default: all), in the order they came."""
        self._close_writer()
        at, reader = -1, None
        for f, b, _, _ in self.index[lo:hi]:
            if f != at:  # (one file open at a time: a file per block where the workers spilled)
                at, reader = f, pa.ipc.open_file(pa.OSFile(str(self.files[f])), options=READ)  # (read, not mapped: no file pages counted as ours)
            yield reader.get_batch(b)

    def schema(self) -> pa.Schema:
        """One schema for every batch (a column a block lacks: null there)."""
        self._close_writer()
        schemas = []
        for path in self.files:
            with pa.OSFile(str(path)) as f:
                schemas.append(pa.ipc.open_file(f, options=READ).schema)
        return pa.unify_schemas(schemas, promote_options="permissive") if schemas else pa.schema([])

    def keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Per spilled row its object index and frame occurrence (int32, handed over)."""
        uidx = np.concatenate(self.uidx) if self.uidx else np.zeros(0, np.int32)
        occ = np.concatenate(self.occ) if self.occ else np.zeros(0, np.int32)
        self.uidx, self.occ = [uidx], [occ]
        return uidx, occ

    def load_into(self, keep) -> None:
        """Every spilled block given to ``keep(ch, ext)`` as it came (with its ``uidx`` and
        ``occ``), in order; the files removed."""
        uidx, occ = self.keys()
        offset = 0
        for batch in self.batches():
            ch, ext = from_table(batch)
            m = batch.num_rows
            ch["uidx"], ch["occ"] = uidx[offset:offset + m].astype(np.int64), occ[offset:offset + m].astype(np.int64)
            keep(ch, ext)
            offset += m
        self._close_writer()
        for path in self.files:  # (the directory stays: blocks in flight may still be written
            path.unlink(missing_ok=True)  # into it; :meth:`close` removes it)
        self.files, self.index = [], []

    def close(self) -> None:
        self._close_writer()
        if self._owner == os.getpid():
            self._owner = None
            shutil.rmtree(self.dir, ignore_errors=True)
