"""A recording's states in time order, a chunk of whole time steps at a time (bounded memory):
the inverse direction of :mod:`aveas_format.io.resort`.

The states are participant-major (sorted by participant, then time); a time-major exporter writes
every participant of one time step (*frame*) together. :func:`open_states` gives the state rows
of one chunk of frames at a time (:func:`chunk_bounds`: about ``chunk_rows`` rows of whole
frames), in frame order, within a frame in the states' order:

- :class:`LoadedStates` takes them from the states table in memory (a recording opened whole);
- :class:`SpilledStates` reads a recording on disk whose states were not loaded
  (``open_recording(path, states=False)``): one pass over ``states.parquet`` row group by row
  group writes each row to the spill file of its *bucket* — consecutive whole chunks of frames,
  about :data:`BUCKET_BYTES` of states each (Arrow IPC streams, as :mod:`~aveas_format.io.resort`
  writes its buckets) — which is the transpose done out of core; then the reader holds one bucket
  at a time. Memory: one row group during the pass, one bucket during the reading, plus a few
  numbers per state (the frame of each row), whatever the recording's length.

``track_columns`` adds columns that need whole tracks (the OpenLABEL export's acceleration
estimated along each track where the states have none): ``track_columns(column names, rows)``
gives None or a function of a table of whole tracks (and the index of its first row in the states)
that returns the columns; the spilled pass calls it on batches of whole tracks (a track's
trailing rows held back to the next row group) and spills the columns with the rows.
The OpenLABEL export reads its states through this module.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa

from aveas_format.io.arrow import column_numpy
from aveas_format.io.resort import BUCKET_BYTES, MAX_BUCKETS, READ, IpcWriter, bucket_options, write_by_bucket
from aveas_format.parallel import read_ahead

#: a recording on disk with fewer states is read whole (the spill pass costs more than it saves)
SPILL_MIN_ROWS = 500_000
#: the prefix of the spilled extra columns (taken off again with the rows), and each row's index
_EXTRA, _ROW = "__aveas_extra:", "__aveas_row"

TrackColumns = Callable[[list[str], int], Callable[[pa.Table, int], dict[str, np.ndarray]] | None]


def chunk_bounds(fs: np.ndarray, chunk_rows: int) -> list[int]:
    """The row offsets where the chunks start, and the number of rows last: about ``chunk_rows``
    rows each, cut after whole frames (``fs``: the sorted frame of each row)."""
    n = len(fs)
    out, start = [0], 0
    while start < n:
        stop = min(start + chunk_rows, n)
        start = int(np.searchsorted(fs, fs[stop - 1], side="right"))
        out.append(start)
    return out


class LoadedStates:
    """The states table in memory (``track_columns``: module docstring)."""

    def __init__(self, table: pa.Table, track_columns: TrackColumns | None = None) -> None:
        self.table = table
        self.column_names = table.column_names
        self.num_rows = table.num_rows
        self.times, self.frame_of_row = np.unique(column_numpy(table, "time"), return_inverse=True)
        extra = track_columns(self.column_names, self.num_rows) if track_columns else None
        self.extra = None if extra is None else extra(table, 0)

    def take(self, rows: np.ndarray) -> tuple[pa.Table, dict[str, np.ndarray] | None]:
        """The state rows ``rows`` and their extra columns (None: no ``track_columns``)."""
        extra = None if self.extra is None else {k: v[rows] for k, v in self.extra.items()}
        return self.table.take(pa.array(rows)), extra

    def participant_ids(self) -> np.ndarray:
        return self.table.column("participant_id").to_numpy()

    def close(self) -> None:
        pass


class SpilledStates:
    """The states of the recording ``rec`` on disk (not loaded) spilled in buckets of frames into
    a temporary directory in ``spill_dir`` (module docstring); ``chunk_rows`` as
    :func:`chunk_bounds` (a chunk's rows are always in one bucket). The file's SHA-256 is checked
    against recording.json during the pass (a ChecksumError before anything is read from the
    spill)."""

    def __init__(self, rec, chunk_rows: int, spill_dir: Path | None = None,
                 track_columns: TrackColumns | None = None, prefix: str = ".states.") -> None:
        from aveas_format.io.reader import TableParts
        from aveas_format.parallel import background

        self.parts = parts = TableParts(rec.path, rec.meta, "states")
        self.column_names, self.num_rows = parts.column_names, parts.num_rows
        self.dir = Path(tempfile.mkdtemp(prefix=prefix, dir=spill_dir))
        self._owner = os.getpid()
        self._bucket, self._table, self._rows = -1, None, None
        try:
            hashed = background(parts.verify, name="states-sha256")
            try:
                self.times, self.frame_of_row = self._frames()
                self._spill(chunk_rows, track_columns(self.column_names, self.num_rows) if track_columns else None)
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

    def _spill(self, chunk_rows: int, extra) -> None:
        parts = self.parts
        writers: dict[int, IpcWriter] = {}
        held: pa.Table | None = None
        offset = 0
        try:  # (the next row group read while this one is spilled)
            for g, rg in enumerate(read_ahead(parts.read, range(parts.num_row_groups))):
                if g == 0:
                    row_bytes = rg.nbytes / max(rg.num_rows, 1)
                    self._buckets(chunk_rows, row_bytes)
                    options = bucket_options(self.num_rows * row_bytes)
                batch = rg
                if extra is not None:  # whole tracks: the last participant's rows wait for the next group
                    batch = rg if held is None else pa.concat_tables([held, rg])
                    if g < parts.num_row_groups - 1 and batch.num_rows:
                        pid = batch.column("participant_id").to_numpy()
                        cut = int(np.flatnonzero(np.r_[True, pid[1:] != pid[:-1]])[-1])
                        batch, held = batch.slice(0, cut), batch.slice(cut)
                    for k, v in extra(batch, offset).items():
                        batch = batch.append_column(_EXTRA + k, pa.array(v, pa.float64()))
                n = batch.num_rows
                if not n:
                    continue
                batch = batch.append_column(_ROW, pa.array(np.arange(offset, offset + n, dtype=np.int64)))
                b = self.bucket_of_frame[self.frame_of_row[offset:offset + n]]
                order = np.argsort(b, kind="stable")  # (the rows' order kept within a bucket)
                taken = batch.take(pa.array(order))
                write_by_bucket(writers, taken, b[order], lambda k: self.dir / f"b{k}.arrow", options)
                offset += n
        finally:
            for w in writers.values():
                w.close()
        # the pass's buffers given back (the allocator keeps them otherwise; forked readers would
        # each inherit them)
        pa.default_memory_pool().release_unused()

    # ---- reading ----------------------------------------------------------------------------
    def take(self, rows: np.ndarray) -> tuple[pa.Table, dict[str, np.ndarray] | None]:
        """The state rows ``rows`` (one chunk of frames, in frame order) and their extra columns
        (None: no ``track_columns``)."""
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
        names = [c for c in s.column_names if c.startswith(_EXTRA)]
        if not names:
            return s, None
        return s.drop_columns(names), {c[len(_EXTRA):]: s.column(c).to_numpy() for c in names}

    def participant_ids(self) -> np.ndarray:
        return self.parts.read(columns=["participant_id"]).column("participant_id").to_numpy()

    def close(self) -> None:
        """The spill removed (by the process that made it: forked readers only read it)."""
        self._table = None
        if self._owner == os.getpid():
            self._owner = None
            self.parts.close()
            shutil.rmtree(self.dir, ignore_errors=True)


def open_states(rec, chunk_rows: int, spill_dir: Path | None = None, track_columns: TrackColumns | None = None,
                prefix: str = ".states."):
    """:class:`LoadedStates` of a recording whose states are loaded; for one opened without them
    (``states=False``), :class:`SpilledStates` (its spill directory named ``prefix``...), or its
    states read whole when they are few (:data:`SPILL_MIN_ROWS`) or the recording needs a
    migration."""
    if rec.states is not None:
        return LoadedStates(rec.states, track_columns)
    if rec.path is None:
        raise ValueError("the recording has no states (and no path to read them from)")
    entry = rec.meta.tables.get("states")
    if rec.migrated_from is not None or (entry is not None and entry.rows < SPILL_MIN_ROWS):
        from aveas_format.io.reader import open_recording

        return LoadedStates(open_recording(rec.path, tables=["states"]).states, track_columns)
    return SpilledStates(rec, chunk_rows, spill_dir, track_columns, prefix)
