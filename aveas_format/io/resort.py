"""Out-of-core re-sorting of states between time-major sources and the participant-major
``states.parquet`` (bounded memory).

Most sources are time-major (OpenLABEL frames, OSI ground truth, MCAP and ROS 2 messages: every
object of one time step together); the format's states are sorted by participant, then time.

:class:`StatesWriter` takes time-major batches of state rows (:meth:`~StatesWriter.add`: Arrow
tables or dicts of columns, any columns, a key column naming each row's participant) and gives
them back as whole participants, a *bucket* of consecutive participants at a time
(:meth:`~StatesWriter.buckets`, :meth:`~StatesWriter.map`), or writes them as the recording's
``states.parquet`` (:meth:`~StatesWriter.write`: each bucket through the caller's ``transform``,
sorted by participant and time, in the recording's row groups, hashed as written). Up to
``memory`` bytes of rows are held in memory (then there is one bucket: no disk); beyond, the rows
are spilled to Arrow IPC files in a hidden temporary directory and, at the end, distributed into
bucket files (one pass; about :data:`BUCKET_BYTES` each, at most :data:`MAX_BUCKETS`), which are
read one at a time. The participant of a row may be decided only after the last row
(``key_map``: the final key of each key added, e.g. OpenLABEL's participant ids, known once every
object is): the buckets follow the final keys.

A converter's import in bounded memory is::

    with StatesWriter(output.parent) as w:
        for batch in time_major_batches:        # e.g. one OSI message or MCAP chunk at a time
            w.add(batch)                        # participant_id, time, x, y, ... as they come
        states_file, summary, _ = w.write(output.parent / "states.parquet", transform=finish)
    write_recording(rec, output, states_file=states_file)   # rec without its states

and in memory ``pa.concat_tables(t for t, _ in w.map(finish))``.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from aveas_format.io.writer import StatesFile

#: rows held in memory before they are spilled (bytes of Arrow data; None: never spilled)
MEMORY = 256 << 20
#: rows held in memory by an import that writes its recording in bounded memory (beyond:
#: spilled, then made into states a bucket at a time; making a bucket's states costs several
#: times its rows' bytes, so an import held whole stays well below a gigabyte)
IMPORT_MEMORY = 128 << 20
#: about this many bytes of rows per bucket (one bucket is held at a time)
BUCKET_BYTES = 32 << 20
#: at most this many buckets (their files are written at once)
MAX_BUCKETS = 256
#: up to this many bytes of rows the bucket files are written uncompressed (read back soon, from
#: the page cache); above, lz4 (the kernel's writeback of gigabytes costs more than it saves)
PLAIN_BUCKETS_BYTES = 1 << 30
#: the spills' Arrow IPC options: written and read in the calling thread (the spills are written
#: by processes that keep every core busy already)
LZ4 = pa.ipc.IpcWriteOptions(compression="lz4", use_threads=False)
PLAIN = pa.ipc.IpcWriteOptions(use_threads=False)
READ = pa.ipc.IpcReadOptions(use_threads=False)
#: the spill files are written through a buffer of this many bytes (one write() per buffer)
SINK_BUFFER = 1 << 20
BUCKET_SINK_BUFFER = 256 << 10


class IpcWriter:
    """An Arrow IPC stream (``file``: an IPC file) at ``path``, written through a buffer."""

    def __init__(self, path: Path | str, schema: pa.Schema, options: pa.ipc.IpcWriteOptions = LZ4,
                 file: bool = False, buffer: int = SINK_BUFFER) -> None:
        self._sink = pa.output_stream(str(path), compression=None, buffer_size=buffer)
        try:
            self._writer = (pa.ipc.new_file if file else pa.ipc.new_stream)(self._sink, schema, options=options)
        except BaseException:
            self._sink.close()
            raise

    def write_table(self, table: pa.Table) -> None:
        self._writer.write_table(table)

    def close(self) -> None:
        if not self._sink.closed:
            try:
                self._writer.close()
            finally:
                self._sink.close()

    def __enter__(self) -> IpcWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def bucket_options(nbytes: float) -> pa.ipc.IpcWriteOptions:
    """The IPC options of a pass's bucket files for ``nbytes`` of rows in all."""
    return PLAIN if nbytes <= PLAIN_BUCKETS_BYTES else LZ4


def read_ipc(path: Path | str) -> pa.Table:
    """An Arrow IPC stream or file, whole (read, not mapped)."""
    with pa.OSFile(str(path)) as f:
        head = f.read(6)
        f.seek(0)
        reader = pa.ipc.open_file(f, options=READ) if head == b"ARROW1" else pa.ipc.open_stream(f, options=READ)
        return reader.read_all()


def write_by_bucket(writers: dict, table: pa.Table, buckets: np.ndarray, path_of, options=LZ4) -> None:
    """The rows of ``table`` appended to their buckets' IPC streams (``buckets``: each row's
    bucket, sorted; ``writers``: the streams open so far, a new one at ``path_of(bucket)``)."""
    cuts = np.r_[0, np.flatnonzero(buckets[1:] != buckets[:-1]) + 1, len(buckets)]
    for lo, hi in zip(cuts[:-1].tolist(), cuts[1:].tolist()):
        k = int(buckets[lo])
        w = writers.get(k)
        if w is None:
            w = writers[k] = IpcWriter(path_of(k), table.schema, options, buffer=BUCKET_SINK_BUFFER)
        w.write_table(table.slice(lo, hi - lo))


def conformed(t: pa.Table, schema: pa.Schema) -> pa.Table:
    """``t`` with ``schema``'s columns in its order and types (a column it lacks: nulls)."""
    if t.schema.equals(schema):
        return t
    have = dict(zip(t.column_names, t.columns))
    cols = [pa.nulls(t.num_rows, f.type) if f.name not in have else
            have[f.name] if have[f.name].type == f.type else have[f.name].cast(f.type) for f in schema]
    return pa.Table.from_arrays(cols, schema=schema)


def unified(schemas: list[pa.Schema], first: list[str] | None = None) -> pa.Schema:
    """One schema holding every column of ``schemas`` (``first``: these names first, in this
    order, then the others in the order met), each in a type that holds all its types."""
    fields: dict[str, pa.Field] = {}
    for sc in schemas:
        for fld in sc:
            have = fields.get(fld.name)
            if have is None:
                fields[fld.name] = fld
            elif have.type != fld.type:
                fields[fld.name] = pa.unify_schemas([pa.schema([have]), pa.schema([fld])],
                                                    promote_options="permissive").field(0)
    names = [c for c in first or [] if c in fields]
    return pa.schema([fields[c] for c in names + [c for c in fields if c not in names]])


def _table(batch: pa.Table | pa.RecordBatch | dict) -> pa.Table:
    if isinstance(batch, dict):
        return pa.table(batch)
    return pa.Table.from_batches([batch]) if isinstance(batch, pa.RecordBatch) else batch


class StatesWriter:
    """Time-major batches of state rows in, whole participants out (module docstring).

    ``spill_dir``: where the hidden temporary directory of spilled rows is made (next to the
    output: the states file is moved in, not copied); ``memory``: bytes of rows held in memory
    (None: never spilled); ``key``: the column naming each row's participant (integers)."""

    def __init__(self, spill_dir: Path | str | None = None, *, memory: int | None = MEMORY,
                 key: str = "participant_id", bucket_bytes: int | None = None) -> None:
        self.spill_dir, self.memory, self.key = spill_dir, memory, key
        self.bucket_bytes = bucket_bytes or BUCKET_BYTES
        self.held: list[pa.Table] = []
        self.held_bytes = self.nbytes = self.rows = 0
        self.keys: list[np.ndarray] = []
        self.runs: list[tuple[Path, pa.Schema]] = []
        self._writer: IpcWriter | None = None
        self.dir: Path | None = None
        self._owner = os.getpid()

    # ---- in -------------------------------------------------------------------------------
    def add(self, batch: pa.Table | pa.RecordBatch | dict) -> None:
        """Rows of any participants and times (columns may differ from batch to batch: a column
        a batch lacks is null there; types are unified)."""
        t = _table(batch)
        if not t.num_rows:
            return
        self.keys.append(np.asarray(t.column(self.key).to_numpy(), np.int64))
        self.rows += t.num_rows
        self.nbytes += t.nbytes
        if self._writer is not None:  # (spilling: straight to the spill)
            self._write(t)
            return
        self.held.append(t)
        self.held_bytes += t.nbytes
        if self.memory is not None and self.held_bytes > self.memory:
            for h in self.held:
                self._write(h)
            self.held, self.held_bytes = [], 0

    def reset(self) -> None:
        """Every row added so far dropped (a reader that starts over)."""
        self._close_run()
        for path, _ in self.runs:
            Path(path).unlink(missing_ok=True)
        self.held, self.keys, self.runs = [], [], []
        self.held_bytes = self.nbytes = self.rows = 0

    @property
    def spilled(self) -> bool:
        return bool(self.runs)

    def _tmp(self) -> Path:
        if self.dir is None:
            self.dir = Path(tempfile.mkdtemp(prefix=".aveas-states.", dir=self.spill_dir))
        return self.dir

    def _write(self, t: pa.Table) -> None:
        """A batch into the spill: the current run file while its schema holds, else a new one."""
        if self._writer is None or not t.schema.equals(self.runs[-1][1]):
            self._close_run()
            path = self._tmp() / f"r{len(self.runs)}.arrow"
            self._writer = IpcWriter(path, t.schema, LZ4)
            self.runs.append((path, t.schema))
        self._writer.write_table(t)

    def _close_run(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    # ---- out ------------------------------------------------------------------------------
    def buckets(self, key_map: np.ndarray | None = None) -> Iterator[pa.Table]:
        """The rows of whole participants, a bucket at a time in ascending (mapped) key, the rows
        of a bucket in the order added. ``key_map``: the final key of each key added (keys are
        indices into it)."""
        if not self.runs:
            if self.held:
                yield pa.concat_tables(self.held, promote_options="permissive")
            return
        for k in self._distribute(key_map):
            yield self._bucket(k)

    def _bucket(self, k: int) -> pa.Table:
        path = self.dir / f"b{k}.arrow"
        t = read_ipc(path)
        path.unlink()
        return t

    def _distribute(self, key_map: np.ndarray | None) -> list[int]:
        """The spilled rows into bucket files of consecutive (mapped) keys, a spilled batch at a
        time: the buckets' numbers."""
        self._close_run()
        keys = np.concatenate(self.keys)
        uniq, inv = np.unique(key_map[keys] if key_map is not None else keys, return_inverse=True)
        del keys
        counts = np.bincount(inv.reshape(-1), minlength=len(uniq))
        per = max(self.bucket_bytes / max(self.nbytes / max(self.rows, 1), 1.0), self.rows / MAX_BUCKETS, 1.0)
        _, bucket_of_key = np.unique(np.floor((np.cumsum(counts) - counts) / per).astype(np.int64),
                                     return_inverse=True)
        bucket_of_row = bucket_of_key.reshape(-1)[inv.reshape(-1)]
        del inv
        schema = unified([sc for _, sc in self.runs])
        writers: dict[int, IpcWriter] = {}
        options = bucket_options(self.nbytes)
        off = 0
        try:
            for path, _ in self.runs:
                with pa.OSFile(str(path)) as f:
                    for batch in pa.ipc.open_stream(f, options=READ):
                        t = conformed(pa.Table.from_batches([batch]), schema)
                        b = bucket_of_row[off:off + t.num_rows]
                        order = np.argsort(b, kind="stable")
                        write_by_bucket(writers, t.take(pa.array(order)), b[order],
                                        lambda k: self.dir / f"b{k}.arrow", options)
                        off += t.num_rows
                path.unlink()
        finally:
            for w in writers.values():
                w.close()
        self.runs = []
        pa.default_memory_pool().release_unused()
        return sorted(writers)

    def _transformed(self, transform, key_map, workers, files: bool) -> Iterator[tuple[Any, Any]]:
        """``(states, info)`` of each bucket through ``transform``, sorted; ``files``: the states as
        an IPC file's path (the worker processes write them so) instead of a table."""
        from aveas_format.parallel import map_ordered, processes

        global _ACTIVE
        if self.runs and processes(workers) > 1:
            ks = self._distribute(key_map)
            if len(ks) > 1:
                _ACTIVE = (self, transform)
                try:
                    for _, (path, info) in map_ordered(_bucket_job, ks, workers=workers):
                        if files:
                            yield path, info
                        else:
                            yield read_ipc(path), info
                            os.unlink(path)
                finally:
                    _ACTIVE = None
                return
            buckets = (self._bucket(k) for k in ks)
        else:
            buckets = self.buckets(key_map)
        for k, b in enumerate(buckets):
            t, info = _sorted(*transform(b))
            yield (_spilled(t, self._tmp() / f"t{k}.arrow", self.nbytes) if files else t), info

    def map(self, transform: Callable[[pa.Table], tuple[pa.Table, Any]], *, key_map: np.ndarray | None = None,
            workers: int | None = 1) -> Iterator[tuple[pa.Table, Any]]:
        """``transform(bucket) -> (states, info)`` of each bucket in order, the states sorted by
        ``participant_id`` and ``time``; spilled buckets in ``workers`` processes (forked:
        ``transform`` need not be picklable)."""
        return self._transformed(transform, key_map, workers, files=False)

    def write(self, target: Path, *, transform: Callable[[pa.Table], tuple[pa.Table, Any]] | None = None,
              key_map: np.ndarray | None = None, workers: int | None = 1, spec=None
              ) -> tuple[StatesFile, dict[str, Any], list]:
        """The states written to ``target`` (the format's ``states`` table: declared columns first,
        the recording's row groups, hashed as written): each bucket through ``transform`` (default:
        as added), sorted by participant and time. ``(the file, {rows, duration_s,
        nominal_rate_hz, location, on_road}, the transforms' infos)``."""
        from aveas_format.schema.tables import TABLES

        spec = spec or TABLES["states"]
        parts = list(self._transformed(transform or (lambda t: (t, None)), key_map, workers, files=True))
        schemas = [_schema_of(p) for p, _ in parts]
        out = _ParquetStates(Path(target), unified(schemas, [c.name for c in spec.columns]), spec)
        try:
            for path, _ in parts:
                out.add(read_ipc(path))
                os.unlink(path)
            return (*out.close(), [info for _, info in parts])
        except BaseException:
            out.abort()
            raise

    def close(self) -> None:
        """The spill removed (by the process that made it)."""
        self.held, self.keys = [], []
        if self._owner == os.getpid():
            self._close_run()
        if self.dir is not None and self._owner == os.getpid():
            shutil.rmtree(self.dir, ignore_errors=True)
            self.dir = None

    def __enter__(self) -> StatesWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: the writer and transform the forked bucket workers run (set while they run)
_ACTIVE: tuple | None = None


def _bucket_job(k: int) -> tuple[str, Any]:
    """Bucket ``k`` of the active writer through its transform, into ``t{k}.arrow``."""
    w, transform = _ACTIVE
    t, info = _sorted(*transform(w._bucket(k)))
    return _spilled(t, w.dir / f"t{k}.arrow", w.nbytes), info


def _spilled(t: pa.Table, path: Path, nbytes: int) -> str:
    with IpcWriter(path, t.schema, bucket_options(nbytes)) as w:
        w.write_table(t)
    return str(path)


def _schema_of(path: str) -> pa.Schema:
    with pa.OSFile(path) as f:
        return pa.ipc.open_stream(f, options=READ).schema


def _sorted(t: pa.Table, info: Any) -> tuple[pa.Table, Any]:
    if t.num_rows > 1:
        pid, time = t.column("participant_id").to_numpy(), t.column("time").to_numpy()
        if not ((pid[1:] > pid[:-1]) | ((pid[1:] == pid[:-1]) & (time[1:] >= time[:-1]))).all():
            t = t.take(pa.array(np.lexsort((time, pid))))
    return t, info


class _Hashing:
    """A file the Parquet writer writes to, hashed as it is written."""

    def __init__(self, f, h) -> None:
        self.f, self.h, self.closed = f, h, False

    def write(self, b) -> int:
        self.h.update(b)
        return self.f.write(b)

    def flush(self) -> None:
        self.f.flush()

    def close(self) -> None:
        self.closed = True

    def tell(self) -> int:
        return self.f.tell()


class _ParquetStates:
    """``states.parquet`` written from sorted parts in order: whole row groups written, the rest
    held for the next part; the duration, rate and location summed on the way."""

    def __init__(self, target: Path, schema: pa.Schema, spec) -> None:
        from aveas_format.io.writer import parquet_options

        self.target, self.schema = target, schema
        self.wschema, options = parquet_options(schema, spec)
        self.h = hashlib.sha256()
        self.n, self.tmax, self.nulls = 0, -np.inf, 0
        self.sums = np.zeros(2)
        self.dts: dict[float, int] = {}
        self.pending: list[pa.Table] = []
        self.held = 0
        self.raw = open(target, "wb")  # noqa: SIM115 - closed in close()/abort()
        try:
            self.pw = pq.ParquetWriter(_Hashing(self.raw, self.h), self.wschema, **options)
        except BaseException:
            self.raw.close()
            raise

    def add(self, s: pa.Table) -> None:
        from aveas_format.io.writer import ROW_GROUP_ROWS
        from aveas_format.numeric import same_participant

        s = conformed(s, self.schema).replace_schema_metadata(self.wschema.metadata)
        if not s.num_rows:
            return
        pid, t = s.column("participant_id").to_numpy(), s.column("time").to_numpy()
        self.n += s.num_rows
        self.tmax = max(self.tmax, float(t.max()))
        dt = np.diff(t)[same_participant(pid)]
        vals, cnt = np.unique(dt[dt > 0], return_counts=True)
        for v, c in zip(vals.tolist(), cnt.tolist()):
            self.dts[v] = self.dts.get(v, 0) + c
        if "lon" in s.column_names and "lat" in s.column_names:
            self.sums += [float(np.sum(s.column(c).to_numpy())) for c in ("lon", "lat")]
        self.nulls += s.column("road_id").null_count if "road_id" in s.column_names else s.num_rows
        self.pending.append(s)
        self.held += s.num_rows
        if self.held >= ROW_GROUP_ROWS:
            whole = pa.concat_tables(self.pending)
            cut = self.held - self.held % ROW_GROUP_ROWS
            self.pw.write_table(whole.slice(0, cut), row_group_size=ROW_GROUP_ROWS)
            self.pending, self.held = [whole.slice(cut)], self.held - cut

    def close(self) -> tuple[StatesFile, dict[str, Any]]:
        from aveas_format.io.writer import ROW_GROUP_ROWS

        try:
            if self.held:
                self.pw.write_table(pa.concat_tables(self.pending), row_group_size=ROW_GROUP_ROWS)
            self.pw.close()
            self.raw.flush()
            os.fsync(self.raw.fileno())
        except BaseException:
            self.abort()
            raise
        self.raw.close()
        n = max(self.n, 1)
        summary = {"rows": self.n, "duration_s": self.tmax if self.n else 0.0,
                   "nominal_rate_hz": _median_rate(self.dts),
                   "location": {"lon": self.sums[0] / n, "lat": self.sums[1] / n},
                   "on_road": self.n - self.nulls}
        return StatesFile(self.target, self.n, self.h.hexdigest()), summary

    def abort(self) -> None:
        try:
            self.pw.close()
        except (OSError, pa.ArrowException):
            pass
        self.raw.close()
        self.target.unlink(missing_ok=True)


def _median_rate(dts: dict[float, int]) -> float:
    """``round(1 / median, 6)`` of the time steps (value -> count), as build_recording takes it."""
    if not dts:
        return 1.0
    vals = np.asarray(sorted(dts))
    cum = np.cumsum([dts[v] for v in vals.tolist()])
    total = int(cum[-1])
    a = float(vals[np.searchsorted(cum, (total - 1) // 2, side="right")])
    b = float(vals[np.searchsorted(cum, total // 2, side="right")])
    return float(round(1.0 / float(np.mean([a, b])), 6))
