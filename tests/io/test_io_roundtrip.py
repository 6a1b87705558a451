"""Round trips: every table and every column type survives write -> read, in both forms."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import aveas_format
from aveas_format.io.arrow import arrow_type, pmf_array
from aveas_format.io.recording import Recording
from aveas_format.schema import TABLES, RecordingMeta
from aveas_format.schema.columns import Column
from aveas_format.schema.taxonomy import CATEGORY_SETS

from helpers_common import STRAIGHT_MAP
from helpers_common import minimal_meta


def random_column(c: Column, n: int, rng: np.random.Generator) -> pa.Array:
    """Valid random values of a declared column (nulls where the column allows them)."""
    nulls = None if not c.nullable else rng.random(n) < 0.1
    lo = c.minimum if c.minimum is not None else -1e3
    hi = c.maximum if c.maximum is not None else 1e3
    t = c.type
    if c.pmf_set:
        k = len(CATEGORY_SETS[c.pmf_set])
        m = rng.dirichlet(np.ones(k), n).astype(np.float32)
        return pmf_array(m, c.pmf_set, mask=nulls)
    if c.categories:
        vals = rng.choice(c.categories, n).astype(object)
        return pa.array(vals, pa.string(), mask=nulls).dictionary_encode()
    if t in ("float64", "float32"):
        v = rng.uniform(lo + 1e-6 if c.exclusive_minimum else lo, hi, n)
        return pa.array(v.astype(t), arrow_type(c), mask=nulls)
    if t.startswith("int"):
        info = np.iinfo(t)
        v = rng.integers(max(int(lo), info.min), min(int(hi), info.max) + 1, n).astype(t)
        return pa.array(v, arrow_type(c), mask=nulls)
    if t == "bool":
        return pa.array(rng.random(n) < 0.5, pa.bool_(), mask=nulls)
    if t == "string":
        return pa.array([f"s{int(i)}-é" for i in rng.integers(0, 1e6, n)], pa.string(), mask=nulls)
    if t == "dict<string>":
        return pa.array(rng.choice(["1", "2", "10"], n).astype(object), pa.string(),
                        mask=nulls).dictionary_encode()
    if t == "binary":
        return pa.array([bytes(rng.integers(0, 256, 8, dtype=np.uint8)) for _ in range(n)],
                        pa.binary(), mask=nulls)
    if t == "list<int64>":
        return pa.array([list(rng.integers(0, 100, rng.integers(0, 4))) for _ in range(n)],
                        pa.list_(pa.int64()), mask=nulls)
    if t == "list<string>":
        return pa.array([[f"r{j}" for j in range(rng.integers(0, 4))] for _ in range(n)],
                        pa.list_(pa.string()), mask=nulls)
    raise AssertionError(t)


def random_table(name: str, n: int, rng: np.random.Generator, optional_share: float) -> pa.Table:
    spec = TABLES[name]
    cols = {}
    for c in spec.columns:
        if c.requirement.value == "MUST" or rng.random() < optional_share:
            cols[c.name] = random_column(c, n, rng)
    # keys unique
    if spec.key == ("participant_id", "time"):
        cols["participant_id"] = pa.array(np.repeat(np.arange(n // 5 + 1), 5)[:n].astype(np.int64))
        cols["time"] = pa.array(np.tile(np.arange(5) * 0.1, n // 5 + 1)[:n])
    elif len(spec.key) == 1 and spec.key[0] in cols and spec.column(spec.key[0]).type == "int64":
        cols[spec.key[0]] = pa.array(rng.permutation(n).astype(np.int64))
    if name == "states":
        cols["heading"] = pa.array(rng.uniform(-3.14, 3.14, n))
    return pa.table(cols)


def random_recording(seed: int, n: int, optional_share: float, tables: list[str]) -> Recording:
    rng = np.random.default_rng(seed)
    data = {name: random_table(name, n, rng, optional_share) for name in tables}
    meta = RecordingMeta.model_validate(minimal_meta(recording_id=f"rand-{seed}"))
    return Recording(meta=meta, tables=data, map_source=STRAIGHT_MAP.read_bytes())


def assert_tables_equal(a: Recording, b: Recording) -> None:
    ta, tb = a.tables(), b.tables()
    assert ta.keys() == tb.keys()
    for name in ta:
        x, y = ta[name], tb[name]
        assert x.schema.names == y.schema.names, name
        for col in x.column_names:
            assert x.column(col).type.equals(y.column(col).type) or (
                pa.types.is_dictionary(x.column(col).type)), (name, col)
            assert x.column(col).to_pylist() == y.column(col).to_pylist(), (name, col)


ALL_TABLES = list(TABLES)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 60), share=st.floats(0.0, 1.0),
       tables=st.sets(st.sampled_from(ALL_TABLES[2:]), max_size=len(ALL_TABLES) - 2),
       form=st.sampled_from(["directory", "zip"]))
def test_random_valid_recordings_round_trip(tmp_path_factory, seed, n, share, tables, form):
    rec = random_recording(seed, n, share, ["participants", "states", *sorted(tables)])
    out = tmp_path_factory.mktemp("rt") / ("r.aveas.zip" if form == "zip" else "r.aveas")
    rec.write(out)
    back = aveas_format.open(out)
    assert_tables_equal(rec, back)  # `rec` now holds the conformed, sorted tables it wrote
    assert back.meta == rec.meta
    assert back.map_source == STRAIGHT_MAP.read_bytes()
    assert set(back.meta.tables) == {"participants", "states", *tables}


def test_every_column_of_every_table(tmp_path):
    rec = random_recording(3, 40, 1.0, ALL_TABLES)
    for name, t in rec.tables().items():
        assert set(t.column_names) == set(TABLES[name].names), name
    rec.write(tmp_path / "all.aveas")
    back = aveas_format.open(tmp_path / "all.aveas")
    assert_tables_equal(rec, back)
    for name, t in back.tables().items():
        for c in TABLES[name].columns:
            assert t.schema.field(c.name).type.equals(arrow_type(c)), (name, c.name)


def test_zip_form_equals_directory_form(tmp_path, rec):
    d = rec.write(tmp_path / "a.aveas")
    z = rec.write(tmp_path / "a.aveas.zip")
    a, b = aveas_format.open(d), aveas_format.open(z)
    assert a.meta == b.meta
    assert_tables_equal(a, b)
    import zipfile

    with zipfile.ZipFile(z) as zf:
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())
        assert zf.namelist()[0] == "recording.json"
        for name in ("participants.parquet", "states.parquet", "map.xodr"):
            assert zf.read(name) == (d / name).read_bytes()


def test_parquet_files_carry_the_aveas_key_and_are_sorted(written):
    for name in ("participants", "states"):
        md = pq.read_schema(written / f"{name}.parquet").metadata
        import json

        key = json.loads(md[b"aveas"])
        assert key["table"] == name and key["format_version"] == "1.0.0"
        assert key["creator"]["library"] == "aveas-format"
    pf = pq.ParquetFile(written / "states.parquet")
    assert pf.metadata.row_group(0).column(0).compression == "ZSTD"


def test_states_are_sorted_on_write(tmp_path, rec):
    shuffled = rec.states.take(pa.array(np.random.default_rng(0).permutation(rec.states.num_rows)))
    rec.states = shuffled
    rec.write(tmp_path / "s.aveas")
    s = aveas_format.open(tmp_path / "s.aveas").states
    pid, t = s.column("participant_id").to_numpy(), s.column("time").to_numpy()
    order = np.lexsort((t, pid))
    assert (order == np.arange(len(order))).all()


def test_no_overwrite_without_permission(tmp_path, rec):
    rec.write(tmp_path / "x.aveas")
    with pytest.raises(aveas_format.RecordingExistsError, match="overwrite"):
        rec.write(tmp_path / "x.aveas")
    with pytest.raises(FileExistsError):
        rec.write(tmp_path / "x.aveas")
    rec.write(tmp_path / "x.aveas", overwrite=True)
    assert aveas_format.open(tmp_path / "x.aveas").states.num_rows == rec.states.num_rows


@pytest.mark.parametrize("form", ["x.aveas", "x.aveas.zip"])
def test_write_is_atomic(tmp_path, rec, monkeypatch, form):
    """A crash at the final rename leaves neither a recording nor temporary debris."""
    target = tmp_path / form

    def boom(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "rename", boom)
    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(aveas_format.RecordingIOError, match="No space left"):
        rec.write(target)
    assert list(tmp_path.iterdir()) == []


def test_overwrite_exchanges_directories_atomically(tmp_path, rec, monkeypatch):
    from aveas_format.io import writer

    target = rec.write(tmp_path / "x.aveas")
    used = []
    real = writer._exchange
    monkeypatch.setattr(writer, "_exchange", lambda a, b: used.append(real(a, b)) or used[-1])
    rec.states = rec.states.slice(0, 10)
    rec.write(target, overwrite=True)
    assert aveas_format.open(target).states.num_rows == 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.aveas"]
    if sys.platform.startswith("linux"):
        assert used == [True]


def test_failed_overwrite_keeps_the_old_recording(tmp_path, rec, monkeypatch):
    """Where no atomic exchange exists, the fallback renames the old recording aside and puts
    it back when the new one cannot be moved into place."""
    from aveas_format.io import writer

    monkeypatch.setattr(writer, "_exchange", lambda a, b: False)
    target = rec.write(tmp_path / "x.aveas")
    before = (target / "states.parquet").read_bytes()
    real_rename = os.rename
    calls = []

    def flaky(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:  # moving the new one into place fails
            raise OSError(5, "I/O error")
        return real_rename(src, dst)

    monkeypatch.setattr(os, "rename", flaky)
    rec.states = rec.states.slice(0, 10)
    with pytest.raises(aveas_format.RecordingIOError):
        rec.write(target, overwrite=True)
    monkeypatch.undo()
    assert (target / "states.parquet").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.aveas"]
    aveas_format.open(target)


def test_zip_with_a_top_level_directory_is_read(tmp_path, written):
    import zipfile

    z = tmp_path / "nested.aveas.zip"
    with zipfile.ZipFile(z, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for f in Path(written).iterdir():
            zf.write(f, f"small.aveas/{f.name}")
    assert aveas_format.open(z).states.num_rows == aveas_format.open(written).states.num_rows


def test_figures_and_tables_are_written_atomically(tmp_path):
    """save_figure_atomic / write_parquet_atomic (plots, fitter outputs, map tables): the result
    appears whole or not at all; a failing render leaves the old file and no temporary behind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pyarrow as pa
    import pyarrow.parquet as pq

    from aveas_format.safeio import save_figure_atomic, write_parquet_atomic

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    p = save_figure_atomic(fig, tmp_path / "f.png", dpi=50)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    before = p.read_bytes()
    with pytest.raises(ValueError):
        save_figure_atomic(fig, tmp_path / "f.png", format="no-such-format")
    assert p.read_bytes() == before
    plt.close(fig)
    t = pa.table({"a": [1, 2, 3]})
    q = write_parquet_atomic(t, tmp_path / "t.parquet")
    assert pq.read_table(q).equals(t)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["f.png", "t.parquet"]
