"""The OpenLABEL import that writes its recording itself: the states in parts (bounded memory).

An OpenLABEL file is time-major (a frame holds every object present at its time), a recording's
states participant-major. Imported into memory, a one-hour file holds every box's values at once
(~570 B per state). :func:`import_openlabel_to` (the CLI's ``convert`` of one file) instead:

1. reads the frames as the import does, the boxes' columns spilled block by block
   (:class:`.spill.RowSpill`) from :data:`SPILL_MIN_ROWS` expected boxes on (boxes read frame by
   frame: once that many are held, they are moved into the spill);
2. after the frames (their keys, times and objects known): a pass over the spill (two worker
   processes, half of the spill each, where there are cores) writes each kept box to the file of
   its *bucket* — consecutive participants, about :data:`BUCKET_BYTES` of boxes each;
   uncompressed up to :data:`.spill.PLAIN_BUCKETS_BYTES` of boxes — dropping what the import drops per
   box (frames whose key repeats, objects that are no road users, boxes with an impossible size)
   and gathering what the import decides over all boxes (has every box a velocity, an
   acceleration, road coordinates; the root coordinate systems);
3. per bucket, in participant order: its boxes in frame order, then exactly the in-memory
   import's steps (repeated states dropped, world -> map frame, vehicle -> world frame, the
   file's road coordinates, the extension's exact values, :func:`~aveas_format.mapref.build.fill_states`)
   -> the states of those participants, spilled again;
4. the buckets' states written to ``states.parquet`` in the recording's row groups (one schema
   over all buckets), hashed as written, as each bucket comes while the workers go on (where a
   later bucket has a column the first has not: after the last, in the schema of all), and
   moved into the recording (:class:`~aveas_format.io.writer.StatesFile`).

The result is the in-memory import's recording (tests/converters/test_openlabel_parts.py: the
same tables, the location's mean summed per bucket). Where a step needs all boxes at once (the
boxes' own timestamps of a foreign file, resolved over all of them) or a block cannot be spilled
exactly, the rows are read back into memory and the import goes on as before.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aveas_format.converters.openlabel.spill import (READ, IpcWriter, RowSpill, bucket_options, from_table,
                                                     write_by_bucket)
from aveas_format.io.arrow import conform
from aveas_format.io.writer import ROW_GROUP_ROWS, StatesFile, parquet_options, prepare_table
from aveas_format.numeric import release_free_memory, same_participant
from aveas_format.schema.tables import TABLES

#: from this many boxes (expected from the first block and the file's size) the rows are spilled
SPILL_MIN_ROWS = 500_000
#: about this many bytes of spilled boxes per bucket (one bucket is held at a time)
BUCKET_BYTES = 24 << 20
#: at most this many buckets (their files are open at once)
MAX_BUCKETS = 256
_SPEC = TABLES["states"]


class Parts:
    """The working files of one import that writes its recording itself, in a hidden temporary
    directory in ``parent`` (next to the output: the states file is moved in, not copied)."""

    def __init__(self, parent: Path, min_rows: int = SPILL_MIN_ROWS) -> None:
        self.parent, self.min_rows = Path(parent), min_rows
        self.dir: Path | None = None
        self._spills: list[RowSpill] = []
        #: the states written (None: in the recording returned)
        self.states_file: StatesFile | None = None
        self.on_road = 0

    def spills(self, rows_expected: int) -> bool:
        return rows_expected >= self.min_rows

    def row_spill(self) -> RowSpill:
        self._dir()
        s = RowSpill(self.dir)
        self._spills.append(s)
        return s

    def _dir(self) -> Path:
        if self.dir is None:
            self.dir = Path(tempfile.mkdtemp(prefix=".openlabel-import.", dir=self.parent))
        return self.dir

    def close(self) -> None:
        for s in self._spills:
            s.close()
        if self.dir is not None:
            shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> Parts:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- the states in parts ----------------------------------------------------------------
    def write_states(self, fd, uids: list[str], time_of: dict, start_time: str, ctx) -> tuple | None:
        """The states of the spilled boxes ``fd.spill`` written in parts (module docstring); as
        :func:`~.read._states_in_memory` returns them, with an empty states table, or None where
        the import needs its rows in memory (nothing reported then: the import reports)."""
        spill = fd.spill
        schema = spill.schema()
        if any(c.startswith("__ef:") and f"__eo:{c[5:]}" in schema.names for c in schema.names):
            return None  # (a member numbers in one block, other values in another)
        work = _Buckets(self._dir(), fd, uids, ctx, spill, schema)
        try:
            got = work.run(time_of, start_time)
            if got is None:
                return None
            self.states_file, self.on_road = work.states_file, work.on_road
            spill.close()
            return got
        finally:
            work.close()


class _Buckets:
    """Steps 2-4 of the module docstring for one import."""

    def __init__(self, parent: Path, fd, uids: list[str], ctx, spill: RowSpill, schema: pa.Schema) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="buckets.", dir=parent))
        self.fd, self.uids, self.ctx, self.spill, self.schema = fd, uids, ctx, spill, schema
        self.states_file: StatesFile | None = None
        self.on_road = 0

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)

    def run(self, time_of: dict, start_time: str) -> tuple | None:
        from aveas_format.converters.openlabel import read as R

        fd, ctx = self.fd, self.ctx
        objects, ext, options, path = ctx.objects, ctx.ext, ctx.options, ctx.path
        names = fd.uid_names
        uidx, occ = self.spill.keys()
        rank_of = fd.rank_of.astype(np.int32)
        valid = rank_of[occ] >= 0
        # each box's place in frame order (by frame key, then file order: as in memory): a frame's
        # boxes are consecutive, so the place is where its frame starts plus the box's place in it
        per_rank = np.zeros(int(rank_of.max()) + 1 if len(rank_of) else 0, np.int64)
        kept_occ = np.flatnonzero(rank_of >= 0)
        per_rank[rank_of[kept_occ]] = np.bincount(occ, minlength=len(rank_of))[kept_occ]
        frame_start = np.cumsum(per_rank) - per_rank
        first_row = np.zeros(len(rank_of), np.int64)  # (of each frame occurrence)
        runs = np.flatnonzero(np.r_[True, occ[1:] != occ[:-1]]) if len(occ) else np.zeros(0, np.int64)
        first_row[occ[runs]] = runs
        del runs
        keep_uid, report_skipped = R._object_filter(fd, objects, self.uids, options, path) \
            if ext is None else (None, None)
        # buckets of consecutive participants (the ids as the objects give them now: their order
        # is the final ids' order, checked below)
        _, pid0 = R._participant_ids(objects, self.uids)
        self._buckets(np.asarray([pid0.get(u, 0) for u in names], np.int64),
                      np.bincount(uidx[valid], minlength=len(names)), int(valid.sum()))
        del valid
        p = self._pass((uidx, occ, rank_of, frame_start, first_row, keep_uid))
        del uidx, occ
        if not p["kept"] or (ext is None and p["cts_all"]):
            return None  # (no box: the import's errors; the boxes' timestamps: over all at once)
        uids = self.uids
        if keep_uid is not None:
            for i in p["had"] - p["left"]:
                keep_uid[names[i]] = False
        fd.sizes = fd.sizes_of(_in_order(p["sizes"])) if p["sizes"] else {}
        if keep_uid is not None:
            uids = R._kept_uids(fd, uids, keep_uid)
        obj_ext, pid_of = R._participant_ids(objects, uids)
        pid_idx = np.asarray([pid_of.get(u, 0) for u in names], np.int64)
        if not self._ordered(pid_idx, p["left"]):
            return None
        use_file = options.road_coordinates == "file" or (options.road_coordinates == "auto" and p["hr_any"])
        b = self._states(pid_idx, np.asarray([time_of[k] for k in fd.fkeys], float), p, use_file)
        if b is None:
            return None
        if b["written"] is None:  # (the buckets' schemas differ: written now, in one schema)
            schema = _one_schema([sc for _, sc in b["schemas"]])
            if schema is None:
                return None
            b["written"] = self._write([k for k, _ in b["schemas"]], schema)
        n, meta_kw, empty = b["written"]
        if report_skipped is not None:  # the findings, in the in-memory import's order
            report_skipped()
        if p["bad"][0]:
            R._report_bad_sizes(p["bad"][0], p["bad"][1], p["bad"][3], p["bad"][4], path)
        if b["repeats"]:
            first = min(b["repeats"], key=lambda r: r[1])
            R._report_repeats(sum(r[0] for r in b["repeats"]), first[2], first[3], path)
        return uids, obj_ext, pid_of, empty, n, start_time, use_file, meta_kw

    # ---- step 2 -----------------------------------------------------------------------------
    def _buckets(self, pid0_of_idx: np.ndarray, counts: np.ndarray, total: int) -> None:
        upid, inv = np.unique(pid0_of_idx, return_inverse=True)
        per_pid = np.bincount(inv, weights=counts, minlength=len(upid))
        per = max(BUCKET_BYTES / max(self.spill.row_bytes, 1.0), total / MAX_BUCKETS, 1.0)
        starts = np.cumsum(per_pid) - per_pid
        _, bucket_of_pid = np.unique(np.floor(starts / per).astype(np.int64), return_inverse=True)
        self.bucket_of_idx = bucket_of_pid.reshape(-1)[inv.reshape(-1)] if len(inv) else np.zeros(0, np.int64)
        self.n_buckets = int(bucket_of_pid.max()) + 1 if len(bucket_of_pid) else 0

    def _ipc_options(self) -> pa.ipc.IpcWriteOptions:
        """The buckets' files uncompressed up to :data:`.spill.PLAIN_BUCKETS_BYTES` of boxes, else lz4."""
        return bucket_options(self.spill.n * self.spill.row_bytes)

    def _pass(self, arrays: tuple) -> dict[str, Any]:
        """The spilled boxes into bucket files (:meth:`_pass_part`), in two halves of the spill
        by two worker processes where there are cores (forked after the freed memory is handed
        back: they would otherwise copy the pages their allocator reuses), what each gathered
        merged in file order."""
        from aveas_format.parallel import map_ordered, processes

        global _WORK
        n = len(self.spill.index)
        halves = 2 if processes(self.ctx.options.workers) > 1 and n > 1 else 1
        cuts = [0, n // 2, n] if halves == 2 else [0, n]
        parts = [(w, cuts[w], cuts[w + 1]) for w in range(halves)]
        self._step2 = arrays
        if halves > 1:
            release_free_memory()
            pa.default_memory_pool().release_unused()
        _WORK = self
        try:
            got = [r for _, r in map_ordered(_pass_of_work, parts, workers=halves)]
        finally:
            _WORK = None
            self._step2 = None
        return _merged(got)

    def _pass_part(self, part: tuple[int, int, int]) -> dict[str, Any]:
        """Batches ``lo`` to ``hi`` of the spill into bucket files ``b{k}.{w}.arrow``: the boxes
        kept (frame key given once, objects imported, plausible sizes) with their object, frame
        rank and place in frame order; and what the import decides over all boxes, gathered."""
        from aveas_format.converters.openlabel import read as R

        w, lo, hi = part
        uidx, occ, rank_of, frame_start, first_row, keep_uid = self._step2
        fd = self.fd
        names = fd.uid_names
        need_size = np.fromiter(map(fd.needs_size, names), bool, len(names))
        p = _gathered()
        writers: dict[int, IpcWriter] = {}
        options = self._ipc_options()
        offset = self.spill.index[lo][2] if lo < len(self.spill.index) else self.spill.n
        try:
            for batch in self.spill.batches(lo, hi):
                m = batch.num_rows
                t = _conformed(pa.Table.from_batches([batch]), self.schema)
                u, oc = uidx[offset:offset + m], occ[offset:offset + m]
                rk = rank_of[oc]
                v = rk >= 0
                # the box's place in frame order: where its frame starts, plus its place in it
                ps = np.where(v, frame_start[np.maximum(rk, 0)] + np.arange(offset, offset + m) - first_row[oc], -1)
                offset += m
                hv, hr = (t.column(c).to_numpy(zero_copy_only=False) for c in ("hv", "hr"))
                p["hv_all"] &= bool(hv[v].all())
                p["hr_any"] |= bool(hr[v].any())
                dims = {c: _f(t, c) for c in ("dl", "dw", "dh")}
                sz = v & need_size[u]
                if sz.any():
                    p["sizes"].append((ps[sz], u[sz], *(dims[c][sz] for c in ("dl", "dw", "dh"))))
                keep = v
                if keep_uid is not None:
                    k, dropped = R._box_filter({"uidx": u, **dims}, keep_uid, names)
                    keep, dropped = k & v, dropped & v
                    if dropped.any():
                        bad = p["bad"]
                        bad[0] += int(dropped.sum())
                        bad[1] |= {names[i] for i in np.unique(u[dropped]).tolist()}
                        i = int(np.flatnonzero(dropped)[np.argmin(ps[dropped])])
                        if bad[2] is None or ps[i] < bad[2]:
                            bad[2:] = [int(ps[i]), fd.fkeys[int(rk[i])], names[int(u[i])]]
                    p["had"] |= set(np.unique(u[v]).tolist())
                idx = np.flatnonzero(keep)
                if not len(idx):
                    continue
                p["left"] |= set(np.unique(u[idx]).tolist())
                p["kept"] += len(idx)
                p["acc_all"] &= bool(np.isfinite(_f(t, "au")[idx]).all() and np.isfinite(_f(t, "av")[idx]).all())
                p["cts_all"] &= bool(np.isfinite(_f(t, "cub_ts")[idx]).all())
                bk = self.bucket_of_idx[u[idx]]
                order = np.argsort(bk, kind="stable")
                sb, idx = bk[order], idx[order]
                kept = t.drop_columns(["hv", "hr"]).take(pa.array(idx))
                p["roots"] |= {r for r in pc.unique(kept.column("csroot")).to_pylist() if r}
                kept = kept.append_column("uidx", pa.array(u[idx].astype(np.int64))) \
                           .append_column("rank", pa.array(rk[idx].astype(np.int64))) \
                           .append_column("__pos", pa.array(ps[idx]))
                write_by_bucket(writers, kept, sb, lambda k: self.dir / f"b{k}.{w}.arrow", options=options)
        finally:
            for wr in writers.values():
                wr.close()
        pa.default_memory_pool().release_unused()
        return p

    def _ordered(self, pid_idx: np.ndarray, objects: set[int]) -> bool:
        """Do the buckets hold consecutive participants by their final ids (each id in one)?"""
        if not objects:
            return True
        idx = np.fromiter(objects, np.int64, len(objects))
        b, pid = self.bucket_of_idx[idx], pid_idx[idx]
        lo = np.full(self.n_buckets, np.iinfo(np.int64).max)
        hi = np.full(self.n_buckets, np.iinfo(np.int64).min)
        np.minimum.at(lo, b, pid)
        np.maximum.at(hi, b, pid)
        used = lo <= hi
        lo, hi = lo[used], hi[used]
        return bool((hi[:-1] < lo[1:]).all())

    # ---- step 3 -----------------------------------------------------------------------------
    def _states(self, pid_idx: np.ndarray, time_arr: np.ndarray, p: dict, use_file: bool) -> dict | None:
        """Each bucket's states (:meth:`_bucket`), in worker processes where there are cores and
        buckets (forked: they inherit this object; their results are a few numbers each), written
        to ``states.parquet`` here as they come while the workers go on with the next buckets
        (``written``: :meth:`_write`'s result; None where a bucket's schema differs from the
        first's: the caller writes them all in one schema)."""
        from aveas_format.parallel import map_ordered

        global _WORK
        self._step3 = (pid_idx, time_arr, p, use_file)
        ks = sorted({int(f.name.split(".")[0][1:]) for f in self.dir.glob("b*.arrow")})
        workers = self.ctx.options.workers if len(ks) > 1 else 1
        out: dict[str, Any] = {"repeats": [], "schemas": [], "written": None}
        acc_after, roots_after = True, set()
        if workers != 1:  # (the pass's freed memory back to the system before the fork: the
            release_free_memory()  # workers would otherwise copy those pages as they reuse them)
            pa.default_memory_pool().release_unused()
        _WORK = self
        writer: _StatesWriter | None = None
        try:
            for k, r in map_ordered(_bucket_of_work, ks, workers=workers):
                out["schemas"].append((k, r["schema"]))
                if r["repeats"] is not None:
                    out["repeats"].append(r["repeats"])
                acc_after &= r["acc"]
                roots_after |= r["roots"]
                first = out["schemas"][0][1]
                if writer is None and len(out["schemas"]) == 1:  # (the first bucket's schema)
                    writer = _StatesWriter(self.dir.parent / "states.parquet", _one_schema([first]))
                if writer is not None and r["schema"].equals(first):  # (its file kept: if a later
                    writer.add(self._bucket_states(k, keep=True))     # bucket differs, _write)
                elif writer is not None:
                    writer.abort()
                    writer = None
            if writer is not None:
                out["written"] = self._written(writer, ks)
                writer = None
        finally:
            _WORK = None
            if writer is not None:
                writer.abort()
        if (acc_after and not p["acc_all"]) or roots_after != p["roots"]:
            return None  # (a decision over all boxes that the repeated states dropped would change)
        return out

    def _bucket(self, k: int) -> dict[str, Any]:
        """Bucket ``k``'s boxes in frame order through the in-memory import's steps into states
        (spilled to ``s{k}.arrow``): their schema, the first repeated state dropped, and what
        the decisions over all boxes are checked against."""
        from aveas_format.converters.openlabel import read as R
        from aveas_format.converters.openlabel.frames import _FrameData
        from aveas_format.mapref.build import fill_states

        pid_idx, time_arr, p, use_file = self._step3
        fd, ctx = self.fd, self.ctx
        files = sorted(self.dir.glob(f"b{k}.*.arrow"))  # (the halves of the pass, in file order)
        tables = []
        for f in files:
            with pa.OSFile(str(f)) as mm:
                tables.append(pa.ipc.open_stream(mm, options=READ).read_all())
        t = pa.concat_tables(tables) if len(tables) > 1 else tables[0]
        del tables
        pos = t.column("__pos").to_numpy()
        if len(pos) > 1 and not (pos[1:] > pos[:-1]).all():  # (frames in the file out of key order)
            order = np.argsort(pos, kind="stable")
            t, pos = t.take(pa.array(order)), pos[order]
        rows, bext = from_table(t)
        del t
        bfd = _FrameData(**{**fd.__dict__, "rows": rows, "ext": bext})
        rows["participant_id"] = pid_idx[rows["uidx"]]
        rows["time"] = time_arr[rows["rank"]]
        dropped: list = []
        state_ext = R._drop_repeats(rows, bfd, ctx.path, dropped)
        r: dict[str, Any] = {"repeats": None, "acc": bool(np.isfinite(rows["au"]).all() and np.isfinite(rows["av"]).all()),
                             "roots": {x for x in set(rows["csroot"].tolist()) if x}}
        if dropped:
            c, i, frame, uid = dropped[0]
            r["repeats"] = (c, int(pos[i]), frame, uid)
        x, y, heading = R._to_local(rows, ctx.ol, ctx.local, ctx.options.world_crs, roots=p["roots"])
        states = R._state_columns(rows, x, y, heading, p["hv_all"], p["acc_all"])
        if use_file:
            R._file_road_coordinates(states, rows, ctx.net, state_ext)
        R._apply_state_extension(states, state_ext)
        del rows, state_ext
        same_xy = states["x"] is x and states["y"] is y and "lon" not in states and "lat" not in states
        states = R._state_arrays(states, ctx.ext)
        if same_xy:
            lon, lat = ctx.local.to_wgs84(x, y)
            states["lon"], states["lat"] = pa.array(lon), pa.array(lat)
        s = fill_states(prepare_table(conform(pa.table(states), _SPEC), _SPEC), ctx.local,
                        None if use_file else ctx.net)
        with IpcWriter(self.dir / f"s{k}.arrow", s.schema, self._ipc_options()) as w:
            w.write_table(s)
        for f in files:
            f.unlink()
        r["schema"] = s.schema
        return r

    # ---- step 4 -----------------------------------------------------------------------------
    def _bucket_states(self, k: int, keep: bool = False) -> pa.Table:
        """Bucket ``k``'s states as :meth:`_bucket` spilled them (the file removed unless ``keep``)."""
        f = self.dir / f"s{k}.arrow"
        with pa.OSFile(str(f)) as mm:
            s = pa.ipc.open_stream(mm, options=READ).read_all()
        if not keep:
            os.unlink(f)
        return s

    def _write(self, buckets: list[int], schema: pa.Schema) -> tuple[int, dict, pa.Table]:
        """The buckets' states into one ``states.parquet`` (the recording's row groups, one
        schema); ``(rows, the recording's duration, rate and location, an empty table)``."""
        w = _StatesWriter(self.dir.parent / "states.parquet", schema)
        try:
            for k in buckets:
                w.add(self._bucket_states(k))
        except BaseException:
            w.abort()
            raise
        return self._written(w, [])

    def _written(self, w: _StatesWriter, spilled: list[int]) -> tuple[int, dict, pa.Table]:
        """:meth:`_write`'s result from the writer ``w`` (closed here), the buckets' ``spilled``
        states files removed."""
        n, meta_kw, digest, on_road = w.close()
        for k in spilled:
            (self.dir / f"s{k}.arrow").unlink(missing_ok=True)
        self.states_file = StatesFile(w.target, n, digest)
        self.on_road = on_road
        return n, meta_kw, w.schema.empty_table()


class _StatesWriter:
    """``states.parquet`` written from the buckets' states in order (:meth:`add`): the
    recording's row groups (whole groups written, the rest held for the next bucket), one schema,
    hashed as written; the recording's duration, rate and location summed on the way."""

    def __init__(self, target: Path, schema: pa.Schema) -> None:
        self.target, self.schema = target, schema
        self.wschema, options = parquet_options(schema, _SPEC)
        self.h = hashlib.sha256()
        self.n, self.tmax, self.nulls = 0, -np.inf, 0
        self.sums = np.zeros(2)
        self.dts: dict[float, int] = {}
        self.pending: list[pa.Table] = []
        self.held = 0
        self.raw = open(target, "wb")
        try:
            self.pw = pq.ParquetWriter(_Hashing(self.raw, self.h), self.wschema, **options)
        except BaseException:
            self.raw.close()
            raise

    def add(self, s: pa.Table) -> None:
        s = _conformed(s, self.schema).replace_schema_metadata(self.wschema.metadata)
        pid, t = s.column("participant_id").to_numpy(), s.column("time").to_numpy()
        self.n += s.num_rows
        self.tmax = max(self.tmax, float(t.max()))
        dt = np.diff(t)[same_participant(pid)]
        vals, cnt = np.unique(dt[dt > 0], return_counts=True)
        for v_, c_ in zip(vals.tolist(), cnt.tolist()):
            self.dts[v_] = self.dts.get(v_, 0) + c_
        self.sums += [float(np.sum(s.column(c).to_numpy())) for c in ("lon", "lat")]
        self.nulls += s.column("road_id").null_count
        self.pending.append(s)
        self.held += s.num_rows
        if self.held >= ROW_GROUP_ROWS:  # whole row groups, the rest held for the next
            whole = pa.concat_tables(self.pending)
            cut = self.held - self.held % ROW_GROUP_ROWS
            self.pw.write_table(whole.slice(0, cut), row_group_size=ROW_GROUP_ROWS)
            self.pending, self.held = [whole.slice(cut)], self.held - cut

    def close(self) -> tuple[int, dict, str, int]:
        """``(rows, the recording's duration, rate and location, SHA-256, rows on a road)``."""
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
        meta_kw = {"duration_s": self.tmax, "nominal_rate_hz": _median_rate(self.dts),
                   "location": {"lon": self.sums[0] / self.n, "lat": self.sums[1] / self.n}}
        return self.n, meta_kw, self.h.hexdigest(), self.n - self.nulls

    def abort(self) -> None:
        """Stop writing; the file removed."""
        try:
            self.pw.close()
        except (OSError, pa.ArrowException):
            pass
        self.raw.close()
        self.target.unlink(missing_ok=True)


#: the import whose buckets the worker processes work on (set while they run: forked, they have it)
_WORK: _Buckets | None = None


def _bucket_of_work(k: int) -> dict[str, Any]:
    return _WORK._bucket(k)


def _pass_of_work(part: tuple[int, int, int]) -> dict[str, Any]:
    return _WORK._pass_part(part)


def _gathered() -> dict[str, Any]:
    """What the pass gathers over the boxes kept (:meth:`_Buckets._pass_part`), before any box."""
    return {"kept": 0, "hv_all": True, "hr_any": False, "acc_all": True, "cts_all": True, "roots": set(),
            "had": set(), "left": set(), "sizes": [], "bad": [0, set(), None, None, None]}


def _merged(parts: list[dict[str, Any]]) -> dict[str, Any]:
    """What the parts of the pass gathered, as one pass over all boxes would have."""
    p = _gathered()
    for q in parts:
        p["kept"] += q["kept"]
        for k in ("hv_all", "acc_all", "cts_all"):
            p[k] &= q[k]
        p["hr_any"] |= q["hr_any"]
        for k in ("roots", "had", "left"):
            p[k] |= q[k]
        p["sizes"] += q["sizes"]
        bad, qb = p["bad"], q["bad"]
        bad[0] += qb[0]
        bad[1] |= qb[1]
        if qb[2] is not None and (bad[2] is None or qb[2] < bad[2]):
            bad[2:] = qb[2:]
    return p


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


def _one_schema(schemas: list[pa.Schema]) -> pa.Schema | None:
    """The buckets' states' schema: every column any has (the format's in its order, others by
    name, as the import in memory orders them), a type that holds each bucket's values; None where
    the buckets' types of a column do not go together (the import then runs in memory)."""
    fields: dict[str, pa.Field] = {}
    try:
        for sc in schemas:
            for fld in sc:
                if fld.name in fields and fields[fld.name].type != fld.type:
                    fields[fld.name] = pa.unify_schemas([pa.schema([fields[fld.name]]), pa.schema([fld])],
                                                        promote_options="permissive").field(0)
                else:
                    fields.setdefault(fld.name, fld)
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
        return None
    declared = [c.name for c in _SPEC.columns]
    return pa.schema([fields[c] for c in [c for c in declared if c in fields]
                      + sorted(c for c in fields if c not in _SPEC)])


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


def _f(t: pa.Table, c: str) -> np.ndarray:
    col = t.column(c)
    return (col.fill_null(np.nan) if col.null_count else col).to_numpy()


def _conformed(t: pa.Table, schema: pa.Schema) -> pa.Table:
    """``t`` with ``schema``'s columns in its order and types (a column it lacks: nulls)."""
    if t.schema.equals(schema):
        return t
    have = dict(zip(t.column_names, t.columns))
    cols = [pa.nulls(t.num_rows, f.type) if f.name not in have else
            have[f.name] if have[f.name].type == f.type else have[f.name].cast(f.type) for f in schema]
    return pa.Table.from_arrays(cols, schema=schema)


def _in_order(parts: list[tuple]) -> dict[str, np.ndarray]:
    """The boxes gathered for the objects' sizes, in frame order (rows for ``_sizes``)."""
    pos, u, dl, dw, dh = (np.concatenate(c) for c in zip(*parts))
    o = np.argsort(pos, kind="stable")
    return {"uidx": u[o].astype(np.int64), "dl": dl[o], "dw": dw[o], "dh": dh[o]}


def import_openlabel_to(inputs: list[Path], output: Path, *, map_source=None, options=None,
                        overwrite: bool = False, min_rows: int | None = None):
    """Import one OpenLABEL file and write the recording to ``output`` (atomically; states in
    parts from ``min_rows`` boxes, default :data:`SPILL_MIN_ROWS`: bounded memory). Returns
    ``(recording, states, on the map)``: the recording as written (its states not loaded when
    they were written in parts)."""
    from aveas_format.converters.openlabel.read import OpenLabelImportOptions, import_openlabel
    from aveas_format.io.writer import check_target, write_recording

    output = Path(output)
    parent = check_target(output, overwrite)
    with Parts(parent, SPILL_MIN_ROWS if min_rows is None else min_rows) as parts:
        rec = import_openlabel(list(inputs), map_source=map_source,
                               options=options or OpenLabelImportOptions(), parts=parts)
        if parts.states_file is None:
            rec.write(output, overwrite=overwrite)
            n = rec.states.num_rows
            return rec, n, n - rec.states.column("road_id").null_count
        write_recording(rec, output, overwrite=overwrite, states_file=parts.states_file)
        return rec, parts.states_file.rows, parts.on_road
