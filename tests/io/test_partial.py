"""Partial reads: selected columns, participants and time windows without reading everything."""

from __future__ import annotations

import numpy as np
import pytest

import aveas_format
from aveas_format.io import writer
from aveas_format.io.reader import ReadPlan

from helpers_common import small_recording


@pytest.fixture
def many_groups(tmp_path, monkeypatch):
    """A recording whose states span many row groups (small row groups for the test)."""
    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 100)
    rec = small_recording(n=20, steps=100)
    return rec.write(tmp_path / "m.aveas")


def test_selected_columns(many_groups):
    rec = aveas_format.open(many_groups, columns=["x", "y"])
    assert rec.states.column_names == ["participant_id", "time", "x", "y"]
    assert rec.participants.num_rows == 20


def test_columns_per_table(many_groups):
    rec = aveas_format.open(many_groups, columns={"states": ["lon"], "participants": ["class"]})
    assert rec.states.column_names == ["participant_id", "time", "lon"]
    assert rec.participants.column_names == ["participant_id", "class"]


def test_unknown_column_is_an_error(many_groups):
    with pytest.raises(aveas_format.FormatError, match=r"columns \['speed'\] are not in states"):
        aveas_format.open(many_groups, columns=["speed"])


def test_selected_participants_read_only_their_row_groups(many_groups):
    plan = ReadPlan()
    rec = aveas_format.open(many_groups, participants=[3, 7], plan=plan)
    pid = rec.states.column("participant_id").to_numpy()
    assert set(pid) == {3, 7} and len(pid) == 200
    assert rec.participants.column("participant_id").to_pylist() == [3, 7]
    read, total = plan.row_groups["states"]
    assert total == 20 and read == 2
    assert "states" not in plan.hashed  # a partial read does not hash the whole file


def test_time_window(many_groups):
    plan = ReadPlan()
    rec = aveas_format.open(many_groups, time_range=(2.0, 3.0), plan=plan)
    t = rec.states.column("time").to_numpy()
    assert t.min() >= 2.0 and t.max() <= 3.0
    assert len(t) == 20 * 11
    # unobserved regions are intervals: those overlapping the window are kept
    assert plan.row_groups["states"][0] <= plan.row_groups["states"][1]


def test_time_window_skips_row_groups_when_time_is_clustered(tmp_path, monkeypatch):
    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 50)
    rec = small_recording(n=2, steps=500)
    path = rec.write(tmp_path / "t.aveas")
    plan = ReadPlan()
    out = aveas_format.open(path, time_range=(10.0, 14.95), plan=plan)
    assert out.states.num_rows == 2 * 50
    read, total = plan.row_groups["states"]
    assert total == 20 and read == 2


def test_participants_and_time_and_columns_together(many_groups):
    rec = aveas_format.open(many_groups, participants=[5], time_range=(0.0, 0.45), columns=["vx"])
    assert rec.states.num_rows == 5
    assert rec.states.column_names == ["participant_id", "time", "vx"]
    full = aveas_format.open(many_groups).states
    sel = full.filter(np.asarray(full.column("participant_id").to_numpy() == 5)).slice(0, 5)
    assert rec.states.column("vx").to_pylist() == sel.column("vx").to_pylist()


def test_tables_selection(many_groups):
    rec = aveas_format.open(many_groups, tables=["participants"])
    assert rec.states is None and rec.participants.num_rows == 20
    with pytest.raises(aveas_format.FormatError, match="unknown tables"):
        aveas_format.open(many_groups, tables=["trajectories"])


@pytest.mark.parametrize("form", ["m.aveas", "m.aveas.zip"])
def test_table_parts_read_the_states_part_by_part(tmp_path, monkeypatch, form):
    """Without the states (``states=False``), then row group by row group through TableParts: the
    table read whole, the same types; the hash checked on demand."""
    import pyarrow as pa

    from aveas_format.io.reader import TableParts

    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 100)
    path = small_recording(n=20, steps=100).write(tmp_path / form)
    rec = aveas_format.open(path, states=False)
    assert rec.states is None and rec.participants.num_rows == 20
    whole = aveas_format.open(path).states
    parts = TableParts(path, rec.meta, "states")
    try:
        assert parts.num_row_groups == 20 and parts.num_rows == whole.num_rows
        got = pa.concat_tables([parts.read(g) for g in range(parts.num_row_groups)])
        assert got.equals(whole) and got.schema.equals(whole.schema)
        assert parts.read(columns=["time"]).column("time").equals(whole.column("time"))
        parts.verify()
        rec.meta.tables["states"].sha256 = "0" * 64
        with pytest.raises(aveas_format.ChecksumError, match="states.parquet"):
            parts.verify()
    finally:
        parts.close()


def test_partial_read_from_zip(tmp_path, monkeypatch):
    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 100)
    path = small_recording(n=10, steps=100).write(tmp_path / "z.aveas.zip")
    plan = ReadPlan()
    rec = aveas_format.open(path, participants=[9], plan=plan)
    assert rec.states.num_rows == 100 and plan.row_groups["states"] == (1, 10)


def test_take_rows_in_threads_equals_arrow_take():
    """The writer's sort takes a large table's columns in threads: the same table as Arrow's take
    (nulls, dictionaries, strings, chunked columns)."""
    import numpy as np
    import pyarrow as pa

    from aveas_format.io.writer import take_rows

    n = 300_000
    rng = np.random.default_rng(1)
    t = pa.table({"a": pa.chunked_array([np.arange(n // 2), np.arange(n // 2, n)]),
                  "b": pa.array(rng.normal(size=n), mask=rng.random(n) < 0.1),
                  "c": pa.array(rng.integers(0, 5, n).astype(str)).dictionary_encode(),
                  "d": pa.array([None if i % 7 == 0 else f"s{i}" for i in range(n)])})
    order = pa.array(rng.permutation(n))
    got = take_rows(t, order)
    assert got.equals(t.take(order)) and got.schema == t.schema
    small = t.slice(0, 10)
    assert take_rows(small, pa.array([3, 1])).equals(small.take(pa.array([3, 1])))
