"""The bounded re-sort of time-major state rows (io/resort.py): whatever the batches, their columns
and the memory given, the rows come back as whole participants in the order of a sort of all
rows by participant and time (numpy's stable lexsort: the truth), written as a states.parquet
whose digest, rows, duration, rate and location are those of the sorted table."""

from __future__ import annotations

import hashlib
import os

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from aveas_format.io import resort
from aveas_format.io.resort import StatesWriter


def _batches(seed: int, n_pid: int = 37, n_t: int = 60, per: int = 3):
    """Time-major batches (``per`` time steps each, participants in a shuffled order in each),
    a column only some batches have, ids with gaps; and the truth: all rows sorted by
    participant and time (stable)."""
    rng = np.random.default_rng(seed)
    ids = np.sort(rng.choice(10_000, n_pid, replace=False))
    out = []
    for t0 in range(0, n_t, per):
        rows = [(p, t) for t in range(t0, min(t0 + per, n_t)) for p in rng.permutation(ids)
                if rng.random() < 0.8]
        if not rows:
            continue
        pid = np.array([p for p, _ in rows], np.int64)
        t = np.array([t for _, t in rows], float) * 0.04
        cols = {"participant_id": pid, "time": t, "x": rng.normal(size=len(rows)), "y": t * 10.0,
                "lon": 8.0 + rng.normal(size=len(rows)) * 1e-3, "lat": 48.0 + rng.normal(size=len(rows)) * 1e-3,
                "road_id": pa.array(["1" if v % 3 else None for v in pid])}
        if t0 % 2:
            cols["tag"] = pa.array([f"p{v}" for v in pid])
        out.append(cols)
    full = pa.concat_tables([pa.table(b) for b in out], promote_options="permissive")
    order = np.lexsort((full.column("time").to_numpy(), full.column("participant_id").to_numpy()))
    return out, full.take(pa.array(order))


@pytest.mark.parametrize("memory", [None, 1])
@pytest.mark.parametrize("bucket_bytes", [None, 3_000])
def test_buckets_are_whole_participants_in_order(tmp_path, memory, bucket_bytes):
    batches, truth = _batches(1)
    with StatesWriter(tmp_path, memory=memory, bucket_bytes=bucket_bytes) as w:
        for b in batches:
            w.add(b)
        assert w.spilled == (memory is not None)
        got = [t for t, _ in w.map(lambda t: (t, None))]
        spill = w.dir
    assert spill is None or not spill.exists()  # (removed)
    assert (len(got) > 3) == (memory is not None and bucket_bytes is not None)
    seen = [set(t.column("participant_id").to_pylist()) for t in got]
    assert all(not (a & b) for i, a in enumerate(seen) for b in seen[i + 1:])  # whole participants
    assert pa.concat_tables(got, promote_options="permissive").select(truth.column_names).equals(truth)


def test_keys_decided_after_the_last_row(tmp_path):
    """``key_map``: the buckets follow the final keys (here: the reverse order of the keys added),
    rows mapped to the same key together."""
    batches, _ = _batches(2)
    ids = sorted({int(v) for b in batches for v in b["participant_id"]})
    key_map = np.full(max(ids) + 1, -1, np.int64)
    key_map[ids] = np.arange(len(ids))[::-1] // 2  # (two participants each, reversed)
    with StatesWriter(tmp_path, memory=1, bucket_bytes=2_000) as w:
        for b in batches:
            w.add(b)
        buckets = list(w.buckets(key_map))
    final = [key_map[t.column("participant_id").to_numpy()] for t in buckets]
    firsts, lasts = [f.min() for f in final], [f.max() for f in final]
    assert all(a < b for a, b in zip(lasts, firsts[1:]))  # (ascending final keys, whole)
    assert sum(len(f) for f in final) == sum(len(b["time"]) for b in batches)
    for t in buckets:  # (the rows of a bucket in the order added: time-major)
        tt = t.column("time").to_numpy()
        assert np.all(tt[1:] >= tt[:-1])


@pytest.mark.parametrize("workers", [1, 2])
def test_written_states_are_the_sorted_rows(tmp_path, monkeypatch, workers):
    """In row groups of the recording, one schema over buckets with and without a column, hashed
    as written; the summary is the sorted table's; transforms may run in worker processes."""
    from aveas_format.io import writer
    from aveas_format.numeric import same_participant

    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 500)
    batches, truth = _batches(3, n_pid=60, n_t=90)
    pids = []
    with StatesWriter(tmp_path, memory=1, bucket_bytes=4_000) as w:
        for b in batches:
            w.add(b)
        sf, summary, infos = w.write(tmp_path / "states.parquet", workers=workers,
                                     transform=lambda t: (t, os.getpid()))
        pids = set(infos)
    assert (workers > 1) == (os.getpid() not in pids)
    got = pq.read_table(sf.path)
    assert got.select(truth.column_names).cast(truth.schema).equals(truth)
    assert got.column_names[:2] == ["participant_id", "time"]
    assert pq.ParquetFile(sf.path).metadata.num_row_groups == -(-truth.num_rows // 500)
    assert sf.rows == truth.num_rows and sf.sha256 == hashlib.sha256(sf.path.read_bytes()).hexdigest()
    t, pid = truth.column("time").to_numpy(), truth.column("participant_id").to_numpy()
    dt = np.diff(t)[same_participant(pid)]
    assert summary["duration_s"] == t.max()
    assert summary["nominal_rate_hz"] == round(1 / np.median(dt[dt > 0]), 6)
    assert summary["location"]["lon"] == pytest.approx(truth.column("lon").to_numpy().mean(), rel=1e-12)
    assert summary["on_road"] == truth.num_rows - truth.column("road_id").null_count


def test_nothing_left_when_a_transform_fails(tmp_path):
    batches, _ = _batches(4)
    target = tmp_path / "out" / "states.parquet"
    target.parent.mkdir()

    def fails(t):
        raise ValueError("no")

    with pytest.raises(ValueError), StatesWriter(tmp_path / "out", memory=1, bucket_bytes=3_000) as w:
        for b in batches:
            w.add(b)
        w.write(target, transform=fails)
    assert list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("options", ["LZ4", "PLAIN"])
def test_bucket_files_written_through_a_buffer_read_back_whole(tmp_path, options):
    """The spills' writers (a buffer under Arrow's IPC writer): every small batch of many buckets
    read back in order; closing twice is harmless; a writer that cannot start leaves its file
    closed."""
    opts = getattr(resort, options)
    rng = np.random.default_rng(3)
    n = 5000
    table = pa.table({f"c{i}": rng.normal(size=n) for i in range(30)} | {"k": np.arange(n)})
    buckets = np.sort(rng.integers(0, 40, n))
    writers: dict = {}
    try:
        for lo in range(0, n, 700):
            resort.write_by_bucket(writers, table.slice(lo, 700), buckets[lo:lo + 700],
                                   lambda k: tmp_path / f"b{k}.arrow", opts)
    finally:
        for w in writers.values():
            w.close()
    got = [resort.read_ipc(tmp_path / f"b{k}.arrow") for k in sorted(writers)]
    assert [len(t) for t in got] == [int((buckets == k).sum()) for k in sorted(writers)]
    assert pa.concat_tables(got).equals(table)
    w = resort.IpcWriter(tmp_path / "f.arrow", table.schema, opts, file=True)
    w.write_table(table)
    w.close()
    w.close()
    assert resort.read_ipc(tmp_path / "f.arrow").equals(table)
    with pytest.raises((TypeError, pa.ArrowException)):
        resort.IpcWriter(tmp_path / "g.arrow", "not a schema", opts)
    if os.path.isdir("/proc/self/fd"):  # (Linux: no descriptor left open on it)
        assert not any(os.path.realpath(f"/proc/self/fd/{fd}").endswith("g.arrow") for fd in os.listdir("/proc/self/fd"))


def test_one_schema_over_the_parts():
    """The format's columns first in its order, others in the order met; a type that holds every
    part's values (a column all null in one part takes the others' type)."""
    one = resort.unified([pa.schema([("zz", pa.null()), ("time", pa.float64())]),
                          pa.schema([("participant_id", pa.int64()), ("aa", pa.string()), ("zz", pa.bool_())])],
                         ["participant_id", "time"])
    assert one.names == ["participant_id", "time", "zz", "aa"]
    assert one.field("zz").type == pa.bool_()
