"""The states as the OpenLABEL export reads them: loaded, or spilled in frame order (bounded memory).

An OpenLABEL file is time-major (a frame holds every object present at its time), a recording's
states are participant-major (sorted by participant, then time). The export asks for the state
rows of one chunk of frames at a time (:func:`~.encode.frame_chunks`), in frame order:

- :class:`LoadedStates` takes them from the states table in memory (a recording opened whole);
- :class:`SpilledStates` reads a recording on disk whose states were not loaded
  (``open_recording(path, states=False)``; the CLI's ``export`` for an exporter that
  ``streams_states``): one pass over ``states.parquet`` row group by row group writes each row to
  the spill file of its *bucket* — consecutive whole chunks of frames, about
  :data:`BUCKET_BYTES` of states each (Arrow IPC streams; uncompressed up to
  :data:`aveas_format.io.resort.PLAIN_BUCKETS_BYTES` of states, else lz4) — which is the transpose done out
  of core; then the export holds one bucket at a time. Memory: one row group during the pass, one
  bucket and one chunk's text during the encoding, plus a few numbers per state (the frame of each
  row; docs/performance.md "Memory"), whatever the recording's length.

Both give the world-frame acceleration of states without ``ax``/``ay`` (it needs whole tracks:
from the derived kinematics, else from the velocities along each track); the spilled pass
computes it on batches of whole tracks (a track's trailing rows held back to the next row group)
and spills it with the rows. :func:`open_states` chooses.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa

from aveas_format.converters.openlabel.encode import chunk_bounds
from aveas_format.io.resort import READ, IpcWriter, bucket_options, write_by_bucket
from aveas_format.io.arrow import column_numpy
from aveas_format.parallel import read_ahead

#: about this many bytes of states per bucket of the spill (one bucket is held at a time)
BUCKET_BYTES = 32 << 20
#: at most this many buckets (their files are written at once)
MAX_BUCKETS = 256
#: a recording on disk with fewer states is read whole (the spill pass costs more than it saves)
SPILL_MIN_ROWS = 500_000
#: the spilled acceleration's columns (taken off again with the rows), and each row's index
_ACC, _ROW = ("__aveas_ax_w", "__aveas_ay_w"), "__aveas_row"


def world_acceleration(kin: tuple | None, pid: np.ndarray, t: np.ndarray, vx: np.ndarray,
                       vy: np.ndarray, ax: np.ndarray | None, ay: np.ndarray | None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The states' acceleration, else the derived kinematics' (``kin``: its ``ax, ay`` for these
    rows, or None), else estimated from the velocities (rows of whole tracks, sorted by
    participant and time)."""
    if ax is not None and ay is not None:
        return ax, ay
    a_est = kin
    if a_est is None:
        from aveas_format.mapref.build import velocity_from_positions

        a_est = velocity_from_positions(pid, t, vx, vy)
    return (np.nan_to_num(a_est[0]) if ax is None else ax,
            np.nan_to_num(a_est[1]) if ay is None else ay)


def _has_acceleration(column_names: list[str]) -> bool:
    return "ax" in column_names and "ay" in column_names


def _kinematics(derived: dict | None, n: int) -> tuple | None:
    """The derived kinematics' ``ax, ay`` when the table has a row per state, else None."""
    kin = derived.get("kinematics") if derived else None
    if kin is None or kin.num_rows != n:
        return None
    return tuple(column_numpy(kin, c, missing=None) for c in ("ax", "ay"))


def _acceleration_of(table: pa.Table, kin: tuple | None) -> tuple[np.ndarray, np.ndarray]:
    return world_acceleration(kin, table.column("participant_id").to_numpy(), column_numpy(table, "time"),
                              *(column_numpy(table, c, missing=None) for c in ("vx", "vy", "ax", "ay")))


class LoadedStates:
    """The states table in memory (``derived``: the recording's derived tables, for the
    kinematics' acceleration)."""

    def __init__(self, table: pa.Table, derived: dict | None) -> None:
        self.table = table
        self.column_names = table.column_names
        self.num_rows = table.num_rows
        self.times, self.frame_of_row = np.unique(column_numpy(table, "time"), return_inverse=True)
        self.acc = None if _has_acceleration(self.column_names) else \
            _acceleration_of(table, _kinematics(derived, table.num_rows))

    def take(self, rows: np.ndarray) -> tuple[pa.Table, tuple | None]:
        """The state rows ``rows`` and their world-frame acceleration (None: the states' own)."""
        acc = None if self.acc is None else (self.acc[0][rows], self.acc[1][rows])
        return self.table.take(pa.array(rows)), acc

    def participant_ids(self) -> np.ndarray:
        return self.table.column("participant_id").to_numpy()

    def close(self) -> None:
        pass


class SpilledStates:
    """The states of the recording ``rec`` on disk (not loaded) spilled in buckets of frames into
    a temporary directory in ``spill_dir`` (module docstring); ``chunk_rows`` as the export's
    :func:`~.encode.frame_chunks` (a chunk's rows are always in one bucket). The file's SHA-256
    is checked against recording.json during the pass (a ChecksumError before anything is
    encoded)."""

    def __init__(self, rec, chunk_rows: int, spill_dir: Path | None = None) -> None:
        from aveas_format.io.reader import TableParts
        from aveas_format.parallel import background

        self.parts = parts = TableParts(rec.path, rec.meta, "states")
        self.column_names, self.num_rows = parts.column_names, parts.num_rows
        self.dir = Path(tempfile.mkdtemp(prefix=".openlabel-states.", dir=spill_dir))
        self._owner = os.getpid()
        self._bucket, self._table, self._rows = -1, None, None
        try:
            hashed = background(parts.verify, name="states-sha256")
            try:
                self.times, self.frame_of_row = self._frames()
                self._spill(rec, chunk_rows)
            finally:
                hashed.result()  # (waited for in any case: no thread left behind)
        except BaseException:
            self.close()
            raise

    # ---- the pass ---------------------------------------------------------------------------
    def _frames(self) -> tuple[np.ndarray, np.ndarray]:
        """The distinct times and the frame of each row (an index into them; as ``np.unique``
        gives them), from the time column read row group by row group (no sort of all times)."""
        parts = self.parts

        def times(g: int) -> np.ndarray:
            return column_numpy(parts.read(g, ["time"]), "time")

        groups = range(parts.num_row_groups)
        distinct = np.unique(np.concatenate([np.unique(times(g)) for g in groups] or [np.zeros(0)]))
        frame_of_row = np.empty(self.num_rows, np.int32 if len(distinct) < 2**31 else np.int64)
        offset = 0
        for g in groups:
            t = times(g)
            frame_of_row[offset:offset + len(t)] = np.searchsorted(distinct, t)
            offset += len(t)
        return distinct, frame_of_row

    def _buckets(self, chunk_rows: int, row_bytes: float) -> None:
        """``bucket_of_frame``: consecutive whole chunks of about BUCKET_BYTES of states each."""
        counts = np.bincount(self.frame_of_row, minlength=len(self.times))
        fs = np.repeat(np.arange(len(self.times)), counts)  # the sorted frames, without a sort
        bounds = np.asarray(chunk_bounds(fs, chunk_rows))
        per = max(BUCKET_BYTES / max(row_bytes, 1.0), self.num_rows / MAX_BUCKETS, 1.0)
        # a bucket starts at the chunks whose first row crosses a multiple of ``per`` rows
        starts = bounds[:-1]
        bucket_of_chunk = np.maximum.accumulate(np.floor(starts / per)).astype(np.int64)
        _, bucket_of_chunk = np.unique(bucket_of_chunk, return_inverse=True)
        self.bucket_of_frame = np.empty(len(self.times), np.int64)
        first_frames = fs[starts] if len(starts) else np.zeros(0, np.int64)
        ends = np.r_[first_frames[1:], len(self.times)]
        for c, (f0, f1) in enumerate(zip(first_frames.tolist(), ends.tolist())):
            self.bucket_of_frame[f0:f1] = bucket_of_chunk[c]
        self.n_buckets = int(bucket_of_chunk.max()) + 1 if len(bucket_of_chunk) else 0

    def _spill(self, rec, chunk_rows: int) -> None:
        parts = self.parts
        kin = None if _has_acceleration(self.column_names) else _kinematics(rec.derived, self.num_rows)
        need_acc = not _has_acceleration(self.column_names)
        writers: dict[int, IpcWriter] = {}
        held: pa.Table | None = None
        offset = 0
        try:  # (the next row group read while this one is spilled)
            for g, rg in enumerate(read_ahead(parts.read, range(parts.num_row_groups))):
                if g == 0:
                    row_bytes = rg.nbytes / max(rg.num_rows, 1)
                    self._buckets(chunk_rows, row_bytes)
                    options = bucket_options(self.num_rows * row_bytes)
                if need_acc:  # whole tracks: the last participant's rows wait for the next group
                    batch = rg if held is None else pa.concat_tables([held, rg])
                    if g < parts.num_row_groups - 1 and batch.num_rows:
                        pid = batch.column("participant_id").to_numpy()
                        cut = int(np.flatnonzero(np.r_[True, pid[1:] != pid[:-1]])[-1])
                        batch, held = batch.slice(0, cut), batch.slice(cut)
                    a = _acceleration_of(batch, None if kin is None else
                                         (kin[0][offset:offset + batch.num_rows],
                                          kin[1][offset:offset + batch.num_rows]))
                    batch = batch.append_column(_ACC[0], pa.array(a[0], pa.float64())) \
                                 .append_column(_ACC[1], pa.array(a[1], pa.float64()))
                else:
                    batch = rg
                n = batch.num_rows
                if not n:
                    continue
                batch = batch.append_column(_ROW, pa.array(np.arange(offset, offset + n, dtype=np.int64)))
                b = self.bucket_of_frame[self.frame_of_row[offset:offset + n]]
                order = np.argsort(b, kind="stable")  # (the rows' order kept within a bucket)
                sb = b[order]
                taken = batch.take(pa.array(order))
                write_by_bucket(writers, taken, sb, lambda k: self.dir / f"b{k}.arrow", options)
                offset += n
        finally:
            for w in writers.values():
                w.close()
        # the pass's buffers given back (the allocator keeps them otherwise; the forked encoders
        # would each inherit them)
        pa.default_memory_pool().release_unused()

    # ---- reading ----------------------------------------------------------------------------
    def take(self, rows: np.ndarray) -> tuple[pa.Table, tuple | None]:
        """The state rows ``rows`` (one chunk of frames, in frame order) and their world-frame
        acceleration (None: the states' own)."""
        b = int(self.bucket_of_frame[self.frame_of_row[rows[0]]])
        if b != self._bucket:
            self._table = None  # (the last bucket freed before the next is read)
            with pa.memory_map(str(self.dir / f"b{b}.arrow")) as f:
                table = pa.ipc.open_stream(f, options=READ).read_all()
            self._rows = table.column(_ROW).to_numpy()  # (ascending: the file's order kept)
            self._table = table.drop_columns([_ROW])
            self._bucket = b
        local = np.searchsorted(self._rows, rows)
        if local[-1] >= len(self._rows) or not np.array_equal(self._rows[local], rows):
            raise RuntimeError("the rows asked for are not one chunk of frames of one bucket")
        s = self._table.take(pa.array(local))
        if _ACC[0] not in s.column_names:
            return s, None
        acc = tuple(s.column(c).to_numpy() for c in _ACC)
        return s.drop_columns(list(_ACC)), acc

    def participant_ids(self) -> np.ndarray:
        return self.parts.read(columns=["participant_id"]).column("participant_id").to_numpy()

    def close(self) -> None:
        """The spill removed (by the process that made it: forked encoders only read it)."""
        self._table = None
        if self._owner == os.getpid():
            self._owner = None
            self.parts.close()
            shutil.rmtree(self.dir, ignore_errors=True)


def open_states(rec, chunk_rows: int, spill_dir: Path | None = None):
    """:class:`LoadedStates` of a recording whose states are loaded; for one opened without them
    (``states=False``), :class:`SpilledStates`, or its states read whole when they are few
    (:data:`SPILL_MIN_ROWS`) or the recording needs a migration."""
    if rec.states is not None:
        return LoadedStates(rec.states, rec.derived)
    if rec.path is None:
        raise ValueError("the recording has no states (and no path to read them from)")
    entry = rec.meta.tables.get("states")
    if rec.migrated_from is not None or (entry is not None and entry.rows < SPILL_MIN_ROWS):
        from aveas_format.io.reader import open_recording

        return LoadedStates(open_recording(rec.path, tables=["states"]).states, rec.derived)
    return SpilledStates(rec, chunk_rows, spill_dir)
